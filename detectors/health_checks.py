"""What every group of the health checks shares: the PX4 topics they read, their words, and the
statistic each check puts on the grid (`HealthChecks._add`); when the vehicle was armed and flying."""

from __future__ import annotations

from typing import Any

import numpy as np

from logscan.detectors.base import Detector, DetectorResult
from logscan.detectors.raw_topics import held as _held
from logscan.detectors.raw_topics import on_grid, persist_count

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
    "battery_warning": "PX4's battery warning critical or worse",
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


class HealthChecks(Detector):
    """The health detector's shared plumbing (`logscan.detectors.health.HealthDetector`)."""

    # the state one run of the checks builds (set by HealthDetector._run)
    _result: DetectorResult
    _grid: Any
    _checks: dict[str, dict]
    _skipped: dict[str, str]
    _unmonitored: list[str]
    _never_armed: bool

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
        statistic = on_grid(self._grid, np.asarray(t_ns), np.asarray(values, dtype=np.float64))
        return self._add_on_grid(name, where, statistic, limit=limit, n_persist=n_persist, why=why,
                                 min_duration_s=min_duration_s)  # fmt: skip

    def _add_on_grid(
        self, name: str, where: str, statistic, *, limit, n_persist=None, why: str = "", min_duration_s=None
    ) -> bool:
        """`_add` of a statistic already on the grid (NaN: not judged)."""
        run = self._grid
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
