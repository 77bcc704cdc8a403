"""The health checks of the power chain: battery voltage and state, motor outputs (DShot or PWM)."""

from __future__ import annotations

import numpy as np

from logscan.detectors.health_checks import (
    ARMED,
    BATTERY,
    CELL_EMPTY_V,
    FLAG,
    OUTPUTS,
    PREFIX,
    STATUS,
    ZERO_VOLTAGE_V,
    HealthChecks,
    _suffix,
)
from logscan.detectors.motor_outputs import MotorGroup, motor_groups
from logscan.detectors.raw_topics import held as _held
from logscan.detectors.raw_topics import in_span
from logscan.detectors.raw_topics import log_parameter as _parameter

# battery_status.warning (PX4's msg/BatteryStatus.msg): the levels at which PX4 itself acts (CRITICAL:
# return or abort, EMERGENCY: land now); LOW only warns and CHARGING (7) is no fault
BATTERY_WARNING_NAMES = {2: "CRITICAL", 3: "EMERGENCY", 4: "FAILED", 6: "UNHEALTHY"}
BATTERY_WARNINGS = tuple(BATTERY_WARNING_NAMES)


class PowerChecks(HealthChecks):
    """Battery and motors."""

    # --- 1. battery ------------------------------------------------------------------------------
    def _battery(self, topics, parameters) -> None:
        found = sorted(i for topic, i in topics if topic == BATTERY)
        if not found:
            self._skipped["battery"] = f"no {BATTERY} topic"
            return
        for instance in found:
            self._one_battery(topics[(BATTERY, instance)], instance, parameters)

    def _one_battery(self, fields, instance: int, parameters) -> None:
        """``health.battery`` (the cells' empty voltage over the voltage) and ``battery_zero`` of one
        battery instance, while it is connected."""
        where = f"{BATTERY}_{instance}"
        name = f"{PREFIX}.battery{_suffix(instance)}"
        voltage = fields.get("voltage_v")
        if voltage is None:
            self._skipped[name] = f"{where} has no voltage_v"
            return
        t, raw = voltage.t, voltage.values
        v, v_from = _judged_voltage(fields, raw)
        connected = fields.get("connected")
        on = np.ones(t.size, bool) if connected is None else np.nan_to_num(_held(connected, t)) != 0
        inside = in_span(self._grid, t)
        if connected is not None and inside.any() and not on[inside].any():
            seen = raw[inside][np.isfinite(raw[inside])]
            volts = f", voltage {seen.min():.2f}-{seen.max():.2f} V" if seen.size else ""
            self._unmonitored.append(f"battery not monitored: connected=0 all flight ({where}{volts})")
            return
        k = instance + 1
        empty = _parameter(parameters, f"BAT{k}_V_EMPTY", "BAT_V_EMPTY")
        v_empty, empty_from = empty if empty else (CELL_EMPTY_V, "default")
        cells, cells_from = _cell_count(fields, t, parameters, k, where)
        with np.errstate(divide="ignore", invalid="ignore"):
            if cells_from is None:
                self._skipped[name] = f"{where}: cell count unknown (no cell_count, no BAT{k}_N_CELLS / BAT_N_CELLS)"
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
                        "voltage": f"{where}.{v_from}",
                        "empty_v": float(np.median(cells_seen)) * v_empty,
                        "cells": float(np.median(cells_seen)),
                        "cells_from": cells_from,
                        "cell_empty_v": v_empty,
                        "cell_empty_from": empty_from,
                    },
                )
            zero = np.where(on & np.isfinite(raw), np.where(raw < ZERO_VOLTAGE_V, FLAG, 0.0), np.nan)
        self._battery_warning(fields, connected, instance, where)
        self._add(
            f"{PREFIX}.battery_zero{_suffix(instance)}",
            where,
            t,
            zero,
            limit={"below_v": ZERO_VOLTAGE_V, "while": "connected" if connected is not None else "always"},
        )

    def _battery_warning(self, fields, connected, instance: int, where: str) -> None:
        """``health.battery_warning``: PX4's own battery state (``warning``) at CRITICAL or worse,
        the level at which PX4 itself acts (return, land), while the battery is connected."""
        warning = fields.get("warning")
        if warning is None:
            return  # older PX4 versions log no warning field: the voltage check stands alone
        level = np.asarray(warning.values, dtype=np.float64)
        flag = np.where(np.isin(level, BATTERY_WARNINGS), FLAG, 0.0)
        on = True if connected is None else np.nan_to_num(_held(connected, warning.t)) != 0
        self._add(
            f"{PREFIX}.battery_warning{_suffix(instance)}",
            where,
            warning.t,
            np.where(np.isfinite(level) & on, flag, np.nan),
            limit={"field": f"{where}.warning", "levels": dict(BATTERY_WARNING_NAMES)},
            n_persist=1,  # set from PX4's own filtered charge estimate: one sample is its verdict
        )

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
        elif (why_not := _never_commanded(group, fly & in_span(self._grid, t))) is not None:
            self._skipped[name] = f"{where}: {why_not}"


def _cell_count(fields, t, parameters, k: int, where: str):
    """(the cell count at each time ``t``, where it comes from; None: unknown) of battery ``k`` (from
    1): its own ``cell_count`` where it reports one, else BAT<k>_N_CELLS (or BAT_N_CELLS)."""
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
    return cells, cells_from


def _judged_voltage(fields, raw: np.ndarray) -> tuple[np.ndarray, str]:
    """(the voltage the battery check judges, its field): PX4's own filtered voltage where it logs
    one (``voltage_filtered_v``, "0 if unknown"; what PX4 estimates the charge from), else the raw
    ``voltage_v``, which swings with the motors' current on every throttle change."""
    filtered = fields.get("voltage_filtered_v")
    if filtered is None or filtered.values.size != raw.size:
        return raw, "voltage_v"
    known = np.asarray(filtered.values, dtype=np.float64)
    known = np.where(np.isfinite(known) & (known >= ZERO_VOLTAGE_V), known, np.nan)
    if not np.isfinite(known).any():
        return raw, "voltage_v"
    return np.where(np.isfinite(known), known, raw), "voltage_filtered_v"


def _never_commanded(group: MotorGroup, flying: np.ndarray) -> str | None:
    """Why ``motor_zero`` judged nothing when the vehicle did fly: PX4 commanded none of the group's
    motors to run then (``actuator_motors`` NaN: stopped on purpose, as a plane's motor at zero
    thrust), so an output at its stopped value was no fault. None: it never flew in the span."""
    if not flying.any() or group.runs[flying].any() or not group.limits.get("commands"):
        return None
    motors = ", ".join(f"{c} ({group.label}{k + 1})" for c, k in zip(group.limits["commands"], group.outputs))
    return (
        f"{motors} NaN at all {int(flying.sum())} samples armed and flying: PX4 commanded no motor to run "
        "in flight (stopped on purpose), so a stopped output is no fault there"
    )
