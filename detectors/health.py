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

- battery (``battery_status``): ``cells * V_EMPTY / voltage_filtered_v`` (else ``voltage_v``); a
  reading under 0.5 V while the battery says it is connected: ``health.battery_zero``; PX4's own
  ``warning`` at CRITICAL or worse: ``health.battery_warning``;
- GNSS (``vehicle_gps_position``, else ``sensor_gps``), while armed when the arming state is
  known: fix lost after the first 3D fix, ``eph`` / ``epv`` over EKF2_REQ_EPH / EKF2_REQ_EPV while
  3D-fixed, ``jamming_indicator`` over ``jamming_limit``, and a sudden rise of the reported
  accuracy (eph, epv, s_variance_m_s over ``accuracy_jump`` times their median of the 3D-fixed
  reports of the ``accuracy_window_s`` before, armed or not: detectors/accuracy_jump.py);
- motors (``actuator_outputs``, ``actuator_motors``, ``actuator_armed`` / ``vehicle_status``):
  saturated share, one output at its max, an output at its stopped value while flying; judged
  only on outputs that drive motors PX4 commands to run (detectors/motor_outputs.py);
- IMU clipping (``sensor_combined``, ``vehicle_imu``), estimator faults (``estimator_status``),
  errors in the logged messages, and sensor timeouts (a gap of more than ``timeout_periods``
  median periods in any topic read).
"""

from __future__ import annotations

import numpy as np

from logscan.detectors.base import DetectorResult
from logscan.detectors.health_checks import (
    CHECK_WORDS,
    INSTANCES,
    NO_TOPICS,
    NOTHING,
    PREFIX,
    TOPIC_NAMES,
)
from logscan.detectors.health_events import EventChecks
from logscan.detectors.health_gnss import GnssChecks
from logscan.detectors.health_power import PowerChecks
from logscan.detectors.params import Interval, multiplier_bound
from logscan.detectors.raw_topics import skipped_lines, split_topics
from logscan.results import NotChecked


class HealthDetector(PowerChecks, GnssChecks, EventChecks):
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
        "accuracy_window_s": 10.0,  # ... the median of the 3D-fixed reports this long before it
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
            del self._result, self._grid  # the run's state, not the detector's
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
