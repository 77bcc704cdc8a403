"""`logscan simulate ins`: an open-loop multirotor flight for the IMU-driven `ins` model.

The closed-loop kernel (`logscan.simulate.runner`) drives a model's inputs from a controller; the
`ins` model's input is a sensor, the IMU, so its simulation runs the other way round:

 1. a reference trajectory (NED) in cycles of CYCLE_S (60 s, as the quadcopter's): a hover of
    HOVER_S (25 s; the first over the origin at 10 m altitude, yaw 0), then minimum-jerk moves
    (quintic in time, zero velocity and acceleration at both ends) to random waypoints (a few
    metres from the previous one, within +-10 m horizontally and 5-15 m altitude), each 3-6 s
    long and followed by a 2-6 s hold, until the cycle ends; one move in three also turns the yaw
    (quintic, up to +-90 deg). ``aggressive``: twice the distance in the same time (twice as
    fast). Mode 1 while moving, 0 while holding. The long hovers (0-25 s, 60-85 s, ...) are the
    steady segments the Kalman-gain-norm paper's test needs;
 2. the attitude a multirotor needs to follow it: its thrust axis along the specific force,
    b3 = -f_n / |f_n| with f_n = a_n - g e3, yaw psi: b2 = b3 x (cos psi, sin psi, 0) normalised,
    b1 = b2 x b3, R = [b1 b2 b3];
 3. a truth that obeys the model's discrete strapdown step exactly: on the grid (period dt) the
    true body rate w_k = Log(R_k^T R_{k+1}) / dt, the NED acceleration a_k = (v_{k+1} - v_k) / dt,
    the position p_{k+1} = p_k + v_k dt + a_k dt^2 / 2 and the specific force
    f_k = R_k^T (a_k - g e3); gyro and accelerometer biases (N(0, 0.003 rad/s), N(0, 0.05 m/s^2))
    and the barometer offset (250 m + N(0, 5 m)) random-walk with the model's parameters;
 4. the IMU logged at step k drives the step k-1 -> k (the EKF's convention, x_k = f(x_{k-1}, u_k)):
    true rate + gyro bias + N(0, gyro_noise), true specific force + accelerometer bias +
    N(0, accel_noise) (the model's parameters: the analysis filter's process noise is the
    simulation's); the aiding sensors sample the model's own `h` of the truth plus N(0, noise_std);
 5. sensor faults on the IMU channels (they corrupt only the log: the vehicle flies its reference
    whatever the IMU reads) and on the aiding sensors, with the closed-loop kernel's fault code;
 6. the on-board estimate is logscan's EKF (`run_ekf`) on the faulty data, open loop.
"""

from __future__ import annotations

import time

import numpy as np
from numba import njit

from logscan.align import AlignedGroup, AlignedRun
from logscan.errors import UsageError
from logscan.filters.ekf import run_ekf
from logscan.models.ins_kernels import ins_h
from logscan.numba_cache import follow_dependencies
from logscan.results import FaultEvent
from logscan.simulate.faults import (
    ACTUATOR_KINDS,
    ESTIMATOR_KINDS,
    SENSOR_KINDS,
    STUCK,
    FaultSpec,
    FaultTable,
    _defaults,
    corrupt_logged_variance,
    resolve_faults,
)
from logscan.simulate.runner import _sensor_faults
from logscan.simulate.scenario import Scenario, SensorGroup
from logscan.simulate.simulation import Simulation, _glitches, sensor_aliases

CYCLE_S = 60.0  # a hover, then manoeuvres
HOVER_S = 25.0  # the hover at the start of each cycle
HOVER_DOWN = -10.0  # m, NED down of the first hover (10 m altitude)
MOVE_S = (3.0, 6.0)  # duration of a move, uniform
HOLD_S = (2.0, 6.0)  # hold after a move, uniform
STEP_M = (3.0, 3.0, 1.5)  # largest waypoint change per axis (north, east, down), uniform +-
BOX_NE = 10.0  # waypoints within +-10 m north and east
ALTITUDE_M = (5.0, 15.0)  # waypoint altitude range
YAW_TURN_P = 1.0 / 3.0  # chance that a move also turns the yaw
YAW_TURN_MAX = np.pi / 2.0  # the largest turn
GYRO_BIAS_STD = 0.003  # rad/s, initial gyro bias per axis
ACCEL_BIAS_STD = 0.05  # m/s^2, initial accelerometer bias per axis
BARO_OFFSET_M = (250.0, 5.0)  # barometer offset at the start: mean, std
IMU_TOPIC = "/imu"
IMU_FIELDS = ("gyro.x", "gyro.y", "gyro.z", "accel.x", "accel.y", "accel.z")  # the model's input order
ONBOARD_RATE_HZ = 50.0
OPEN_LOOP = "none (open-loop reference trajectory)"


# ---- reference trajectory ------------------------------------------------------------------------


def _quintic(s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Minimum-jerk profile q(s) = 10 s^3 - 15 s^4 + 6 s^5 on s in [0, 1] and its first two
    derivatives (zero at both ends)."""
    s2 = s * s
    return (
        s2 * s * (10.0 - 15.0 * s + 6.0 * s2),
        30.0 * s2 * (1.0 - 2.0 * s + s2),
        60.0 * s * (1.0 - 3.0 * s + 2.0 * s2),
    )


def move_schedule(duration: float, aggressive: bool, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """The moves of a flight of ``duration`` s: start (s), length (s), waypoint before and after
    (NED m) and yaw before and after (rad, unwrapped), one row per move (the last may run past the
    log's end). A Python loop over the moves, not the samples (one per 5-12 s)."""
    scale = 2.0 if aggressive else 1.0
    starts, lengths, p_from, p_to, yaw_from, yaw_to = [], [], [], [], [], []
    p = np.array([0.0, 0.0, HOVER_DOWN])
    yaw = 0.0
    t = HOVER_S
    while t < duration:
        length = rng.uniform(*MOVE_S)
        hold = rng.uniform(*HOLD_S)
        cycle_start = np.floor(t / CYCLE_S) * CYCLE_S
        t = max(t, cycle_start + HOVER_S)  # a hold that ran into a cycle's hover: wait it out
        if t + length > cycle_start + CYCLE_S:  # no move across a cycle's end: the next hover starts there
            t = cycle_start + CYCLE_S + HOVER_S
            continue
        step = rng.uniform(-1.0, 1.0, size=3) * np.array(STEP_M) * scale
        target = p + step
        target[:2] = np.clip(target[:2], -BOX_NE, BOX_NE)
        target[2] = np.clip(target[2], -ALTITUDE_M[1], -ALTITUDE_M[0])
        turn = rng.uniform(-YAW_TURN_MAX, YAW_TURN_MAX) if rng.random() < YAW_TURN_P else 0.0
        starts.append(t)
        lengths.append(length)
        p_from.append(p)
        p_to.append(target)
        yaw_from.append(yaw)
        yaw_to.append(yaw + turn)
        p, yaw = target, yaw + turn
        t += length + hold
    return {
        "start": np.array(starts, dtype=np.float64),
        "length": np.array(lengths, dtype=np.float64),
        "p_from": np.array(p_from, dtype=np.float64).reshape(-1, 3),
        "p_to": np.array(p_to, dtype=np.float64).reshape(-1, 3),
        "yaw_from": np.array(yaw_from, dtype=np.float64),
        "yaw_to": np.array(yaw_to, dtype=np.float64),
    }


def reference_trajectory(t: np.ndarray, moves: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The reference at times ``t`` (vectorised): position, velocity, acceleration (N, 3) NED, yaw
    (N,) unwrapped, mode (N,) 1 moving / 0 holding, set-point (N, 3) and set-point yaw (N,)."""
    n = t.size
    idx = np.searchsorted(moves["start"], t, side="right") - 1  # current (or last) move, -1 before the first
    flying = idx >= 0
    i = np.maximum(idx, 0)
    hover = np.array([0.0, 0.0, HOVER_DOWN])
    if moves["start"].size == 0:  # a log shorter than the hover
        zeros = np.zeros((n, 3))
        p = np.broadcast_to(hover, (n, 3)).copy()
        return {
            "p": p,
            "v": zeros,
            "a": zeros.copy(),
            "yaw": np.zeros(n),
            "mode": np.zeros(n),
            "setpoint": p.copy(),
            "setpoint_yaw": np.zeros(n),
        }
    length = moves["length"][i]
    s = np.clip((t - moves["start"][i]) / length, 0.0, 1.0)
    q, dq, ddq = _quintic(s)
    d = moves["p_to"][i] - moves["p_from"][i]
    p = moves["p_from"][i] + d * q[:, None]
    v = d * (dq / length)[:, None]
    a = d * (ddq / length**2)[:, None]
    yaw = moves["yaw_from"][i] + (moves["yaw_to"][i] - moves["yaw_from"][i]) * q
    p[~flying] = hover
    v[~flying] = 0.0
    a[~flying] = 0.0
    yaw[~flying] = 0.0
    setpoint = np.where(flying[:, None], moves["p_to"][i], hover)
    setpoint_yaw = np.where(flying, moves["yaw_to"][i], 0.0)
    mode = (flying & (t < moves["start"][i] + length)).astype(np.float64)
    return {"p": p, "v": v, "a": a, "yaw": yaw, "mode": mode, "setpoint": setpoint, "setpoint_yaw": setpoint_yaw}


def thrust_attitude(a_n: np.ndarray, yaw: np.ndarray, g: float) -> np.ndarray:
    """Body-to-NED rotations (N, 3, 3) of a multirotor producing the NED acceleration ``a_n``
    (N, 3) at yaw ``yaw`` (N,): body down along minus the specific force, the body x axis in the
    vertical plane of heading ``yaw``."""
    f_n = a_n - np.array([0.0, 0.0, g])
    b3 = -f_n / np.linalg.norm(f_n, axis=1, keepdims=True)
    c = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], axis=1)
    b2 = np.cross(b3, c)
    b2 /= np.linalg.norm(b2, axis=1, keepdims=True)
    b1 = np.cross(b2, b3)
    return np.stack([b1, b2, b3], axis=2)  # columns


def euler_from_rotations(R: np.ndarray) -> np.ndarray:
    """ZYX (roll, pitch, yaw) of body-to-world rotations (N, 3, 3); yaw in (-pi, pi]."""
    roll = np.arctan2(R[:, 2, 1], R[:, 2, 2])
    pitch = np.arcsin(np.clip(-R[:, 2, 0], -1.0, 1.0))
    yaw = np.arctan2(R[:, 1, 0], R[:, 0, 0])
    return np.stack([roll, pitch, yaw], axis=1)


def so3_log_batch(R: np.ndarray) -> np.ndarray:
    """Rotation vectors (N, 3) of rotations (N, 3, 3) with angles below pi: Log(R), computed from
    atan2(|vee(R - R^T)|, tr R - 1) (accurate at small angles, where arccos is not)."""
    v = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], axis=1)  # 2 sin t * axis
    s2 = np.linalg.norm(v, axis=1)
    t = np.arctan2(s2, np.trace(R, axis1=1, axis2=2) - 1.0)
    small = s2 < 1e-8
    scale = np.where(small, 0.5 + t * t / 12.0, t / np.where(small, 1.0, s2))  # t / (2 sin t)
    return v * scale[:, None]


def _walk(rng: np.random.Generator, start: np.ndarray, q: float, dt: float, n: int) -> np.ndarray:
    """Random walks (n, len(start)) from ``start``, each step N(0, q^2 dt)."""
    steps = rng.standard_normal((n, start.size)) * (q * np.sqrt(dt))
    steps[0] = 0.0
    return start + np.cumsum(steps, axis=0)


# ---- scenario ------------------------------------------------------------------------------------


def imu_channels() -> list[str]:
    return [f"{IMU_TOPIC}/{f}" for f in IMU_FIELDS]


def ins_scenario(model, dt: float, t: np.ndarray, groups: list[SensorGroup], aggressive: bool, rng) -> Scenario:
    """The `ins` scenario (called by `dispatch.build_scenario`): the reference flight, the aiding
    sensor groups, the IMU as the input channels, mode and set-points."""
    moves = move_schedule(t[-1] + dt, aggressive, rng)
    ref = reference_trajectory(t, moves)
    reference = np.column_stack([ref["p"], ref["v"], ref["a"], ref["yaw"]])  # (N, 10)
    x0 = np.zeros(model.n_states)
    x0[2] = HOVER_DOWN
    x0[15] = BARO_OFFSET_M[0]
    wrap = (ref["setpoint_yaw"] + np.pi) % (2.0 * np.pi) - np.pi
    sc = Scenario(
        model_name="ins",
        model=model,
        dt=dt,
        groups=groups,
        a_lo=np.zeros(0),
        a_hi=np.zeros(0),
        ctrl_id=-1,
        ctrl_params=np.zeros(0),
        ctrl_state=np.zeros(0),
        reference=reference,
        x0=x0,
        P0=model.default_P0(),
        imu_default="accel.x",
        input_channels=imu_channels(),
        mode_channel="/flight_mode/mode",
        mode_values=ref["mode"],
        setpoints={
            "/setpoint/position.north": ref["setpoint"][:, 0],
            "/setpoint/position.east": ref["setpoint"][:, 1],
            "/setpoint/position.down": ref["setpoint"][:, 2],
            "/setpoint/yaw": wrap,
        },
        onboard_rate_hz=min(ONBOARD_RATE_HZ, 1.0 / dt),
        controller_input=OPEN_LOOP,
        profile_params=None,
    )
    p = model.p
    sc.truth_extra = {
        "imu_topic": IMU_TOPIC,
        "imu_noise_std": {
            **{ch: p["gyro_noise"] for ch in imu_channels()[:3]},
            **{ch: p["accel_noise"] for ch in imu_channels()[3:]},
        },
    }
    return sc


def check_ins_faults(specs: list[FaultSpec]) -> None:
    """UsageError for a fault kind the `ins` simulation cannot inject (actuator and estimator
    kinds: the vehicle flies an open-loop reference and the on-board estimator is logscan's EKF)."""
    for spec in specs:
        kind = _defaults(spec.kind)[0]
        if kind in ACTUATOR_KINDS or kind in ESTIMATOR_KINDS:
            named = spec.kind if spec.kind == kind else f"{spec.kind} ({kind})"
            raise UsageError(
                f"fault {named} does not apply to ins (open-loop flight, no actuators or estimator to corrupt)",
                hint="ins takes the sensor kinds " + ", ".join(sorted(SENSOR_KINDS)) + " and the imu-* aliases",
            )


# ---- truth, sensors, faults ----------------------------------------------------------------------


def ins_truth(sc: Scenario, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(x_true (N, 16), IMU reading without noise (N, 6)) from the scenario's reference: the
    truth obeys the model's discrete step exactly, x_k = f(x_{k-1}, imu_k) for k >= 1 apart from
    the biases' and the barometer offset's random walks (the model's process noise); imu_0 = imu_1."""
    p = sc.model.p
    dt = sc.dt
    ref = sc.reference
    n = ref.shape[0]
    g = float(p["g"])
    v = ref[:, 3:6]
    R = thrust_attitude(ref[:, 6:9], ref[:, 9], g)
    a = np.diff(v, axis=0) / dt  # (n-1, 3): a_k = (v_{k+1} - v_k) / dt
    pos = np.empty((n, 3))
    pos[0] = ref[0, 0:3]
    pos[1:] = pos[0] + np.cumsum(v[:-1] * dt + a * (0.5 * dt * dt), axis=0)
    w = so3_log_batch(np.einsum("kji,kjl->kil", R[:-1], R[1:])) / dt  # Log(R_k^T R_{k+1}) / dt
    f_b = np.einsum("kji,kj->ki", R[:-1], a - np.array([0.0, 0.0, g]))  # R_k^T (a_k - g e3)
    b_g = _walk(rng, rng.normal(0.0, GYRO_BIAS_STD, 3), p["gyro_bias_rw"], dt, n)
    b_a = _walk(rng, rng.normal(0.0, ACCEL_BIAS_STD, 3), p["accel_bias_rw"], dt, n)
    b_baro = _walk(rng, np.array([rng.normal(*BARO_OFFSET_M)]), p["baro_offset_rw"], dt, n)
    x = np.column_stack([pos, v, euler_from_rotations(R), b_g, b_a, b_baro])
    imu = np.empty((n, 6))
    if n > 1:
        imu[1:, 0:3] = w + b_g[:-1]
        imu[1:, 3:6] = f_b + b_a[:-1]
        imu[0] = imu[1]
    else:
        imu[0] = sc.model.hover_input()
    return x, imu


@njit(cache=True)
def sample_sensors(p, x, g_id, g_m, g_off, g_ratio, std, wrap, E):
    """The aiding sensors' samples (N, total measurements), NaN where a group does not sample:
    h(x_k) of the `ins` model plus E std, angles wrapped to [-pi, pi)."""
    N = x.shape[0]
    z = np.full((N, std.size), np.nan)
    u = np.zeros(6)
    for g in range(g_id.size):
        for k in range(0, N, g_ratio[g]):
            hg = ins_h(p, g_id[g], x[k], u)
            for j in range(g_m[g]):
                c = g_off[g] + j
                v = hg[j] + E[k, c] * std[c]
                if wrap[c]:
                    v = (v + np.pi) % (2.0 * np.pi) - np.pi
                z[k, c] = v
    return z


@njit(cache=True)
def apply_sensor_faults(z, dt, f_kind, f_target, f_start, f_end, f_mag, f_unif, f_bit):
    """``z`` (N, channels; NaN where a channel has no sample) after the sensor faults of the table
    (`runner._sensor_faults`); a stuck channel holds its last sample before the fault's start."""
    N, C = z.shape
    out = z.copy()
    last = np.zeros(C)
    stuck = np.zeros(f_kind.size)
    caught = np.zeros(f_kind.size, dtype=np.bool_)
    for k in range(N):
        for c in range(C):
            v = z[k, c]
            if v != v:  # no sample
                continue
            for i in range(f_kind.size):
                if f_kind[i] == STUCK and f_target[i] == c and k >= f_start[i] and not caught[i]:
                    stuck[i] = last[c]
                    caught[i] = True
            v = _sensor_faults(k, c, v, dt, f_kind, f_target, f_start, f_end, f_mag, f_unif, f_bit, stuck)
            out[k, c] = v
            last[c] = v
    return out


def _held(z: np.ndarray, fresh: np.ndarray) -> np.ndarray:
    """Each row of ``z`` replaced by the last fresh one (zero-order hold)."""
    idx = np.where(fresh, np.arange(fresh.size), 0)
    np.maximum.accumulate(idx, out=idx)
    return z[idx]


def onboard_ekf(sc: Scenario, u: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """logscan's EKF (`run_ekf`, the analysis's filter, default start) on the logged IMU and aiding
    sensors: (x_post (N, n), P_post diagonal (N, n), rejected samples)."""
    n = u.shape[0]
    groups, offset = {}, 0
    for g in sc.groups:
        m = len(g.fields)
        fresh = np.zeros(n, dtype=np.bool_)
        fresh[:: g.ratio] = True
        groups[g.name] = AlignedGroup(
            name=g.name,
            channels=g.channels,
            z=_held(z[:, offset : offset + m], fresh),
            fresh=fresh,
            noise_std=g.noise_std,
            rate_hz=g.rate_hz,
            stale_s=2.5 / g.rate_hz,
        )
        offset += m
    run = AlignedRun(
        t=np.arange(n) * sc.dt,
        dt=sc.dt,
        start_ns=0,
        u=u,
        u_fresh=np.all(np.isfinite(u), axis=1),
        input_channels=list(sc.input_channels),
        groups=groups,
        input_names=list(sc.model.input_names),
    )
    trace = run_ekf(sc.model, run, store_gain=False, store_S=False, store_innovations=False)
    return trace.x_post, trace.P_post_diag.astype(np.float64), int(trace.rejected.sum())


def _resolve(
    sc: Scenario, faults: list[FaultSpec], duration: float, rng: np.random.Generator
) -> tuple[list[FaultEvent], FaultTable]:
    """The faults' events and table over the IMU (the model's inputs are its aliases) and the
    aiding sensors; estimator faults act on the logged variances."""
    model = sc.model
    imu = imu_channels()
    imu_targets = list(IMU_FIELDS)
    sensor_channels = list(zip(imu_targets, imu)) + [
        (target, ch) for g in sc.groups for target, ch in zip(g.targets(), g.channels)
    ]
    aliases = {**sensor_aliases(sc), **{name: t for name, t in zip(model.input_names, imu_targets)}}
    return resolve_faults(
        faults,
        duration=duration,
        dt=sc.dt,
        sensor_channels=sensor_channels,
        imu_default=sc.imu_default,
        sensor_aliases=aliases,
        actuators=[],
        state_names=model.state_names,
        estimator_fields={s: f"/ekf/variance/{s}" for s in model.state_names},
        rng=rng,
    )


def _sensed(sc: Scenario, x_true: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The aiding sensors' noisy samples of the true states (each group at its rate)."""
    model = sc.model
    n_steps = sc.reference.shape[0]
    std = np.concatenate([g.noise_std for g in sc.groups])
    g_m = np.array([len(g.fields) for g in sc.groups], dtype=np.int64)
    return sample_sensors(
        model.param_vector(sc.dt),
        np.ascontiguousarray(x_true),
        np.array([g.group_id for g in sc.groups], dtype=np.int64),
        g_m,
        np.concatenate([[0], np.cumsum(g_m)[:-1]]).astype(np.int64),
        np.array([g.ratio for g in sc.groups], dtype=np.int64),
        std,
        np.concatenate([g.wrap for g in sc.groups]).astype(np.bool_),
        rng.standard_normal((n_steps, std.size)),
    )


def simulate_ins(
    sc: Scenario,
    faults: list[FaultSpec],
    *,
    duration: float,
    seed: int,
    aggressive: bool = False,
    glitches_per_min: float = 0.0,
) -> Simulation:
    """One `ins` run (see the module docstring), deterministic in ``seed``; called by
    `dispatch.simulate`, which has checked its arguments."""
    check_ins_faults(faults)
    rng = np.random.default_rng(seed)
    model = sc.model
    glitches = _glitches(sc, duration, glitches_per_min, np.random.default_rng([seed, 3]))
    events, table = _resolve(sc, faults + glitches, duration, np.random.default_rng([seed, 2]))
    events, transients = events[: len(faults)], events[len(faults) :]
    started = time.perf_counter()
    x_true, imu_true = ins_truth(sc, rng)
    imu_std = np.array([model.p["gyro_noise"]] * 3 + [model.p["accel_noise"]] * 3)
    imu_noisy = imu_true + rng.standard_normal(imu_true.shape) * imu_std
    z = _sensed(sc, x_true, rng)
    logged = apply_sensor_faults(
        np.ascontiguousarray(np.hstack([imu_noisy, z])),
        sc.dt,
        table.kind,
        table.target,
        table.start,
        table.end,
        table.magnitude,
        table.uniform,
        table.bit,
    )
    u_log, z_log = np.ascontiguousarray(logged[:, :6]), np.ascontiguousarray(logged[:, 6:])
    x_hat, P_diag, rejected = onboard_ekf(sc, u_log, z_log)
    elapsed = time.perf_counter() - started
    return Simulation(
        scenario=sc,
        seed=seed,
        duration=duration,
        aggressive=aggressive,
        events=events,
        transients=transients,
        faults=table,
        x_true=x_true,
        u_cmd=u_log,
        u_act=imu_true,
        z=z_log,
        x_hat=x_hat,
        P_diag=corrupt_logged_variance(P_diag, table),
        rejected=rejected,
        elapsed_s=elapsed,
    )


follow_dependencies(__name__)
