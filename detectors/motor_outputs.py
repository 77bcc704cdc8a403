"""Which of a PX4 log's actuator outputs drive motors, and which output values mean "stopped" and
"full", as PX4 drives them: the protocol from the timer parameters, the motors from the output
functions and the motor topic, reduced to the outputs that were active while armed.

Read by the `health` detector's motor checks (docs/algorithms.md section 3c). PX4 facts used:

- ``PWM_MAIN_TIMn`` / ``PWM_AUX_TIMn`` (v1.13+, pwm_out's module.yaml): a timer's protocol, > 0 PWM
  at that rate, -1 OneShot, -2 to -5 DShot1200 to DShot150, -6 to -8 bidirectional DShot. Legacy
  logs: ``DSHOT_CONFIG`` > 0 puts the FMU outputs (AUX with an IO board, ``SYS_USE_IO`` 1) on DShot.
- a DShot output's value in ``actuator_outputs`` is 0 disarmed or stopped, 1 to 1999 running
  (the driver's DSHOT_DISARM_VALUE, DSHOT_MIN_THROTTLE, DSHOT_MAX_THROTTLE); PWM and OneShot
  outputs are microseconds, stopped at their disarmed value (``PWM_MAIN_DISn``...).
- ``PWM_MAIN_FUNCn`` / ``PWM_AUX_FUNCn`` 101 to 112: the output drives Motor 1 to 12.
- ``actuator_motors`` (v1.14+): the allocator's command per motor, NaN where a motor is disarmed,
  unused or stopped on purpose (a VTOL's hover motors in forward flight, a plane's motor at zero
  thrust): a motor is judged only where PX4 commands it to run.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from logscan.detectors.raw_topics import held, log_parameter

OUTPUTS = "actuator_outputs"
MOTORS = "actuator_motors"
MOTOR_FUNCTIONS = range(101, 113)  # PWM_MAIN_FUNCn Motor1..Motor12 (PX4 v1.13+)
# MAV_TYPE of multicopters (MAVLink: quad, coaxial, hexa, octo, tri, dodeca, deca): without
# PWM_MAIN_FUNCn their first noutputs outputs are taken for motors; other vehicles' are not
MULTICOPTERS = (2, 3, 13, 14, 15, 29, 35)
PWM_MAX = 2000.0  # PX4's PWM_MAIN_MAX default
DSHOT_STOP = 0.0  # DSHOT_DISARM_VALUE
DSHOT_MAX = 1999.0  # DSHOT_MAX_THROTTLE
ONE_COUNT = 0.5  # outputs are integers: half a count is "equal"
TIMER_NAMES = {-1: "OneShot", -2: "DShot1200", -3: "DShot600", -4: "DShot300", -5: "DShot150"}
TIMER_NAMES |= {-6: "BDShot600", -7: "BDShot300", -8: "BDShot150"}


@dataclass
class MotorGroup:
    """The motor outputs of one ``actuator_outputs`` instance: (n samples, m motors) arrays."""

    where: str  # actuator_outputs_<i>
    label: str  # "" (MAIN) or "aux": the prefix of an output's number in statistic names
    t: np.ndarray  # int64 ns
    outputs: list[int]  # output index k (0-based) of each column
    values: np.ndarray  # (n, m) the logged output values
    top: np.ndarray  # (m,) the value that means full
    runs: np.ndarray  # (n, m) armed, and PX4 commands this motor to run (actuator_motors finite)
    stopped: np.ndarray  # (n, m) the output at its stopped value (the disarmed value of its protocol)
    limits: dict = field(default_factory=dict)  # what was taken and from where, for info["checks"]


def motor_groups(topics, parameters, armed) -> tuple[list[MotorGroup], dict[str, str]]:
    """The motor groups of the log, and {instance suffix ("" / ".aux"): why not checked}."""
    groups: list[MotorGroup] = []
    skipped: dict[str, str] = {}
    commands = _commands(topics)
    for instance in sorted(i for topic, i in topics if topic == OUTPUTS):
        sfx = "" if instance == 0 else ".aux" if instance == 1 else f".aux{instance}"
        found = _group(topics[(OUTPUTS, instance)], instance, parameters, armed, commands)
        if isinstance(found, str):
            skipped[sfx] = found
        else:
            groups.append(found)
    return groups, skipped


def _commands(topics) -> dict[int, object]:
    """Motor index -> its ``actuator_motors_0.control[m]`` channel (empty when not logged)."""
    fields = topics.get((MOTORS, 0), {})
    return {int(m.group(1)): ch for f, ch in fields.items() if (m := re.fullmatch(r"control\[(\d+)\]", f))}


def _group(fields, instance: int, parameters, armed, commands) -> MotorGroup | str:
    where = f"{OUTPUTS}_{instance}"
    outputs = sorted(int(m.group(1)) for f in fields if (m := re.fullmatch(r"output\[(\d+)\]", f)) is not None)
    if not outputs:
        return f"{where} has no output[k] fields"
    t = fields[f"output[{outputs[0]}]"].t
    if t.size == 0 or not all(np.array_equal(fields[f"output[{k}]"].t, t) for k in outputs):
        return f"{where}: no samples, or outputs with different sample times"
    if instance > 1:
        return f"{where}: which output parameters (MAIN or AUX) describe instance {instance} is unknown"
    group = "MAIN" if instance == 0 else "AUX"
    mapped = _motor_map(fields, outputs, t, instance, group, parameters)
    if isinstance(mapped, str):
        return f"{where}: {mapped}"
    motor_of, mapping = mapped
    if not motor_of:
        return f"{where}: no output is a motor ({mapping})"
    motors = sorted(motor_of)
    values = np.column_stack([fields[f"output[{k}]"].values for k in motors]).astype(np.float64)
    on = armed[1](t)
    if not on.any():
        return f"{where}: never armed while it was logged"
    kind, protocol = _protocol(parameters, group)
    stop, stop_from = _stops(parameters, group, motors, kind, values, on)
    if np.isnan(stop).any():
        return f"{where}: {stop_from[int(np.flatnonzero(np.isnan(stop))[0])]}"
    top = np.array([_top(parameters, group, k, kind) for k in motors])
    idle = np.array([_idle(parameters, group, k, kind) for k in motors])
    command = _commanded(commands, [motor_of[k] for k in motors], t)
    # a motor PX4 commands to run: armed, and finite in actuator_motors when that is logged
    runs = on[:, None] & (np.isfinite(command) if commands else np.ones(values.shape, bool))
    # an output never active while armed (constant: unused channel, unused group, no ESC) is no motor
    seen = runs & np.isfinite(values)
    high = np.max(np.where(seen, values, -np.inf), axis=0)
    low = np.min(np.where(seen, values, np.inf), axis=0)
    active = high - low > ONE_COUNT  # False for a motor never seen running
    label = "" if instance == 0 else "aux"
    names = [f"{label}{k + 1}" for k in motors]
    if not active.any():
        return f"{where}: no motor output was active while armed ({', '.join(names)} constant or never commanded)"
    stopped, stop_from = _stopped(values, stop, idle, top, command if commands else None, stop_from)
    keep = np.flatnonzero(active)
    limits = {
        "mapping": mapping,
        "protocol": protocol,
        "motor_topic": f"{MOTORS}_0 (judged where its command is finite)" if commands else None,
        "commands": [f"{MOTORS}_0.control[{motor_of[motors[j]]}]" for j in keep] if commands else None,
        "outputs": [names[j] for j in keep],
        "not_motors": [n for n, a in zip(names, active) if not a],
        "max": top[keep].tolist(),
        "stopped_at": stop[keep].tolist(),
        "stopped_from": [stop_from[j] for j in keep],
    }
    cols = (values[:, keep], top[keep], runs[:, keep], stopped[:, keep])
    return MotorGroup(where, label, t, [motors[j] for j in keep], *cols, limits)


def _commanded(commands, motor_index: list[int], t) -> np.ndarray:
    """(n, m) PX4's command of each motor held at the output times (NaN: not commanded, or no
    ``actuator_motors`` in the log)."""
    out = np.full((t.size, len(motor_index)), np.nan)
    for j, m in enumerate(motor_index):
        channel = commands.get(m)
        if channel is not None and channel.t.size:
            out[:, j] = held(channel, t)
    return out


def _stopped(values, stop, idle, top, command, whence: list[str]) -> tuple[np.ndarray, list[str]]:
    """(n, m) each output at its stopped value. Where the stopped value is also the output's idle
    minimum (PX4 v1.13+'s PWM defaults: PWM_MAIN_DISn = PWM_MAIN_MINn = 1000) the value alone
    cannot tell a stop from idle: stopped there only while PX4 commands the motor at least one
    count above idle (``command * (top - stop) > 1/2``), never without ``actuator_motors``."""
    at_stop = values <= stop[None, :] + ONE_COUNT
    same = np.isfinite(idle) & (idle <= stop + ONE_COUNT)
    if not same.any():
        return at_stop, whence
    whence = [w + (", = its idle minimum" if s else "") for w, s in zip(whence, same)]
    above_idle = np.zeros(values.shape, bool) if command is None else np.nan_to_num(command) * (top - stop) > ONE_COUNT
    return np.where(same[None, :], at_stop & above_idle, at_stop), whence


def _motor_map(fields, outputs, t, instance: int, group: str, parameters) -> tuple[dict[int, int], str] | str:
    """({output k: motor index}, how it was found), or why it cannot be known."""
    functions = {k: log_parameter(parameters, f"PWM_{group}_FUNC{k + 1}", positive=False) for k in outputs}
    if any(functions.values()):
        motor_of = {k: int(f[0]) - 101 for k, f in functions.items() if f is not None and int(f[0]) in MOTOR_FUNCTIONS}
        return motor_of, f"PWM_{group}_FUNCn in 101..112"
    if instance != 0:
        return f"no PWM_{group}_FUNCn, so which outputs drive motors is unknown (AUX outputs drive servos)"
    vehicle = log_parameter(parameters, "MAV_TYPE", positive=False)
    if vehicle is not None and int(vehicle[0]) not in MULTICOPTERS:
        return (
            f"no PWM_MAIN_FUNCn and MAV_TYPE {int(vehicle[0])} is not a multicopter: "
            "its outputs drive servos too, which of them are motors is unknown"
        )
    n_out = np.nan_to_num(held(fields["noutputs"], t)).max() if "noutputs" in fields else len(outputs)
    return {k: k for k in outputs if k < n_out}, "the first noutputs outputs (no PWM_MAIN_FUNCn)"


def _protocol(parameters, group: str) -> tuple[str, str]:
    """("pwm" | "dshot" | "mixed", the parameters that say so) for a group's outputs."""
    pattern = re.compile(rf"PWM_{group}_TIM(\d+)")
    timers = {}
    for name in parameters:
        if pattern.fullmatch(str(name)) and (found := log_parameter(parameters, name, positive=False)):
            timers[str(name)] = int(found[0])
    if timers:
        dshot = [v for v in timers.values() if v <= -2]
        said = ", ".join(
            f"{n} = {v} ({TIMER_NAMES.get(v, f'PWM {v} Hz' if v > 0 else 'unknown')})"
            for n, v in sorted(timers.items())
        )
        if not dshot:
            return "pwm", said
        return ("dshot" if len(dshot) == len(timers) else "mixed"), said
    config = log_parameter(parameters, "DSHOT_CONFIG", positive=True)
    if config is not None:  # legacy: DShot on the FMU outputs, AUX on a board with an IO
        io = log_parameter(parameters, "SYS_USE_IO", positive=True)
        fmu = "AUX" if io is not None else "MAIN"
        if fmu == group:
            return "dshot", f"DSHOT_CONFIG = {int(config[0])} (DShot on the FMU outputs: {fmu})"
    return "pwm", "no DShot timer (PWM)"


def _stops(parameters, group: str, motors, kind: str, values, on) -> tuple[np.ndarray, list[str]]:
    """Each motor output's stopped value and where it came from. DShot: 0. PWM: its disarmed
    value parameter, else the value it held while disarmed in this log. A group with both
    DShot and PWM timers: 0 (which timer drives which output is board wiring the log lacks, and
    0 is "stopped" in both protocols)."""
    stops, whence = [], []
    for j, k in enumerate(motors):
        if kind in ("dshot", "mixed"):
            stops.append(DSHOT_STOP)
            whence.append("DShot disarmed value" if kind == "dshot" else "0: DShot and PWM timers in the group")
            continue
        names = (f"PWM_{group}_DIS{k + 1}", f"PWM_{group}_DISARM", f"PWM_{group}_DISARMED", "PWM_DISARMED")
        found = next((n for n in names if (log_parameter(parameters, n, positive=False) or (-1.0,))[0] >= 0), None)
        if found is not None:  # PX4 writes -1 for "not set"; 0 (no pulse) is a disarmed value
            stops.append(log_parameter(parameters, found, positive=False)[0])
            whence.append(found)
            continue
        off = values[~on, j]
        off = off[np.isfinite(off)]
        if off.size:
            levels, counts = np.unique(off, return_counts=True)
            level = float(levels[np.argmax(counts)])
            # a stop runs below the motor: a disarmed value not under most of its armed values is
            # some other publisher's or a failsafe's, not "stopped" (a ulog2csv export of the real
            # robologs flight: 1500 disarmed, 1000-1300 in flight, all of it read as stopped)
            running = float(np.nanmedian(values[on, j])) if np.isfinite(values[on, j]).any() else np.nan
            if not level < running:
                stops.append(np.nan)
                whence.append(
                    f"no PWM_{group}_DISn or PWM_DISARMED parameter, and output {k + 1}'s value while disarmed "
                    f"({level:g}) is not below its median while armed ({running:g}): which value means stopped "
                    "is unknown"
                )
                continue
            stops.append(level)
            whence.append("its value while disarmed")
        else:
            stops.append(0.0)
            whence.append("unknown: 0")
    return np.asarray(stops, dtype=np.float64), whence


def _top(parameters, group: str, k: int, kind: str) -> float:
    """An output's full value: DShot 1999; PWM its max parameter (PWM_MAIN_MAXn, v1.13+, the
    group's, the legacy PWM_MAX) else 2000; a mixed group the larger of the two."""
    found = log_parameter(parameters, f"PWM_{group}_MAX{k + 1}", f"PWM_{group}_MAX", "PWM_MAX")
    pwm = found[0] if found else PWM_MAX
    return {"dshot": DSHOT_MAX, "pwm": pwm}.get(kind, max(pwm, DSHOT_MAX))


def _idle(parameters, group: str, k: int, kind: str) -> float:
    """An output's lowest running value: DShot 1 (DSHOT_MIN_THROTTLE, above the stop 0); PWM its
    min parameter (PWM_MAIN_MINn, the group's, the legacy PWM_MIN), NaN when unknown."""
    if kind != "pwm":
        return 1.0
    found = log_parameter(parameters, f"PWM_{group}_MIN{k + 1}", f"PWM_{group}_MIN", "PWM_MIN")
    return found[0] if found else np.nan
