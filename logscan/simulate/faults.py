"""Fault injection for `logscan simulate`: fault kinds, their defaults, parsing, and the kernel table.

A fault is (kind, target, start, end, magnitude), times in seconds since the log start. Kinds
(docs/algorithms.md section 6.5) and what their magnitude means:

    bias             sensor channel    z += m                       (step; default 1.0 on accel x)
    drift            sensor channel    z += m * (t - start)         (slope per second; 0.05)
    random           sensor channel    z += U(-m, m)                (uniform; 1.0)
    bitflip          sensor channel    flip one high-order bit (sign or exponent, bits 24..31)
                                       of the float32 value with probability m per sample (1.0)
    stuck            sensor channel    z = last value before start (m unused)
    actuator-offset  actuator          u_i *= 1 + m                 (-0.10: -10 % thrust)
    lost-actuator    actuator          u_i = 0                      (m unused)
    cov-corruption   on-board state    LOGGED variance *= m          (100; "all" states)
    state-corruption on-board state    estimator state += m, once at start (the controller
                                       then flies on the corrupted estimate)
    control-fault    controller output u_j *= 1 + m                 (a wrong gain; +0.5 on the
                     (model input)                                   first input, 2 s)
    control-stuck    controller output u_j = its value at the step before start (m unused; 2 s)

The control kinds are the encoded-EKF paper's control-program fault (Tables I-IV): the controller
computes a wrong output, and the vehicle logs and flies that output (the logged command is the
faulty one; the actuator limits still apply).

Aliases: imu-bias = bias on the accelerometer x channel (Kalman-gain-norm paper: +1 m/s^2),
imu-bitflip = a 1.2 s burst of bit flips in one IMU channel (encoded-EKF paper), imu-drift,
motor-offset = actuator-offset (-10 % thrust on motor 0), lost-motor = lost-actuator.
The UBIKF paper's two scenarios (section IV.B), timed in grid samples k counted from
PAPER_SETTLE_S after the log start (the hover_uav's excitation starts there, the filters have
converged): roll-bias = bias 0.1 rad on attitude.roll for k in [30, 70] (both included),
rotor-loss = total loss of the first actuator (rotor1) from k = 31 to the end of the log.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from logscan.errors import UsageError, did_you_mean
from logscan.results import FaultEvent

# Kernel codes (the closed-loop kernel switches on these).
BIAS, DRIFT, RANDOM, BITFLIP, STUCK, ACT_OFFSET, LOST_ACT, COV_CORRUPT, STATE_CORRUPT, CTRL_GAIN, CTRL_STUCK = range(11)

KIND_CODES = {
    "bias": BIAS,
    "drift": DRIFT,
    "random": RANDOM,
    "bitflip": BITFLIP,
    "stuck": STUCK,
    "actuator-offset": ACT_OFFSET,
    "lost-actuator": LOST_ACT,
    "cov-corruption": COV_CORRUPT,
    "state-corruption": STATE_CORRUPT,
    "control-fault": CTRL_GAIN,
    "control-stuck": CTRL_STUCK,
}
SENSOR_KINDS = frozenset({"bias", "drift", "random", "bitflip", "stuck"})
ACTUATOR_KINDS = frozenset({"actuator-offset", "lost-actuator"})
ESTIMATOR_KINDS = frozenset({"cov-corruption", "state-corruption"})
CONTROL_KINDS = frozenset({"control-fault", "control-stuck"})

# alias -> (kind, fixed default target or None, default magnitude, default duration s)
ALIASES = {
    "imu-bias": ("bias", "imu", 1.0, 10.0),
    "imu-drift": ("drift", "imu", 0.05, 20.0),
    "imu-random": ("random", "imu", 1.0, 10.0),
    "imu-bitflip": ("bitflip", "imu", 1.0, 1.2),
    "imu-stuck": ("stuck", "imu", 0.0, 5.0),
    "motor-offset": ("actuator-offset", None, -0.10, 10.0),
    "lost-motor": ("lost-actuator", None, 0.0, 5.0),
    # the UBIKF paper's scenarios; durations here are at 100 Hz, ALIAS_SAMPLES times them
    "roll-bias": ("bias", "attitude.roll", 0.1, 0.41),
    "rotor-loss": ("lost-actuator", None, 0.0, math.inf),
}
# alias -> (first sample k, last sample k included or None: to the log end), k counted in grid
# periods from PAPER_SETTLE_S; used when the fault's start (and end) are not given
ALIAS_SAMPLES = {"roll-bias": (30, 70), "rotor-loss": (31, None)}
PAPER_SETTLE_S = 5.0  # the hover_uav's hover before its attitude excitation: the paper's k = 0
# kind -> (default magnitude, default duration s)
KIND_DEFAULTS = {
    "bias": (1.0, 10.0),
    "drift": (0.05, 20.0),
    "random": (1.0, 10.0),
    "bitflip": (1.0, 1.2),
    "stuck": (0.0, 5.0),
    "actuator-offset": (-0.10, 10.0),
    "lost-actuator": (0.0, 5.0),
    "cov-corruption": (100.0, 1.0),
    "state-corruption": (1.0, 1.0),
    "control-fault": (0.5, 2.0),
    "control-stuck": (0.0, 2.0),
}
ALL_NAMES = tuple(KIND_CODES) + tuple(ALIASES)
BITFLIP_LOWEST_BIT = 24  # bits 24..30 are the high-order exponent bits, 31 the sign


@dataclass(frozen=True)
class FaultSpec:
    """One fault as the user asked for it; None fields take the kind's default for the model."""

    kind: str
    target: str | None = None
    start: float | None = None
    end: float | None = None
    magnitude: float | None = None


def parse_fault(text: str) -> FaultSpec:
    """Parse ``KIND`` or ``KIND:TARGET:START:END:MAGNITUDE`` (empty fields take defaults)."""
    parts = text.strip().split(":")
    kind = parts[0].strip().lower()
    if kind not in ALL_NAMES:
        raise UsageError(
            f"unknown fault kind {kind!r}",
            hint=did_you_mean(kind, ALL_NAMES) + "choose one of " + ", ".join(ALL_NAMES),
        )
    if len(parts) > 5:
        raise UsageError(
            f"fault {text!r} has {len(parts)} fields",
            hint="use KIND or KIND:TARGET:START:END:MAGNITUDE, e.g. bias:accel.x:30:40:1.0",
        )
    fields = [p.strip() for p in parts[1:]] + [""] * (5 - len(parts))
    target = fields[0] or None
    try:
        start, end, magnitude = (float(v) if v else None for v in fields[1:4])
    except ValueError:
        raise UsageError(
            f"fault {text!r}: START, END and MAGNITUDE must be numbers",
            hint="e.g. bias:accel.x:30:40:1.0 (leave a field empty for its default)",
        ) from None
    return FaultSpec(kind, target, start, end, magnitude)


@dataclass
class FaultTable:
    """Resolved faults as arrays the closed-loop kernel reads (one row per fault)."""

    kind: np.ndarray  # (nf,) int64 kind code
    target: np.ndarray  # (nf,) int64 channel / actuator / state index (-1: all states)
    start: np.ndarray  # (nf,) int64 first grid step affected
    end: np.ndarray  # (nf,) int64 first grid step no longer affected
    magnitude: np.ndarray  # (nf,) float64
    uniform: np.ndarray  # (nf, N) float64 U[0,1) draws (random value, bit-flip probability)
    bit: np.ndarray  # (nf, N) int64 bit index flipped by a bit-flip fault at each step

    @classmethod
    def empty(cls, n_steps: int) -> FaultTable:
        zi = np.zeros(0, dtype=np.int64)
        return cls(
            zi,
            zi.copy(),
            zi.copy(),
            zi.copy(),
            np.zeros(0),
            np.zeros((0, n_steps)),
            np.zeros((0, n_steps), dtype=np.int64),
        )


def resolve_faults(
    specs: list[FaultSpec],
    *,
    duration: float,
    dt: float,
    sensor_channels: list[tuple[str, str]],
    imu_default: str,
    actuators: list[str],
    state_names: tuple[str, ...],
    estimator_fields: dict[str, str],
    rng: np.random.Generator,
    sensor_aliases: dict[str, str] | None = None,
    inputs: tuple[tuple[str, str], ...] = (),
) -> tuple[list[FaultEvent], FaultTable]:
    """Turn user specs into ground-truth events and the kernel's fault table.

    ``sensor_channels``: (target name like "accel.x", log channel) per measured value, in kernel
    order; ``imu_default``: the target of imu-* aliases; ``actuators``: actuator target names in
    kernel order; ``estimator_fields``: state name -> logged field prefix (for the truth's channels);
    ``sensor_aliases``: other names of sensor targets -> target name (gps -> gps_speed);
    ``inputs``: (model input name, logged command channel) per controller output, in kernel order
    (none: the simulation has no controller to corrupt).
    """
    n_steps = int(round(duration / dt)) + 1
    events: list[FaultEvent] = []
    rows: list[tuple[int, int, int, int, float]] = []
    for spec in specs:
        kind, target, start, end, magnitude = _when_and_how_much(spec, duration, dt)
        if kind in SENSOR_KINDS:
            target = target or "imu"
            index = _sensor_target((sensor_aliases or {}).get(target, target), imu_default, sensor_channels, spec.kind)
            target = sensor_channels[index][0]
            channels: tuple[str, ...] = (sensor_channels[index][1],)
        elif kind in ACTUATOR_KINDS:
            target = target or actuators[0]
            if target not in actuators:
                raise UsageError(
                    f"fault {spec.kind}: unknown actuator {target!r}",
                    hint="choose one of " + ", ".join(actuators),
                )
            index = actuators.index(target)
            channels = ()
        elif kind in CONTROL_KINDS:
            target, index, channels = _control_target(spec, target, list(inputs))
        else:
            target, index, channels = _estimator_target(spec, kind, target, state_names, estimator_fields)
        first = int(math.ceil(start / dt - 1e-9))
        last = min(int(math.ceil(end / dt - 1e-9)), n_steps)
        if kind == "state-corruption":
            last = first + 1  # one memory upset; the event window is where its effect is expected
        rows.append((KIND_CODES[kind], index, first, max(last, first + 1), float(magnitude)))
        events.append(FaultEvent(float(start), float(end), kind, target, float(magnitude), tuple(channels)))
    return events, _fault_table(rows, n_steps, rng)


def _when_and_how_much(spec: FaultSpec, duration: float, dt: float) -> tuple[str, str | None, float, float, float]:
    """(kind, target or None, start s, end s, magnitude) of a spec, its alias's defaults filled in;
    UsageError for a window outside the log or a non-finite magnitude."""
    kind, alias_target, magnitude, length = _defaults(spec.kind)
    target = spec.target or alias_target
    start = 0.5 * duration if spec.start is None else spec.start
    end = start + length if spec.end is None else spec.end
    if spec.kind in ALIAS_SAMPLES:
        start, end = _sample_window(spec, dt)
    magnitude = magnitude if spec.magnitude is None else spec.magnitude
    if not (0.0 <= start < duration):
        raise UsageError(
            f"fault {spec.kind} starts at {start:g} s, outside the log (0 .. {duration:g} s)",
            hint="choose --at within the log or raise --duration",
        )
    end = min(end, duration)
    if end <= start:
        raise UsageError(
            f"fault {spec.kind} ends at {end:g} s, not after its start {start:g} s",
            hint="give a positive duration",
        )
    if not math.isfinite(magnitude):
        raise UsageError(f"fault {spec.kind}: magnitude must be finite, got {magnitude}")
    return kind, target, start, end, magnitude


def _control_target(
    spec: FaultSpec, target: str | None, inputs: list[tuple[str, str]]
) -> tuple[str, int, tuple[str, ...]]:
    """(target, controller output index, the logged command channel) of a control fault."""
    if not inputs:
        raise UsageError(
            f"fault {spec.kind} needs a closed-loop controller, which this simulation does not have",
            hint="simulate quadcopter, steer_by_wire, dc_motor or hover_uav",
        )
    names = [name for name, _ in inputs]
    target = target or names[0]
    if target not in names:
        raise UsageError(
            f"fault {spec.kind}: unknown controller output {target!r}", hint="choose one of " + ", ".join(names)
        )
    index = names.index(target)
    return target, index, (inputs[index][1],)


def _estimator_target(
    spec: FaultSpec, kind: str, target: str | None, state_names: tuple[str, ...], estimator_fields: dict[str, str]
) -> tuple[str, int, tuple[str, ...]]:
    """(target, state index or -1 for all, logged channels) of an estimator fault."""
    target = target or ("all" if kind == "cov-corruption" else state_names[0])
    if target == "all":
        index = -1
        names = state_names
    elif target in state_names:
        index = state_names.index(target)
        names = (target,)
    else:
        raise UsageError(
            f"fault {spec.kind}: unknown estimator state {target!r}",
            hint="choose 'all' or one of " + ", ".join(state_names),
        )
    channels = tuple(estimator_fields[n] for n in names)
    return target, index, channels


def _fault_table(rows: list[tuple[int, int, int, int, float]], n_steps: int, rng: np.random.Generator) -> FaultTable:
    """The kernel's fault table of the rows (kind code, target index, first step, end step,
    magnitude), with each fault's random draws for every step."""
    nf = len(rows)
    if nf == 0:
        return FaultTable.empty(n_steps)
    table = FaultTable(
        kind=np.array([r[0] for r in rows], dtype=np.int64),
        target=np.array([r[1] for r in rows], dtype=np.int64),
        start=np.array([r[2] for r in rows], dtype=np.int64),
        end=np.array([r[3] for r in rows], dtype=np.int64),
        magnitude=np.array([r[4] for r in rows], dtype=np.float64),
        uniform=rng.random((nf, n_steps)),
        bit=rng.integers(BITFLIP_LOWEST_BIT, 32, size=(nf, n_steps)).astype(np.int64),
    )
    return table


def _sample_window(spec: FaultSpec, dt: float) -> tuple[float, float]:
    """(start, end) s of a fault of ALIAS_SAMPLES: samples k in [first, last] counted from
    PAPER_SETTLE_S (a given start replaces k = first; a given end stays)."""
    first, last = ALIAS_SAMPLES[spec.kind]
    start = round(PAPER_SETTLE_S + first * dt, 9) if spec.start is None else spec.start
    if spec.end is not None:
        return start, spec.end
    return start, math.inf if last is None else round(start + (last + 1 - first) * dt, 9)


def _defaults(name: str) -> tuple[str, str | None, float, float]:
    if name in ALIASES:
        return ALIASES[name]
    if name in KIND_DEFAULTS:
        magnitude, length = KIND_DEFAULTS[name]
        return name, None, magnitude, length
    raise UsageError(
        f"unknown fault kind {name!r}", hint=did_you_mean(name, ALL_NAMES) + "choose one of " + ", ".join(ALL_NAMES)
    )


def _sensor_target(target: str, imu_default: str, channels: list[tuple[str, str]], kind: str) -> int:
    """Index of the sensor channel named ``target`` (a target name like accel.x or a channel)."""
    if target == "imu":
        target = imu_default
    for i, (name, channel) in enumerate(channels):
        if target in (name, channel):
            return i
    raise UsageError(
        f"fault {kind}: unknown sensor target {target!r}",
        hint="choose one of " + ", ".join(name for name, _ in channels),
    )


def corrupt_logged_variance(variance: np.ndarray, table: FaultTable) -> np.ndarray:
    """Apply cov-corruption rows to the LOGGED on-board variance (N, n): P_ii *= m on [start, end)."""
    out = variance.copy()
    for row in np.flatnonzero(table.kind == COV_CORRUPT):
        cols = slice(None) if table.target[row] < 0 else int(table.target[row])
        out[table.start[row] : table.end[row], cols] *= table.magnitude[row]
    return out
