"""A-TFM on redundant sensors: weak and strong inconsistency with a speed lookup table.

Specified in docs/algorithms.md section 4 (from the adaptive transient fault model thesis,
chapter II). Per `[redundant.<group>]` of the profile:

- Detection grid: the rate of the group's slowest sensor; faster sensors are sampled onto it by
  taking their latest reading (the aligned run's hold), never by averaging.
- Training (`fit`, from healthy runs; `logscan train`): per sensor and mode value (the profile's
  `[mode]` channel, e.g. the commanded speed), the error against the median of the others on
  segments of one mode value (a settle time after each change dropped), e(eps, w) for every eps and
  window, the knee per window, the knees at the detection window w as the table row, and the
  monotone envelope of eps over the mode values (`logscan.redundant.tfm`).
- Detection: the row is the smallest trained mode >= max(commanded, measured - margin), measured
  being the median of the sensors; above the top row the top row is used with a warning.
  Intervals [y_i - eps_i, y_i + eps_i]; WI_ij when two do not overlap; SI_ij when the WI count over
  the last w samples exceeds e_i + e_j: one statistic per pair (the count against e_i + e_j),
  alarms closer than w samples merged. Attribution: a sensor in SI with every other sensor (a
  majority for groups of 4+) is named; otherwise the pair.
- Fusion (thesis chapter III): the group's fused signals as extras (`logscan.redundant.fusion`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from logscan.detectors.base import Detector, DetectorResult, Needs, decode_state_value
from logscan.detectors.modes import mode_segments
from logscan.detectors.params import Interval, Options, RealList
from logscan.detectors.words import group_words
from logscan.docs import doc_url
from logscan.errors import NotTrainedError, ProfileError
from logscan.redundant.fusion import fuse_all, rmse
from logscan.redundant.tfm import (
    attribute,
    monotone_envelope,
    reference_errors,
    select_rows,
    strong_inconsistency,
    train_sensor,
)

EXTRA_CAPTIONS = {
    "mode": "The commanded mode value and the lookup-table row in use (the next higher trained mode value than "
    "max(commanded, measured - margin)). Normal: the row follows the command, one step up now and then at a "
    "row's own speed.",
    "fused": "The group's sensors fused by each method of the thesis's chapter III (average, moving average, "
    "median, iterative filter, Marzullo's interval midpoint, hybrid = median). Normal: the methods agree; an "
    "attacked sensor pulls the average away from the median and Marzullo.",
}
# logs that embed their profile need no --profile; with a profile file, add --profile FILE
TRAIN_COMMAND = "logscan train HEALTHY_LOG... -o tables.json"


@dataclass
class GroupSamples:
    """One redundant group on its detection grid: steps of the analysis grid, readings, mode."""

    name: str
    sensors: list[str]
    channels: list[str]
    steps: np.ndarray  # (M,) indices into the analysis grid
    t: np.ndarray  # (M,) their times, s since the log's start
    values: np.ndarray  # (M, s) readings in the group's unit (NaN: none within the staleness limit)
    mode: np.ndarray  # (M,) mode value (NaN: none)
    dt: float  # detection period, s


def detection_grid(run, name: str) -> GroupSamples:
    """The redundant group ``name`` of an aligned run sampled at its slowest sensor's rate."""
    group = run.redundant[name]
    n = run.n_steps
    if group.rate_hz:
        rate = float(group.rate_hz)
    else:  # each sensor's rate from the steps where it had a new reading
        fresh = group.channel_fresh if group.channel_fresh is not None else group.fresh[:, None]
        counts = np.asarray(fresh, dtype=bool).sum(axis=0)
        rate = float(counts.min()) / max(n * run.dt, run.dt) if counts.size else 1.0 / run.dt
    period = max(int(round(1.0 / (max(rate, 1e-9) * run.dt))), 1)
    steps = np.arange(period - 1, n, period)
    mode = run.mode[steps] if run.mode is not None else np.full(steps.size, np.nan)
    values = np.asarray(group.z, dtype=np.float64).reshape(n, -1)[steps]
    sensors = list(group.labels or group.channels)
    mode = np.asarray(mode, dtype=np.float64)
    return GroupSamples(name, sensors, list(group.channels), steps, run.t[steps], values, mode, period * run.dt)


def train_table(
    sensors: list[str], segments: dict[float, list[np.ndarray]], windows: list[int], w: int, eps_points: int
) -> dict:
    """The lookup table of one group from its error segments by mode value ((M, s) arrays): per
    sensor and mode, e(eps, w) for every window and its knee (`logscan.redundant.tfm.train_sensor`); the
    row is the knee at the detection window ``w``; eps then takes its monotone envelope over the
    mode values. Keeps the curves for the training report."""
    modes = sorted(segments)
    at = windows.index(w)
    eps = np.zeros((len(modes), len(sensors)))
    e = np.zeros((len(modes), len(sensors)), dtype=np.int64)
    curves = []
    for r, value in enumerate(modes):
        row = []
        for i in range(len(sensors)):
            trained = train_sensor([seg[:, i] for seg in segments[value]], tuple(windows), eps_points)
            eps[r, i], e[r, i] = trained.knees[at].eps, trained.knees[at].e
            row.append({
                "eps": trained.eps, "counts": trained.counts, "n_samples": int(trained.n_samples),
                "knees": [[k.w, float(k.eps), int(k.e)] for k in trained.knees],
            })  # fmt: skip
        curves.append(row)
    knees = eps.copy()
    for i in range(len(sensors)):
        eps[:, i] = monotone_envelope(eps[:, i])
    return {
        "sensors": list(sensors), "modes": np.asarray(modes), "w": int(w), "windows": list(windows),
        "eps": eps, "eps_knee": knees, "e": e, "curves": curves,
    }  # fmt: skip


def check_windows(detector: Detector) -> None:
    """``windows`` are positive integers and the detection ``window`` is one of them."""
    windows = detector.params["windows"]
    if not all(isinstance(w, int) and not isinstance(w, bool) and w >= 1 for w in windows):
        raise ProfileError(f"detector {detector.name!r}: windows must be a list of positive integers, got {windows!r}")
    if detector.params["window"] not in windows:
        raise ProfileError(f"detector {detector.name!r}: window {detector.params['window']} must be one of {windows}")


def table_rows(detector: str, modes: np.ndarray, row, margin: float, commanded: np.ndarray, measured: np.ndarray):
    """(row per step, above the top row per step): "next higher" by max(commanded, measured -
    margin) when ``row`` is "adaptive", else the trained mode value ``row`` throughout."""
    if row == "adaptive":
        return select_rows(modes, commanded, measured, margin)
    fixed = np.flatnonzero(np.isclose(modes, float(row)))
    if fixed.size == 0:
        raise ProfileError(
            f"detector {detector!r}: row {row!r} is not a trained mode value",
            hint="trained: " + ", ".join(f"{m:g}" for m in modes),
        )
    return np.full(commanded.size, int(fixed[0])), np.zeros(commanded.size, dtype=bool)


# The lookup-table parameters of every transient-fault-model detector (atfm, atfm_residual)
TABLE_DEFAULTS: dict[str, Any] = {
    "window": 100,  # w, the detection window
    "windows": [25, 50, 100, 200],  # windows whose e(eps, w) curves are trained (w among them)
    "settle_s": 5.0,  # dropped after every mode change when training
    "row": "adaptive",  # "adaptive", or a trained mode value to use throughout (a fixed table)
    "eps_points": 201,
}
TABLE_CONSTRAINTS: dict[str, list] = {
    "window": [Interval(int, 1, None)],
    "windows": [RealList()],  # positive integers, checked by check_windows
    "settle_s": [Interval(float, 0, None)],
    "row": [Options("adaptive"), Interval(float, 0, None), Interval(int, 0, None)],
    "eps_points": [Interval(int, 200, None)],
}
TABLE_FIT_PARAMS = ("window", "windows", "settle_s", "eps_points")


class AtfmDetector(Detector):
    """A-TFM: weak/strong inconsistency of redundant sensors with a trained speed lookup table."""

    name = "atfm"
    requires_fit = True
    requires_trace = False
    reads = frozenset({"mode", "redundant"})
    trained_attributes = ("tables_",)
    fit_params = TABLE_FIT_PARAMS
    defaults = {
        **TABLE_DEFAULTS,  # window: w in samples of the detection grid
        "margin": 0.05,  # selection value = max(commanded, measured - margin)
        "fusion_window": 5,  # moving-average fusion window, samples
    }
    parameter_constraints = {
        **TABLE_CONSTRAINTS,
        "margin": [Interval(float, 0, None)],
        "fusion_window": [Interval(int, 1, None)],
    }

    @classmethod
    def signal_label(cls, signal: str) -> str | None:
        parts = signal.split(".", 2)
        if len(parts) != 3 or parts[0] != "atfm":
            return None
        _, group, sensor = parts
        if "~" in sensor:  # a pair's strong inconsistency
            a, b = (group_words(s) for s in sensor.split("~", 1))
            return f"{a} and {b} disagree longer than a healthy transient does (A-TFM, {group_words(group)})"
        return f"{group_words(sensor)} disagrees with the other redundant sensors (A-TFM, named sensor)"

    def check_params(self) -> None:
        super().check_params()
        check_windows(self)

    def needs(self, run=None) -> Needs:
        return Needs()

    @classmethod
    def asked_for_by(cls, profile) -> bool:
        return bool(profile.redundant)

    @classmethod
    def state_lines(cls, state) -> list[str]:
        """The lookup table of each group: eps (e) per sensor and mode value."""
        lines = []
        for group, table in decode_state_value(state["state"]["tables_"]).items():
            sensors, modes, eps, e = table["sensors"], table["modes"], table["eps"], table["e"]
            lines.append(f"  {cls.name} {group}: w = {table['w']}, eps (e) per mode value")
            lines.append("    mode  " + "".join(f"{s:>16}" for s in sensors))
            for r, mode in enumerate(modes):
                cells = "".join(f"{eps[r, i]:>10.4g} ({int(e[r, i]):>3})" for i in range(len(sensors)))
                lines.append(f"    {mode:<5g} {cells}")
        return lines

    def check_trained(self) -> None:
        if not hasattr(self, "tables_"):
            raise NotTrainedError(
                "detector 'atfm' has no lookup table",
                hint=f"train one with `{TRAIN_COMMAND}` (and --profile FILE when the logs embed none), then "
                "pass --tables tables.json (or set the profile's `tables` key)",
            )

    # --- training -----------------------------------------------------------------------------------
    def _fit(self, runs, traces, **context) -> None:
        names = _redundant_names(runs)
        tables = {}
        for name in names:
            # errors per (mode value, sensor): one segment per run of that mode in each log
            segments: dict[float, list[np.ndarray]] = {}
            sensors: list[str] = []
            for run in runs:
                if name not in run.redundant:
                    continue
                samples = detection_grid(run, name)
                sensors = samples.sensors
                errors = reference_errors(samples.values)
                settle = int(round(self.settle_s / samples.dt))
                for value, first, stop in mode_segments(samples.mode, settle):
                    segments.setdefault(value, []).append(errors[first:stop])
            if not segments:
                raise NotTrainedError(
                    f"detector 'atfm': no samples of redundant group {name!r} with a mode value to train on",
                    hint="the training logs need the profile's [mode] channel and the group's sensors",
                )
            tables[name] = train_table(
                sensors, segments, [int(w) for w in self.windows], int(self.window), int(self.eps_points)
            )
        self.tables_ = tables

    # --- detection ----------------------------------------------------------------------------------
    def _table(self, name: str) -> dict:
        table = self.tables_.get(name)
        if table is None:
            raise NotTrainedError(
                f"detector 'atfm': the tables have no redundant group {name!r}",
                hint=f"retrain with `{TRAIN_COMMAND}` on logs of this profile",
            )
        return table

    def _run(self, run, trace, **context) -> DetectorResult:
        result = self.new_result()
        t = run.t
        for name in run.redundant:
            table = self._table(name)
            samples = detection_grid(run, name)
            modes, w = np.asarray(table["modes"], dtype=np.float64), int(table["w"])
            eps_rows, e_rows = np.asarray(table["eps"], dtype=np.float64), np.asarray(table["e"])
            if len(table["sensors"]) != samples.values.shape[1]:
                raise NotTrainedError(
                    f"detector 'atfm': group {name!r} has {samples.values.shape[1]} sensors, its table "
                    f"{len(table['sensors'])}",
                    hint=f"retrain with `{TRAIN_COMMAND}`",
                )
            measured = _median(samples.values)
            rows, _ = self._rows(modes, samples.mode, measured)
            # beyond the top row: commanded above it, or measured clearly above it (noise at the top
            # speed puts measured - margin over it now and then; the top row is then right)
            above = (samples.mode > modes[-1] + 1e-9) | (measured - 2.0 * float(self.margin) > modes[-1])
            if above.any():
                result.warnings.append(
                    f"{name}: {above.sum() * samples.dt:.1f} s above the table's top row ({modes[-1]:g}): "
                    "the top row was used (train at higher mode values to cover them)"
                )
            eps, e = eps_rows[rows], e_rows[rows]
            pairs = strong_inconsistency(samples.values, eps, e, w)
            warm = np.zeros(t.size, dtype=bool)
            warm[samples.steps[: max(w - 1, 0)]] = True  # a full window first
            options = {"warmup": warm, "hold_off_s": w * samples.dt, "check": name}  # closer than w: merged
            si = {}
            for (i, j), (count, threshold) in pairs.items():
                signal = f"atfm.{name}.{table['sensors'][i]}~{table['sensors'][j]}"
                statistic, upper, valid = _on_grid(t.size, samples.steps, count, threshold)
                result.add_statistic(t, signal, statistic, upper=upper, valid=valid, **options)
                si[(i, j)] = count > threshold
            for i, ratio in enumerate(_named_ratio(pairs, len(table["sensors"]))):
                # the sensor named: in SI with every other (a majority in groups of 4+), as the
                # measurement group its channel belongs to, so the incident names that sensor
                signal = f"atfm.{_sensor_label(run, samples.channels[i], name)}.{table['sensors'][i]}"
                statistic, upper, valid = _on_grid(t.size, samples.steps, ratio, np.ones(ratio.size))
                result.add_statistic(t, signal, statistic, upper=upper, valid=valid, **options)
            self._attribute(result, name, table["sensors"], samples, si, attribute)
            fused = self._extras(result, t.size, name, samples, modes, rows, eps)
            truth = context.get("truth")
            if truth and truth.get("events"):
                result.info[f"fusion RMSE vs fault-free.{name}"] = self._fusion_rmse(samples, eps, fused, truth)
        result.info["window"] = int(self.window)
        result.info["row"] = self.row
        result.info["extra_captions"] = EXTRA_CAPTIONS
        return result

    def _rows(self, modes: np.ndarray, commanded: np.ndarray, measured: np.ndarray):
        return table_rows(self.name, modes, self.row, float(self.margin), commanded, measured)

    @staticmethod
    def _attribute(result, name, sensors, samples, si, attribute) -> None:
        """Name the sensor (or the pair) behind each SI stretch, in the result's info."""
        if not si:
            return
        named = attribute(si, len(sensors))
        any_si = np.logical_or.reduce(list(si.values()))
        lines = []
        for i, flags in enumerate(named):
            if flags.any():
                lines.append(f"{sensors[i]}: in SI with every other sensor for {flags.sum() * samples.dt:.1f} s")
        for (i, j), flags in si.items():
            alone = flags & ~np.logical_or.reduce(named)
            if alone.any():
                seconds = alone.sum() * samples.dt
                lines.append(f"{sensors[i]}~{sensors[j]}: pair in SI, no single sensor named, {seconds:.1f} s")
        if any_si.any():
            result.info[f"attribution.{name}"] = "; ".join(lines)

    def _extras(self, result, grid: int, name, samples, modes, rows, eps) -> None:
        """The mode value, the table row in use and the fused signals, on the analysis grid."""
        selection = np.full(grid, np.nan, dtype=np.float32)
        selection[samples.steps] = modes[rows]
        result.extras[f"{name} row in use.mode"] = selection
        mode = np.full(grid, np.nan, dtype=np.float32)
        mode[samples.steps] = samples.mode
        result.extras[f"{name} commanded.mode"] = mode
        fused = fuse_all(samples.values, eps, int(self.fusion_window))
        for method, values in fused.items():
            out = np.full(grid, np.nan, dtype=np.float32)
            out[samples.steps] = values
            result.extras[f"{name} {method}.fused"] = out
        return fused

    def _fusion_rmse(self, samples: GroupSamples, eps: np.ndarray, fused: dict, truth: dict) -> str:
        """Each fusion method's RMSE against the same method on the fault-free readings: the
        readings of the sensors the truth's fault events name are dropped while those last (the
        thesis's chapter III comparison of the methods under attack)."""
        clean = samples.values.copy()
        t = samples.t
        touched = False
        for event in truth.get("events") or []:
            columns = [i for i, ch in enumerate(samples.channels) if ch in (event.get("channels") or [])]
            end = event.get("end")
            during = (t >= float(event.get("start", 0.0))) & (t <= (np.inf if end is None else float(end)))
            for i in columns:
                clean[during, i] = np.nan
                touched = True
        if not touched:
            return "no fault event on these sensors"
        reference = fuse_all(clean, eps, int(self.fusion_window))
        return ", ".join(f"{method} {rmse(fused[method], reference[method]):.3g}" for method in fused)


def _named_ratio(pairs: dict, n_sensors: int) -> list[np.ndarray]:
    """Per sensor (groups of 3+), how far it is into SI with the others it must disagree with to be
    named: the k-th largest over its pairs of WI count / (e_i + e_j + 1/2), k = every other sensor
    (3 sensors) or a majority of them (4+). Counts are integers, so the ratio exceeds 1 exactly
    when count > e_i + e_j: > 1 is "named" (`logscan.redundant.tfm.attribute`'s rule), with a peak ratio."""
    if n_sensors < 3:
        return []
    others = n_sensors - 1
    k = others if n_sensors == 3 else others // 2 + 1
    out = []
    for i in range(n_sensors):
        ratio = np.stack([
            count / (threshold + 0.5) for (a, b), (count, threshold) in pairs.items() if i in (a, b)
        ]).astype(np.float64)  # fmt: skip
        out.append(-np.sort(-ratio, axis=0)[k - 1])
    return out


def _sensor_label(run, channel: str, group: str) -> str:
    """The measurement group a redundant sensor's channel belongs to (its name in incidents), else
    the redundant group's name."""
    for name, measured in run.groups.items():
        if channel in measured.channels:
            return name
    return group


def _redundant_names(runs) -> list[str]:
    names: list[str] = []
    for run in runs:
        names.extend(n for n in run.redundant if n not in names)
    if not names:
        raise ProfileError(
            "detector 'atfm' needs a [redundant.<name>] group of sensors in the profile",
            hint=f"see {doc_url('profiles.md')}, section [redundant]",
        )
    return names


def _median(values: np.ndarray) -> np.ndarray:
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # steps without any reading
        return np.nanmedian(values, axis=1)


def _on_grid(n: int, steps: np.ndarray, count: np.ndarray, threshold: np.ndarray):
    """(statistic, upper, valid) on the analysis grid: the detection grid's values at its steps."""
    statistic = np.full(n, np.nan)
    upper = np.full(n, np.nan)
    valid = np.zeros(n, dtype=bool)
    statistic[steps] = count
    upper[steps] = threshold
    valid[steps] = True
    return statistic, upper, valid
