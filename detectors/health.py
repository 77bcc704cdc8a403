"""The `health` detector: plausibility checks on the PX4 topics of a log (no filter of its own).

Specified in docs/algorithms.md section 3c.

Each check reads the log's own PX4 topics (``raw_topics``, instances 0 to 3) and gives one
statistic ``health.<check>`` normalised so that its threshold is 1.0: a measured value over its
limit (``eph / EKF2_REQ_EPH``), or a flag. The alarm logic's test is strict (statistic > threshold),
so a count c that alarms when it reaches a limit L is stored as ``c / (L - 1/2)``: a flag (L = 1) is
0 or 2, "all n motor outputs saturated" is ``count / (n - 1/2)``. Every statistic alarms through the
shared logic with ``n_persist`` spanning ``min_duration_s`` at the source's sample rate on the grid.

Checks (a check whose topic or field is absent is skipped, listed in ``info["skipped"]`` and as a
`logscan.results.NotChecked` line; a sensor in the log that gave no valid sample over the whole
log, a battery whose ``connected`` is 0 all flight or a GNSS without a 3D fix all flight, is a
``partial`` one: the log is not fully checked, as with a measurement group without valid samples):

- battery (``battery_status``): ``cells * V_EMPTY / voltage_v``; a reading under 0.5 V while the
  battery says it is connected: ``health.battery_zero``;
- GNSS (``vehicle_gps_position``, else ``sensor_gps``), while armed when the arming state is
  known: fix lost after the first 3D fix, ``eph`` / ``epv`` over EKF2_REQ_EPH / EKF2_REQ_EPV while
  3D-fixed, ``jamming_indicator`` over ``jamming_limit``, and a sudden rise of the reported
  accuracy (eph, epv, s_variance_m_s over ``accuracy_jump`` times their median of the
  ``accuracy_window_s`` before: detectors/accuracy_jump.py);
- motors (``actuator_outputs``, ``actuator_motors``, ``actuator_armed`` / ``vehicle_status``):
  saturated share, one output at its max, an output at its stopped value while flying; judged
  only on outputs that drive motors PX4 commands to run (detectors/motor_outputs.py);
- IMU clipping (``sensor_combined``, ``vehicle_imu``), estimator faults (``estimator_status``),
  errors in the logged messages, and sensor timeouts (a gap of more than ``timeout_periods``
  median periods in any topic read).
"""

from __future__ import annotations

import numpy as np

from logscan.detectors.accuracy_jump import accuracy_jump
from logscan.detectors.base import Detector, DetectorResult
from logscan.detectors.motor_outputs import MotorGroup, motor_groups
from logscan.detectors.params import Interval, multiplier_bound
from logscan.detectors.raw_topics import grid_steps, in_span, on_grid, persist_count, skipped_lines, split_topics
from logscan.detectors.raw_topics import held as _held
from logscan.detectors.raw_topics import log_parameter as _parameter
from logscan.log import logged_messages
from logscan.results import NotChecked

PREFIX = "health"
INSTANCES = (0, 1, 2, 3)
BATTERY = "battery_status"
GPS = "vehicle_gps_position"
SENSOR_GPS = "sensor_gps"
OUTPUTS = "actuator_outputs"
MOTORS = "actuator_motors"
ARMED = "actuator_armed"
STATUS = "vehicle_status"
LAND = "vehicle_land_detected"
COMBINED = "sensor_combined"
IMU = "vehicle_imu"
ESTIMATOR = "estimator_status"
TOPIC_NAMES = (BATTERY, GPS, SENSOR_GPS, OUTPUTS, MOTORS, ARMED, STATUS, LAND, COMBINED, IMU, ESTIMATOR)
# published on change, not at a rate: a long interval is no timeout
EVENT_TOPICS = (ARMED, STATUS, LAND)

FLAG = 2.0  # a set flag: count 1 / (limit 1 - 1/2)
ZERO_VOLTAGE_V = 0.5  # a battery reading below this is "about 0 V"
CELL_EMPTY_V = 3.3  # per-cell empty voltage when the log has no BAT*_V_EMPTY
REQ_EPH_M = 3.0  # PX4's EKF2_REQ_EPH default
# PX4's EKF2 calls its GNSS checks (EKF2_REQ_EPH, EKF2_REQ_EPV, ...) failing only once they have
# failed for 5 s without a pass (gps_control.cpp: gps_checks_failing = isTimedOut(_last_gps_pass_us,
# 5 s)); a receiver over the limit for less is one PX4 keeps using, not a fault
GNSS_CHECKS_FAILING_S = 5.0
REQ_EPV_M = 5.0  # PX4's EKF2_REQ_EPV default
ARMED_STATE = 2  # vehicle_status.arming_state ARMED
LEVELS = ("EMERGENCY", "ALERT", "CRITICAL", "ERROR")  # pyulog's log_level_str, severe ones
MAX_LOGGED_ERRORS = 50

NO_TOPICS = (
    "health: the log has none of the PX4 topics the plausibility checks read "
    "(battery_status, vehicle_gps_position / sensor_gps, actuator_outputs, sensor_combined, "
    "vehicle_imu, estimator_status) and no logged messages"
)
NOTHING = f"{PREFIX}.checks"  # the statistic that stands for "nothing was checked" (never finite)


def _suffix(instance: int) -> str:
    return "" if instance == 0 else f".{instance}"


# Plain words for each check, said in an incident's headline instead of "<group> inconsistent"
CHECK_WORDS = {
    "battery": "battery voltage below empty",
    "battery_zero": "battery sensor reading about 0 V",
    "gnss_fix": "GNSS 3D fix lost",
    "gnss_eph": "GNSS horizontal accuracy worse than required",
    "gnss_epv": "GNSS vertical accuracy worse than required",
    "gnss_jamming": "GNSS jamming indicated",
    "gnss_accuracy_jump": "GNSS reported accuracy suddenly worse",
    "motor_saturated": "motors saturated",
    "motor_max": "a motor output at its maximum",
    "motor_zero": "a motor output at zero while flying",
    "imu_clipping": "IMU clipping",
    "estimator_fault": "PX4 estimator fault flags set",
    "logged_error": "the autopilot logged an error",
    "timeout": "a sensor topic stopped",
}


def _px4_gnss_passing(topics, t_ns: np.ndarray) -> np.ndarray | None:
    """At each time: whether PX4's own GNSS checks (``estimator_status_0.gps_check_fail_flags``
    all clear) passed within the last GNSS_CHECKS_FAILING_S, so PX4 did not call them failing;
    None when the log lacks the flags. PX4 judges its own receiver values, with its own filtering:
    where it saw a pass, a reading over the limit in ``vehicle_gps_position`` is not a fault."""
    channel = topics.get((ESTIMATOR, 0), {}).get("gps_check_fail_flags")
    if channel is None or not channel.values.size:
        return None
    t = np.asarray(channel.t)
    # failing is 5 s of failures seen: the log's first flags count as the latest pass (PX4's timer
    # before the log started is unknown), and before them nothing is known to fail
    pass_t = np.union1d(t[:1], t[np.nan_to_num(channel.values) == 0])
    latest = np.searchsorted(pass_t, t_ns, side="right") - 1
    last_pass = pass_t[np.maximum(latest, 0)]
    return (latest < 0) | ((np.asarray(t_ns) - last_pass) < GNSS_CHECKS_FAILING_S * 1e9)


class HealthDetector(Detector):
    """Plausibility checks on PX4's own topics: battery, GNSS, motors, clipping, faults, errors, timeouts."""

    name = "health"
    requires_trace = False
    reads = frozenset()  # none of the filter's series: only the log's own PX4 topics
    raw_topics = tuple(f"{topic}_{i}" for topic in TOPIC_NAMES for i in INSTANCES)
    defaults = {
        "min_duration_s": 1.0,  # a check must fail for this long (logged errors and timeouts: once)
        "jamming_limit": 80.0,  # GNSS jamming_indicator (0-255) above this is jamming
        "timeout_periods": 5.0,  # a gap of more than this many median periods is a timeout
        "accuracy_jump": 2.0,  # GNSS eph / epv / speed accuracy over this times its recent median
        "accuracy_window_s": 10.0,  # ... the median of the reports this long before it
    }
    parameter_constraints = {
        "min_duration_s": [multiplier_bound(0, 3600, "s of a failing check before an alarm", closed="both")],
        "jamming_limit": [
            Interval(float, 0, 255, closed="right", why="the indicator is 0-255: over 255 it would hide jamming")
        ],
        "timeout_periods": [multiplier_bound(1, 10_000, "median periods of silence before a timeout", closed="both")],
        "accuracy_jump": [multiplier_bound(1, 1000, "times the recent median accuracy", closed="neither")],
        "accuracy_window_s": [Interval(float, 0, None, closed="neither")],
    }

    # --- the shared plumbing -------------------------------------------------------------------

    @classmethod
    def signal_label(cls, signal: str) -> str | None:
        if signal == NOTHING:
            return "the autopilot's health topics (none in the log: nothing checked)"
        parts = signal.split(".", 2)
        words = CHECK_WORDS.get(parts[1]) if len(parts) > 1 and parts[0] == PREFIX else None
        if words is None or len(parts) == 2:
            return words
        if parts[1] == "timeout":
            return f"the topic {parts[2]} stopped arriving"
        return f"{words} ({parts[2]})"  # one instance: battery 1, imu0

    @classmethod
    def signal_words(cls, signal: str) -> str | None:
        parts = signal.split(".")
        return CHECK_WORDS.get(parts[1]) if len(parts) > 1 and parts[0] == PREFIX else None

    def _run(self, run, trace, **context) -> DetectorResult:
        result = self.new_result()
        raw = context.get("raw") or {}
        metadata = context.get("metadata") or {}
        parameters = metadata.get("ulog.parameters", {}) or {}
        topics = split_topics(raw, TOPIC_NAMES)
        self._result, self._grid = result, run
        self._checks: dict[str, dict] = {}
        self._skipped: dict[str, str] = {}
        self._unmonitored: list[str] = []  # sensors in the log without one valid sample: not checked
        try:
            armed = self._arming(topics)
            # never armed on the grid: every while-armed check has nothing to judge, said as such
            grid_ns = run.start_ns + np.round(np.asarray(run.t) * 1e9).astype(np.int64)
            self._never_armed = armed is not None and run.n_steps > 0 and not armed[1](grid_ns).any()
            self._battery(topics, parameters)
            self._gnss(topics, parameters, armed)
            self._motors(topics, parameters, armed)
            self._clipping(topics)
            self._estimator(topics)
            self._logged_errors(metadata)
            self._timeouts(topics, metadata)
        finally:
            self._result = self._grid = None
        n = run.n_steps
        if not topics:
            result.warnings.append(NO_TOPICS)
        if not self._checks:
            if topics and NO_TOPICS not in result.warnings:
                result.warnings.append("health: none of the log's PX4 topics had a sample to check on the grid")
            # never finite: the verdict lists it as not checked (logscan.verdict.coverage)
            result.add_statistic(run.t, NOTHING, np.full(n, np.nan), upper=1.0, valid=np.zeros(n, bool))
        result.info["checks"] = self._checks
        result.info["skipped"] = self._skipped
        result.not_checked = [NotChecked(reason, partial=True) for reason in self._unmonitored]
        result.not_checked += [NotChecked(line) for line in skipped_lines(self._skipped, PREFIX)]
        result.info["armed_from"] = armed[0] if armed else None
        return result

    def _add(
        self,
        name: str,
        where: str,
        t_ns,
        values,
        *,
        limit,
        n_persist: int | None = None,
        why: str = "",
        min_duration_s: float | None = None,
    ) -> bool:
        """Put ``values`` (at times ``t_ns``, NaN: not judged) on the grid and alarm over 1.0.
        False (and ``name`` listed as skipped, ``why`` saying when it is judged) when no sample
        lands on a grid step."""
        run = self._grid
        statistic = on_grid(run, np.asarray(t_ns), np.asarray(values, dtype=np.float64))
        valid = np.isfinite(statistic)
        if not valid.any():
            never = self._never_armed and "armed" in why
            self._skipped[name] = f"{where}: never armed in the log" if never else (
                f"{where}: no sample to judge on the analysis grid{why}"
            )  # fmt: skip
            return False
        if n_persist is None:
            seconds = float(self.min_duration_s) if min_duration_s is None else min_duration_s
            n_persist = persist_count(run.t[valid], seconds)
        self._result.add_statistic(run.t, name, statistic, upper=1.0, valid=valid, n_persist=n_persist)
        self._checks[name] = {"source": where, "limit": limit, "n_persist": n_persist}
        return True

    def _accuracy_jumps(self, fields, where: str, sfx: str, judged, while_: str) -> None:
        """``health.gnss_accuracy_jump.<field>``: each reported accuracy over ``accuracy_jump``
        times its recent median (detectors/accuracy_jump.py), judged where ``judged``."""
        for field in ("eph", "epv", "s_variance_m_s"):
            channel = fields.get(field)
            name = f"{PREFIX}.gnss_accuracy_jump.{field}{sfx}"
            if channel is None or channel.t.shape != judged.shape:
                self._skipped[name] = f"{where} has no {field}"
                continue
            ratio = accuracy_jump(channel.t, np.where(judged, channel.values, np.nan), float(self.accuracy_window_s))
            limit = {"times_recent_median": float(self.accuracy_jump), "window_s": float(self.accuracy_window_s)}
            limit["while"] = while_
            self._add(name, where, channel.t, ratio / float(self.accuracy_jump), limit=limit, why=f" ({while_})")

    def _arming(self, topics) -> tuple[str, object, object] | None:
        """(source, armed(t_ns) -> bool array, flying(t_ns) -> bool array), None when unknown."""
        armed_channel = topics.get((ARMED, 0), {}).get("armed")
        if armed_channel is not None:
            source = f"{ARMED}_0.armed"

            def armed(t_ns):
                return np.nan_to_num(_held(armed_channel, t_ns)) != 0

        else:
            state = topics.get((STATUS, 0), {}).get("arming_state")
            if state is None:
                return None
            source = f"{STATUS}_0.arming_state == {ARMED_STATE}"

            def armed(t_ns):
                return _held(state, t_ns) == ARMED_STATE

        landed = topics.get((LAND, 0), {}).get("landed")

        def flying(t_ns):
            out = armed(t_ns)
            if landed is not None:
                held = _held(landed, t_ns)
                out &= np.isfinite(held) & (held == 0)
            return out

        return source, armed, flying

    # --- 1. battery ------------------------------------------------------------------------------
    def _battery(self, topics, parameters) -> None:
        found = sorted(i for topic, i in topics if topic == BATTERY)
        if not found:
            self._skipped["battery"] = f"no {BATTERY} topic"
            return
        for instance in found:
            fields = topics[(BATTERY, instance)]
            where = f"{BATTERY}_{instance}"
            name = f"{PREFIX}.battery{_suffix(instance)}"
            voltage = fields.get("voltage_v")
            if voltage is None:
                self._skipped[name] = f"{where} has no voltage_v"
                continue
            t, v = voltage.t, voltage.values
            connected = fields.get("connected")
            on = np.ones(t.size, bool) if connected is None else np.nan_to_num(_held(connected, t)) != 0
            inside = in_span(self._grid, t)
            if connected is not None and inside.any() and not on[inside].any():
                seen = v[inside][np.isfinite(v[inside])]
                volts = f", voltage {seen.min():.2f}-{seen.max():.2f} V" if seen.size else ""
                self._unmonitored.append(f"battery not monitored: connected=0 all flight ({where}{volts})")
                continue
            k = instance + 1
            empty = _parameter(parameters, f"BAT{k}_V_EMPTY", "BAT_V_EMPTY")
            v_empty, empty_from = empty if empty else (CELL_EMPTY_V, "default")
            cells = np.full(t.size, np.nan)
            cells_from = None
            if "cell_count" in fields:
                cells = np.where(_held(fields["cell_count"], t) > 0, _held(fields["cell_count"], t), np.nan)
                cells_from = f"{where}.cell_count" if np.isfinite(cells).any() else None
            param = _parameter(parameters, f"BAT{k}_N_CELLS", "BAT_N_CELLS")
            if param is not None:
                if cells_from is None:
                    cells_from = param[1]
                cells = np.where(np.isfinite(cells), cells, param[0])
            with np.errstate(divide="ignore", invalid="ignore"):
                if cells_from is None:
                    self._skipped[name] = (
                        f"{where}: cell count unknown (no cell_count, no BAT{k}_N_CELLS / BAT_N_CELLS)"
                    )
                else:
                    limit = cells * v_empty
                    ok = on & np.isfinite(v) & (v >= ZERO_VOLTAGE_V)
                    cells_seen = cells[np.isfinite(cells)]
                    self._add(
                        name,
                        where,
                        t,
                        np.where(ok, limit / v, np.nan),
                        limit={
                            "empty_v": float(np.median(cells_seen)) * v_empty,
                            "cells": float(np.median(cells_seen)),
                            "cells_from": cells_from,
                            "cell_empty_v": v_empty,
                            "cell_empty_from": empty_from,
                        },
                    )
                zero = np.where(on & np.isfinite(v), np.where(v < ZERO_VOLTAGE_V, FLAG, 0.0), np.nan)
            self._add(
                f"{PREFIX}.battery_zero{_suffix(instance)}",
                where,
                t,
                zero,
                limit={"below_v": ZERO_VOLTAGE_V, "while": "connected" if connected is not None else "always"},
            )

    # --- 2. GNSS ---------------------------------------------------------------------------------
    def _gnss(self, topics, parameters, armed) -> None:
        topic = GPS if any(t == GPS for t, _ in topics) else SENSOR_GPS
        found = sorted(i for t, i in topics if t == topic)
        if not found:
            self._skipped["gnss"] = f"no {GPS} or {SENSOR_GPS} topic"
            return
        eph_limit, eph_from = _parameter(parameters, "EKF2_REQ_EPH") or (REQ_EPH_M, "default")
        epv_limit, epv_from = _parameter(parameters, "EKF2_REQ_EPV") or (REQ_EPV_M, "default")
        for instance in found:
            fields = topics[(topic, instance)]
            where = f"{topic}_{instance}"
            sfx = _suffix(instance)
            any_channel = next(iter(fields.values()))
            t = any_channel.t
            px4_passing = _px4_gnss_passing(topics, t)
            gate = np.ones(t.size, bool) if armed is None else armed[1](t)
            while_ = "armed" if armed is not None else "always (arming state unknown)"
            fixed = np.ones(t.size, bool)  # 3D-fixed now (all when fix_type is absent)
            fix = fields.get("fix_type")
            if fix is not None and np.array_equal(fix.t, t):
                three_d = fix.values >= 3
                first = np.flatnonzero(three_d)
                inside = in_span(self._grid, t)
                if inside.any() and not three_d[inside].any():
                    best = int(np.nanmax(fix.values)) if np.isfinite(fix.values).any() else None
                    self._unmonitored.append(
                        f"GNSS: no 3D fix all flight ({where}.fix_type"
                        + (f" at most {best})" if best is not None else " never set)")
                    )
                    fixed = np.zeros(t.size, bool)
                elif first.size == 0:
                    self._skipped[f"{PREFIX}.gnss_fix{sfx}"] = f"{where}: no 3D fix in the log"
                    fixed = three_d
                else:
                    after = np.arange(t.size) >= first[0]
                    flag = np.where(three_d, 0.0, FLAG)
                    self._add(
                        f"{PREFIX}.gnss_fix{sfx}",
                        where,
                        t,
                        np.where(after & gate, flag, np.nan),
                        limit={
                            "fix_type_below": 3,
                            "after_s": (t[first[0]] - self._grid.start_ns) / 1e9,
                            "while": while_,
                        },
                        why=f" ({while_}, after the first 3D fix)",
                    )
                    fixed = three_d
            else:
                self._skipped[f"{PREFIX}.gnss_fix{sfx}"] = f"{where} has no fix_type"
            for field, limit, source in (("eph", eph_limit, eph_from), ("epv", epv_limit, epv_from)):
                name = f"{PREFIX}.gnss_{field}{sfx}"
                if not fixed.any():  # judged while 3D-fixed only: the line above says it
                    continue
                channel = fields.get(field)
                if channel is None or not np.array_equal(channel.t, t):
                    self._skipped[name] = f"{where} has no {field}"
                    continue
                values = np.where(gate & fixed, channel.values / limit, np.nan)
                if px4_passing is not None:  # PX4's own checks passed within 5 s: not failing
                    values = np.where(px4_passing, np.minimum(values, 1.0), values)
                self._add(
                    name,
                    where,
                    t,
                    values,
                    limit={"m": limit, "from": source, "while": f"{while_}, 3D fix", "for_s": GNSS_CHECKS_FAILING_S},
                    why=f" ({while_}, 3D fix)",
                    # PX4's own pass/fail timer, when logged, already waited the 5 s
                    min_duration_s=None if px4_passing is not None else GNSS_CHECKS_FAILING_S,
                )
            if fixed.any():  # judged while 3D-fixed only, as eph / epv
                self._accuracy_jumps(fields, where, sfx, gate & fixed, f"{while_}, 3D fix")
            jam = fields.get("jamming_indicator")
            name = f"{PREFIX}.gnss_jamming{sfx}"
            if jam is None or not np.array_equal(jam.t, t):
                self._skipped[name] = f"{where} has no jamming_indicator"
            else:
                values = np.where(gate, jam.values / float(self.jamming_limit), np.nan)
                limit = {"indicator": float(self.jamming_limit), "while": while_}
                self._add(name, where, t, values, limit=limit, why=f" ({while_})")

    # --- 3. motors (which outputs are motors and their levels: motor_outputs.py) ----------------
    def _motors(self, topics, parameters, armed) -> None:
        if not any(t == OUTPUTS for t, _ in topics):
            self._skipped["motors"] = f"no {OUTPUTS} topic"
            return
        if armed is None:
            self._skipped["motors"] = f"arming state unknown (no {ARMED}.armed, no {STATUS}.arming_state)"
            return
        groups, skipped = motor_groups(topics, parameters, armed)
        for sfx, why in skipped.items():
            self._skipped[f"{PREFIX}.motor_saturated{sfx}"] = why
        for group in groups:
            self._motor_checks(group, armed)

    def _motor_checks(self, group: MotorGroup, armed) -> None:
        """Saturated share, each motor at its max (while armed), any motor stopped (while flying),
        each judged only where PX4 commands that motor to run (``group.runs``)."""
        t, values, runs, label, where = group.t, group.values, group.runs, group.label, group.where
        sfx = f".{label}" if label else ""
        on = armed[1](t)
        fly = armed[2](t)
        saturated = (values >= group.top[None, :] - 0.5) & runs
        n_runs = runs.sum(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            share = np.where(on & (n_runs > 0), saturated.sum(axis=1) / (n_runs - 0.5), np.nan)
        why = " (armed)"
        limits = group.limits
        self._add(f"{PREFIX}.motor_saturated{sfx}", where, t, share, limit={**limits, "all_outputs": True}, why=why)
        for j, k in enumerate(group.outputs):
            flag = np.where(on & runs[:, j], np.where(saturated[:, j], FLAG, 0.0), np.nan)
            self._add(
                f"{PREFIX}.motor_max.{label}{k + 1}",
                where,
                t,
                flag,
                limit={"output": f"{label}{k + 1}", "field": f"output[{k}]", "max": float(group.top[j])},
                why=why,
            )
        stopped = group.stopped & runs & fly[:, None]
        judged = fly & (n_runs > 0)
        zero = np.where(judged, np.where(stopped.any(axis=1), FLAG, 0.0), np.nan)
        name = f"{PREFIX}.motor_zero{sfx}"
        if self._add(name, where, t, zero, limit={**limits, "while": "armed and flying"}, why=" (armed and flying)"):
            self._checks[name]["outputs_stopped"] = [
                f"{label}{k + 1}" for j, k in enumerate(group.outputs) if stopped[:, j].any()
            ]

    # --- 4. IMU clipping, 5. estimator faults ----------------------------------------------------
    def _flag_check(self, topics, topic: str, field: str, name_of) -> bool:
        ran = False
        for (t_name, instance), fields in sorted(topics.items()):
            if t_name != topic:
                continue
            channel = fields.get(field)
            name = name_of(instance)
            if channel is None:
                self._skipped[name] = f"{topic}_{instance} has no {field}"
                continue
            values = np.where(np.isfinite(channel.values), np.where(channel.values != 0, FLAG, 0.0), np.nan)
            ran |= self._add(name, f"{topic}_{instance}", channel.t, values, limit={field: "!= 0"})
        return ran

    def _clipping(self, topics) -> None:
        if not any(t in (COMBINED, IMU) for t, _ in topics):
            self._skipped["imu_clipping"] = f"no {COMBINED} or {IMU} topic"
            return
        self._flag_check(topics, COMBINED, "accelerometer_clipping", lambda i: f"{PREFIX}.imu_clipping{_suffix(i)}")
        self._flag_check(topics, IMU, "delta_velocity_clipping", lambda i: f"{PREFIX}.imu_clipping.imu{i}")

    def _estimator(self, topics) -> None:
        if not any(t == ESTIMATOR for t, _ in topics):
            self._skipped["estimator_fault"] = f"no {ESTIMATOR} topic"
            return
        self._flag_check(topics, ESTIMATOR, "filter_fault_flags", lambda i: f"{PREFIX}.estimator_fault{_suffix(i)}")
        failed = {}
        for (topic, instance), fields in sorted(topics.items()):
            channel = fields.get("gps_check_fail_flags") if topic == ESTIMATOR else None
            if channel is not None and channel.values.size:
                bits = np.bitwise_or.reduce(np.nan_to_num(channel.values).astype(np.int64))
                failed[f"{topic}_{instance}"] = {
                    "bits_ever_set": int(bits),
                    "share_of_samples": float(np.mean(channel.values != 0)),
                }
        if failed:
            self._result.info["gps_check_fail_flags"] = failed

    # --- 6. logged errors ------------------------------------------------------------------------
    def _logged_errors(self, metadata) -> None:
        messages = metadata.get("ulog.messages")
        name = f"{PREFIX}.logged_error"
        if messages is None:
            self._skipped[name] = "the log carries no logged messages (not a ULog)"
            return
        run = self._grid
        found = logged_messages(metadata, run.start_ns, LEVELS, limit=None)
        t_ns = np.array([m.t_ns for m in found], dtype=np.int64)
        statistic = np.nan_to_num(on_grid(run, t_ns, np.full(t_ns.size, FLAG)))
        landed = grid_steps(run, t_ns)[1] if found else np.zeros(0, bool)
        errors = [
            {"time": m.t, "level": m.level, "text": m.text, "on_grid": bool(on)}
            for m, on in zip(found[:MAX_LOGGED_ERRORS], landed.tolist())
        ]
        if run.n_steps:
            run_result = self._result
            run_result.add_statistic(run.t, name, statistic, upper=1.0, valid=np.ones(run.n_steps, bool), n_persist=1)
            self._checks[name] = {"source": "ulog.messages", "limit": {"levels": list(LEVELS)}, "n_persist": 1}
        self._result.info["logged_errors"] = errors

    # --- 7. sensor timeouts ----------------------------------------------------------------------
    def _timeouts(self, topics, metadata) -> None:
        periods = float(self.timeout_periods)
        for (topic, instance), fields in sorted(topics.items()):
            if topic in EVENT_TOPICS:
                continue
            where = f"{topic}_{instance}"
            name = f"{PREFIX}.timeout.{where}"
            t = next(iter(fields.values())).t
            if t.size < 4:
                self._skipped[name] = f"{where}: fewer than 4 samples"
                continue
            gaps = np.diff(t).astype(np.float64)
            period = float(np.median(gaps))
            if not period > 0:
                self._skipped[name] = f"{where}: no sample period"
                continue
            ratio = np.full(t.size, np.nan)
            # the first interval is not judged: PX4's logger writes a topic's latest sample when it
            # subscribes, which can be older than the topic's rate says
            ratio[2:] = gaps[1:] / (periods * period)
            limit = {"gap_s": periods * period / 1e9, "median_period_s": period / 1e9}
            self._add(name, where, t, ratio, limit=limit, n_persist=1)
        dropouts = (metadata.get("ulog.log") or {}).get("dropouts")
        if dropouts not in (None, "0"):
            self._result.info["logging_dropouts"] = (
                f"{dropouts} logging dropout(s) in the log: a timeout may be data the logger lost, not a sensor"
            )
