"""PX4's own EKF2 innovation test ratios, per aiding source (the baseline for PX4 logs).

Specified in docs/algorithms.md section 3b.

PX4's EKF2 logs, for each aiding source, innovation^2 / (gate^2 * innovation variance): above 1
the source fails PX4's own gate. This detector reads those ratios from the log (no filter of its
own: it runs whatever model the profile uses) and raises an alarm per source when the ratio stays
above ``ratio`` (1.0) for ``min_duration_s`` (2 s). Where the ratios are, by PX4 version:

- v1.12+: ``estimator_innovation_test_ratios`` (gps_hpos[0..1], baro_vpos, heading, ...: one
  statistic per field, the max over an array's components) and ``estimator_status``
  (mag_test_ratio, vel_test_ratio, pos_test_ratio, ...);
- v1.14+: also ``estimator_aid_src_*`` (``test_ratio``, scalar or array): ``px4.aid_<source>``;
- v1.6-1.8: ``ekf2_innovations`` (innovations and their variances: the ratio is computed here
  with the log's EKF2_*_GATE parameters, PX4's defaults when absent) and ``estimator_status``.

A ratio is judged only while PX4 fuses its source (``estimator_status_flags`` cs_* of the same
instance, v1.12+; an ``estimator_aid_src_*`` sample's own ``fused`` field): before GNSS is
accepted or for a sensor PX4 ignores, the ratio is no evidence. Each statistic lives on the
analysis grid: a sample counts at the first grid step at or after its time (the max of the samples
that fall on one step); steps without a sample are not judged. A ratio of exactly 0 (a source not
fused) or a non-finite one is no evidence: not judged. A source with no such sample over the log
is not reported (listed in ``info["unused"]``). Several EKF2 instances (multi-EKF): statistics per
instance, ``px4.ekf<i>.<source>``. PX4's tests of synthetic observations that it runs only as a
gate (gravity, fake position/height, drag, sideslip: `GATE_ONLY`) are read and set aside
(``info["gate_only"]``): a ratio over 1 there is PX4 declining an assumption, never a fault.
"""

from __future__ import annotations

import re
from collections.abc import Mapping

import numpy as np

from logscan.detectors.base import Detector, DetectorResult
from logscan.detectors.params import multiplier_bound
from logscan.detectors.raw_topics import held, log_parameter, on_grid, persist_count, split_topics

PREFIX = "px4"
# EKF2 instances read (PX4 runs up to several with EKF2_MULTI_IMU / EKF2_MULTI_MAG)
INSTANCES = (0, 1, 2, 3)
TEST_RATIOS = "estimator_innovation_test_ratios"
STATUS = "estimator_status"
LEGACY = "ekf2_innovations"
AID_PREFIX = "estimator_aid_src_"
# estimator_aid_src_* topics of PX4 v1.14 and later (gps_* in v1.14, gnss_* since)
AID_SOURCES = (
    "airspeed",
    "aux_global_position",
    "aux_vel",
    "baro_hgt",
    "drag",
    "ev_hgt",
    "ev_pos",
    "ev_vel",
    "ev_yaw",
    "fake_hgt",
    "fake_pos",
    "gnss_hgt",
    "gnss_pos",
    "gnss_vel",
    "gnss_yaw",
    "gps_hgt",
    "gps_pos",
    "gps_vel",
    "gps_yaw",
    "gravity",
    "mag",
    "mag_heading",
    "optical_flow",
    "ranging_beacon",
    "rng_hgt",
    "sideslip",
    "terrain_optical_flow",
    "terrain_range_finder",
)
STATUS_FIELDS = (
    "vel_test_ratio",
    "pos_test_ratio",
    "hgt_test_ratio",
    "mag_test_ratio",
    "tas_test_ratio",
    "hagl_test_ratio",
    "beta_test_ratio",
)
FLAGS = "estimator_status_flags"  # PX4 v1.12+: which sources the EKF fuses (cs_* booleans)
TOPIC_NAMES = (TEST_RATIOS, STATUS, LEGACY, FLAGS, *(AID_PREFIX + source for source in AID_SOURCES))
# estimator_innovation_test_ratios source -> the cs_* flags of which one must be set for the EKF to
# fuse it: a ratio while the source is not fused (before GNSS is accepted, on the ground) is PX4
# computing a test for data it does not use, no evidence (it ran to 5.6e9 before the first fix of a
# real log)
FUSED_BY = {
    "gps_hvel": ("cs_gps",),
    "gps_vvel": ("cs_gps",),
    "gps_hpos": ("cs_gps",),
    "gps_vpos": ("cs_gps_hgt", "cs_gps"),
    "baro_vpos": ("cs_baro_hgt",),
    "rng_vpos": ("cs_rng_hgt",),
    "heading": ("cs_mag_hdg", "cs_gps_yaw", "cs_ev_yaw"),
    "mag_field": ("cs_mag_3d",),
    "flow": ("cs_opt_flow",),
    "ev_hpos": ("cs_ev_pos",),
    "ev_vpos": ("cs_ev_hgt",),
    "ev_hvel": ("cs_ev_vel",),
    "ev_vvel": ("cs_ev_vel",),
    "airspeed": ("cs_fuse_aspd",),
    "beta": ("cs_fuse_beta",),
}

# ekf2_innovations (PX4 v1.6-1.8): source -> (innovation fields, gate parameter, PX4's default gate)
_HEIGHT_BY_MODE = {  # EKF2_HGT_MODE -> (source, gate parameter, default)
    0: ("baro_vpos", "EKF2_BARO_GATE", 5.0),
    1: ("gps_vpos", "EKF2_GPS_P_GATE", 5.0),
    2: ("rng_vpos", "EKF2_RNG_GATE", 5.0),
    3: ("ev_vpos", "EKF2_EV_GATE", 5.0),
}
LEGACY_SOURCES = {
    "gps_hvel": (("vel_pos_innov[0]", "vel_pos_innov[1]"), "EKF2_GPS_V_GATE", 5.0),
    "gps_vvel": (("vel_pos_innov[2]",), "EKF2_GPS_V_GATE", 5.0),
    "gps_hpos": (("vel_pos_innov[3]", "vel_pos_innov[4]"), "EKF2_GPS_P_GATE", 5.0),
    "height": (("vel_pos_innov[5]",), "EKF2_BARO_GATE", 5.0),  # renamed by EKF2_HGT_MODE
    "mag_field": (("mag_innov[0]", "mag_innov[1]", "mag_innov[2]"), "EKF2_MAG_GATE", 3.0),
    "heading": (("heading_innov",), "EKF2_HDG_GATE", 2.6),
    "airspeed": (("airspeed_innov",), "EKF2_TAS_GATE", 3.0),
    "beta": (("beta_innov",), "EKF2_BETA_GATE", 5.0),
    "flow": (("flow_innov[0]", "flow_innov[1]"), "EKF2_OF_GATE", 3.0),
    "hagl": (("hagl_innov",), "EKF2_RNG_GATE", 5.0),
}

# Tests PX4 runs only as a gate on a synthetic observation, not on a sensor: a ratio over 1 there is
# PX4 choosing not to fuse the assumption at that moment, by design, never a fault. gravity: the
# accelerometer taken as the gravity direction, with a 0.25 gate, so every manoeuvre fails it
# (gravity_fusion.cpp; 82 % of the samples of a normal real flight); fake_pos / fake_hgt: "no
# motion" fused while PX4 has no aiding source; drag: the multirotor drag model's specific force
# (wind estimation); beta / sideslip: the zero-sideslip assumption of a fixed wing
# (cs_fuse_beta: "synthetic sideslip measurements"). Keys: the source with "aid_" and
# "_test_ratio" removed.
GATE_ONLY = frozenset({"gravity", "fake_pos", "fake_hgt", "drag", "beta", "sideslip"})


def gate_only(source: str) -> bool:
    """Whether PX4's test of ``source`` (a statistic's last part) is a gate on a synthetic
    observation (GATE_ONLY): read, never an alarm."""
    return source.removeprefix("aid_").removesuffix("_test_ratio") in GATE_ONLY


NO_RATIOS = (
    "px4_estimator: the log has no PX4 estimator test ratios (estimator_innovation_test_ratios, "
    "estimator_status, estimator_aid_src_*, ekf2_innovations)"
)
# the statistic that stands for "nothing was checked" (never finite: logscan.verdict.coverage says so)
NOTHING = f"{PREFIX}.test_ratios"

_ELEMENT = re.compile(r"^(?P<base>.+)\[(?P<index>\d+)\]$")


def _base(field: str) -> str:
    match = _ELEMENT.match(field)
    return match.group("base") if match else field


def _max_over(channels: list) -> tuple[np.ndarray, np.ndarray] | None:
    """(t ns, max over the channels' finite non-zero values; NaN where none) of channels sharing
    their sample times (one topic's fields); None when the times differ."""
    t = channels[0].t
    if any(c.t.shape != t.shape or not np.array_equal(c.t, t) for c in channels[1:]):
        return None
    values = np.full(t.shape, np.nan)
    for channel in channels:
        v = np.where(np.isfinite(channel.values) & (channel.values != 0.0), channel.values, np.nan)
        values = np.fmax(values, v)
    return t, values


def _legacy_ratio(fields: dict, innov: tuple[str, ...], gate: float) -> tuple[np.ndarray, np.ndarray] | None:
    """innov^2 / (gate^2 * innov_var), the max over the components (NaN where undefined)."""
    parts = []
    for name in innov:
        base, _, index = name.partition("[")
        var_name = f"{base}_var[{index}" if index else f"{name}_var"
        if name not in fields or var_name not in fields:
            return None
        y, s = fields[name], fields[var_name]
        if not np.array_equal(y.t, s.t):
            return None
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            ratio = y.values**2 / (gate**2 * s.values)
        ratio[~(np.isfinite(ratio) & (s.values > 0))] = np.nan
        parts.append(ratio)
    t = fields[innov[0]].t
    values = np.full(t.shape, np.nan)
    for ratio in parts:
        values = np.fmax(values, np.where(ratio != 0.0, ratio, np.nan))
    return t, values


def _parameter(parameters: Mapping, name: str, default: float) -> float:
    found = log_parameter(parameters, name)
    return default if found is None else found[0]


# Plain words for each source, in an incident's headline: "PX4's own test of the <words> failed"
SOURCE_WORDS = {
    "gps_hpos": "GNSS horizontal position",
    "gps_vpos": "GNSS height",
    "gps_hvel": "GNSS horizontal velocity",
    "gps_vvel": "GNSS vertical velocity",
    "baro_vpos": "barometer height",
    "rng_vpos": "range-finder height",
    "heading": "heading",
    "mag_field": "magnetometer field",
    "flow": "optical flow",
    "airspeed": "airspeed",
    "beta": "sideslip",
    "pos_test_ratio": "position",
    "vel_test_ratio": "velocity",
    "hgt_test_ratio": "height",
    "mag_test_ratio": "magnetometer",
    "tas_test_ratio": "airspeed",
    "hagl_test_ratio": "height above ground",
    "beta_test_ratio": "sideslip",
    "aid_gnss_pos": "GNSS position",
    "aid_gnss_vel": "GNSS velocity",
    "aid_gnss_hgt": "GNSS height",
    "aid_baro_hgt": "barometer height",
    "aid_mag": "magnetometer",
}


class Px4EstimatorDetector(Detector):
    """PX4's own EKF2 innovation test ratios per aiding source, over 1 for a set time."""

    name = "px4_estimator"
    requires_trace = False
    reads = frozenset()  # none of the filter's series: only the log's own estimator topics
    raw_topics = tuple(f"{topic}_{i}" for topic in TOPIC_NAMES for i in INSTANCES)
    defaults = {
        "ratio": 1.0,  # PX4's gate: innovation^2 / (gate^2 * variance) above 1 fails it
        "min_duration_s": 2.0,  # the ratio must stay above for this long
    }
    parameter_constraints = {
        "ratio": [multiplier_bound(0, 100, "times PX4's own gate (a test ratio over 1 fails it)")],
        "min_duration_s": [multiplier_bound(0, 3600, "s of a failing test before an alarm", closed="both")],
    }

    is_baseline = True  # PX4's own verdict: logscan's model-based alarms are reported against it

    @classmethod
    def signal_label(cls, signal: str) -> str | None:
        if signal == NOTHING:
            return "PX4's estimator test ratios (none in the log: nothing checked)"
        parts = signal.split(".")
        if len(parts) < 2 or parts[0] != PREFIX:
            return None
        source = parts[-1]
        words = SOURCE_WORDS.get(source, source.replace("aid_", "").replace("_test_ratio", "").replace("_", " "))
        instance = f", estimator {parts[1].removeprefix('ekf')}" if len(parts) > 2 else ""
        return f"PX4's own innovation test of the {words} (above 1: PX4 rejects it{instance})"

    @classmethod
    def signal_words(cls, signal: str) -> str | None:
        parts = signal.split(".")
        if len(parts) < 2 or parts[0] != PREFIX:
            return None
        source = parts[-1]
        words = SOURCE_WORDS.get(source, source.replace("aid_", "").replace("_test_ratio", "").replace("_", " "))
        return f"PX4's own test of the {words} failed"

    def _sources(self, raw: Mapping, metadata: Mapping) -> tuple[list, dict]:
        """[(instance, source, topic, (t ns, ratio))] and the gates used for ekf2_innovations."""
        parameters = (metadata or {}).get("ulog.parameters", {}) or {}
        found = []
        gates: dict[str, float] = {}
        for (topic, instance), fields in sorted(split_topics(raw, TOPIC_NAMES).items()):
            if topic == TEST_RATIOS:
                by_base: dict[str, list] = {}
                for field, channel in fields.items():
                    if not field.startswith("timestamp"):
                        by_base.setdefault(_base(field), []).append(channel)
                for base, channels in sorted(by_base.items()):
                    found.append((instance, base, topic, _max_over(channels)))
            elif topic == STATUS:
                for field in STATUS_FIELDS:
                    if field in fields:
                        found.append((instance, field, topic, _max_over([fields[field]])))
            elif topic.startswith(AID_PREFIX):
                channels = [c for f, c in fields.items() if _base(f) == "test_ratio"]
                if channels:
                    found.append((instance, f"aid_{topic[len(AID_PREFIX) :]}", topic, _max_over(channels)))
            elif topic == LEGACY:
                mode = int(_parameter(parameters, "EKF2_HGT_MODE", 0.0) or 0)
                for source, (innov, param, default) in LEGACY_SOURCES.items():
                    if source == "height":
                        source, param, default = _HEIGHT_BY_MODE.get(mode, _HEIGHT_BY_MODE[0])
                    gate = _parameter(parameters, param, default)
                    series = _legacy_ratio(fields, innov, gate)
                    if series is not None:
                        gates[source] = gate
                        found.append((instance, source, topic, series))
        return found, gates

    @staticmethod
    def _fused_only(found: list, raw: Mapping) -> list:
        """``found`` with each test-ratio sample NaN where its instance's estimator_status_flags say
        the source was not fused (the flags held from their latest sample; all kept without them),
        and each estimator_aid_src_* sample NaN where its own ``fused`` field is 0."""
        topics = split_topics(raw, TOPIC_NAMES)
        out = []
        for instance, source, topic, series in found:
            if series is not None:
                t, values = series
                mask = None
                if topic == TEST_RATIOS and source in FUSED_BY:
                    flags = topics.get((FLAGS, instance), {})
                    present = [flags[f] for f in FUSED_BY[source] if f in flags]
                    if present:
                        mask = np.zeros(t.shape, dtype=bool)
                        for flag in present:
                            mask |= np.nan_to_num(held(flag, t)) != 0
                elif topic.startswith(AID_PREFIX):
                    fused = topics.get((topic, instance), {}).get("fused")
                    if fused is not None and np.array_equal(fused.t, t):
                        mask = fused.values != 0
                if mask is not None:
                    series = (t, np.where(mask, values, np.nan))
            out.append((instance, source, topic, series))
        return out

    def _run(self, run, trace, **context) -> DetectorResult:
        result = self.new_result()
        raw = context.get("raw") or {}
        found, gates = self._sources(raw, context.get("metadata") or {})
        found = self._fused_only(found, raw)
        instances = {instance for instance, *_ in found}
        t_grid = run.t
        n = run.n_steps
        sources: dict[str, str] = {}
        persist: dict[str, int] = {}
        unused: list[str] = []
        gates_only: list[str] = []
        for instance, source, topic, series in found:
            name = f"{PREFIX}.ekf{instance}.{source}" if len(instances) > 1 else f"{PREFIX}.{source}"
            where = f"{topic}_{instance}"
            if gate_only(source):  # PX4's gate on a synthetic observation: no evidence of a fault
                gates_only.append(name)
                continue
            if series is None:
                result.warnings.append(f"px4_estimator: {where} {source}: fields with different sample times, skipped")
                continue
            statistic = on_grid(run, *series)
            valid = np.isfinite(statistic)
            if not valid.any():
                unused.append(name)
                continue
            n_persist = persist_count(t_grid[valid], float(self.min_duration_s))
            result.add_statistic(t_grid, name, statistic, upper=float(self.ratio), valid=valid, n_persist=n_persist)
            sources[name] = where
            persist[name] = n_persist
        if not sources:
            result.warnings.append(
                NO_RATIOS
                if not found
                else "px4_estimator: the log's PX4 estimator topics carry no test ratio (all zero or not finite)"
            )
            # never finite: the verdict lists it as not checked (logscan.verdict.coverage)
            result.add_statistic(t_grid, NOTHING, np.full(n, np.nan), upper=float(self.ratio), valid=np.zeros(n, bool))
        result.info["sources"] = sources
        result.info["n_persist"] = persist
        result.info["unused"] = unused
        result.info["gate_only"] = gates_only
        if gates:
            result.info["gates"] = gates
        return result
