"""Closed-loop controllers of the simulator (numba) and their reference trajectories (numpy).

Every controller reads the ON-BOARD ESTIMATE (never the true state), so sensor and estimator faults
propagate into the flight/drive as they would on a vehicle. Each has the signature
``control(cp, cs, r, xh, dt, u)``: controller parameters ``cp``, mutable controller state ``cs``
(integrators, the hand wheel), the reference row ``r`` of this step, the estimate ``xh``; it
writes the input into ``u``. The references are computed vectorised before the loop.

 - quadcopter (id 0): cascaded PD: position (PD, PID on altitude) -> desired acceleration ->
   thrust and tilt set-points -> attitude PD -> body torques. Reference: hover, then a
   figure-eight, repeating every 60 s ("aggressive": faster, larger eight and yaw swings).
 - steer_by_wire (id 1): PD hand wheel (a driver following a steering-wheel profile of lane
   changes) and a sliding-mode front-wheel controller tracking theta_h / N_theta (paper V.B).
 - dc_motor (id 2): PI speed control of each wheel on the estimated speed through a schedule of
   constant-speed modes, given speed changes or a random piecewise-constant profile.
 - hover_uav (id 3): the linearised hover: PD position hold -> roll/pitch set-points (plus the
   attitude excitation of the reference) -> attitude PD -> wrench deviation -> rotor thrust
   deviations through the inverse mixer. Reference: hover for a settle time, then roll, pitch and
   yaw set-point excitation (multi-sines).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from logscan.numba_cache import follow_dependencies

QUAD_CTRL, SBW_CTRL, DCM_CTRL, HOVER_CTRL = 0, 1, 2, 3


@njit(cache=True)
def _clip(v, lo, hi):
    return min(max(v, lo), hi)


@njit(cache=True)
def _wrap(a):
    return (a + np.pi) % (2.0 * np.pi) - np.pi


# ---- quadcopter ------------------------------------------------------------------------------
# cp: m, g, Ix, Iy, Iz, kp_xy, kd_xy, kp_z, kd_z, ki_z, kp_att, kd_att, kp_yaw, kd_yaw, tilt_max
# r:  x, y, z, vx, vy, vz, ax, ay, az, yaw
@njit(cache=True)
def quad_control(cp, cs, r, xh, dt, u):
    m, g = cp[0], cp[1]
    ax = r[6] + cp[5] * (r[0] - xh[0]) + cp[6] * (r[3] - xh[3])
    ay = r[7] + cp[5] * (r[1] - xh[1]) + cp[6] * (r[4] - xh[4])
    ez = r[2] - xh[2]
    cs[0] = _clip(cs[0] + ez * dt, -2.0, 2.0)  # altitude integrator
    az = r[8] + cp[7] * ez + cp[8] * (r[5] - xh[5]) + cp[9] * cs[0]
    psi = xh[8]
    # small-angle inversion of a = R e3 T/m - g e3 (ZYX): theta = (c a_x + s a_y)/g, phi = (s a_x - c a_y)/g
    theta_d = _clip((np.cos(psi) * ax + np.sin(psi) * ay) / g, -cp[14], cp[14])
    phi_d = _clip((np.sin(psi) * ax - np.cos(psi) * ay) / g, -cp[14], cp[14])
    tilt = max(np.cos(xh[6]) * np.cos(xh[7]), 0.5)
    u[0] = m * (g + az) / tilt
    u[1] = cp[2] * (cp[10] * (phi_d - xh[6]) - cp[11] * xh[9])
    u[2] = cp[3] * (cp[10] * (theta_d - xh[7]) - cp[11] * xh[10])
    u[3] = cp[4] * (cp[12] * _wrap(r[9] - xh[8]) - cp[13] * xh[11])


def quad_reference(t: np.ndarray, aggressive: bool) -> np.ndarray:
    """(N, 10) reference [x, y, z, vx, vy, vz, ax, ay, az, yaw]: per 60 s cycle a 15 s hover at
    (0, 0, 2 m), then a figure-eight (Lissajous 1:2) faded in and out over 3 s."""
    cycle, hover, fade = 60.0, 15.0, 3.0
    amp, period = (5.0, 7.5) if aggressive else (3.0, 15.0)
    omega = 2.0 * np.pi / period
    tc = np.mod(t, cycle)
    te = np.clip(tc - hover, 0.0, None)
    span = cycle - hover
    # envelope: sin^2 ramps at both ends of the figure-eight segment
    ramp_in = np.sin(0.5 * np.pi * np.clip(te / fade, 0.0, 1.0)) ** 2
    ramp_out = np.sin(0.5 * np.pi * np.clip((span - te) / fade, 0.0, 1.0)) ** 2
    env = np.where(tc >= hover, ramp_in * ramp_out, 0.0)
    ref = np.zeros((t.size, 10))
    ref[:, 0] = env * amp * np.sin(omega * te)
    ref[:, 1] = env * 0.5 * amp * np.sin(2.0 * omega * te)
    ref[:, 2] = 2.0 + (env * 0.5 * np.sin(omega * te) if aggressive else 0.0)
    if aggressive:
        ref[:, 9] = env * 0.6 * np.sin(0.5 * omega * te)
    dt = t[1] - t[0] if t.size > 1 else 1.0
    for i in range(3):
        ref[:, 3 + i] = np.gradient(ref[:, i], dt)
        ref[:, 6 + i] = np.gradient(ref[:, 3 + i], dt)
    return ref


def quad_params(model, aggressive: bool) -> np.ndarray:
    """Controller gains: position loop ~0.8 rad/s (xy), attitude loop ~8 rad/s, damped 0.9."""
    p = model.p
    tilt = 0.6 if aggressive else 0.35
    wn_xy, wn_z, wn_att, wn_yaw = (1.2, 2.0, 10.0, 4.0) if aggressive else (0.8, 1.5, 8.0, 3.0)
    return np.array(
        [
            p["mass"],
            p["g"],
            p["Ixx"],
            p["Iyy"],
            p["Izz"],
            wn_xy**2,
            1.8 * wn_xy,
            wn_z**2,
            1.8 * wn_z,
            0.3 * wn_z**2,
            wn_att**2,
            1.8 * wn_att,
            wn_yaw**2,
            1.8 * wn_yaw,
            tilt,
        ]
    )


# ---- steer-by-wire ---------------------------------------------------------------------------
# cp: Jeq, Beq, Fs, Cf, lt, lf, V, vs, N_theta, Jh, Bh, ch, kp_h, kd_h, lam, K, phi
# cs: theta_h, theta_h_dot (the hand wheel)
# r:  theta_h_ref, theta_h_ref_dot
@njit(cache=True)
def sbw_control(cp, cs, r, xh, dt, u):
    Jeq, Beq, Fs, Cf, lt, lf, V, vs, N = cp[0], cp[1], cp[2], cp[3], cp[4], cp[5], cp[6], cp[7], cp[8]
    Jh, Bh, ch, kp_h, kd_h, lam, K, phi = cp[9], cp[10], cp[11], cp[12], cp[13], cp[14], cp[15], cp[16]
    # driver PD on the hand wheel: Jh th_dd + Bh th_d + ch th = tau_h
    tau_h = kp_h * (r[0] - cs[0]) + kd_h * (r[1] - cs[1])
    th_dd = (tau_h - Bh * cs[1] - ch * cs[0]) / Jh
    cs[1] += th_dd * dt
    cs[0] += cs[1] * dt
    # ECU reference for the front wheel: delta_r = theta_h / N_theta
    d_r, dd_r, ddd_r = cs[0] / N, cs[1] / N, th_dd / N
    e = xh[0] - d_r
    e_dot = xh[1] - dd_r
    s = e_dot + lam * e  # sliding surface
    tau_e = Cf * lt * (xh[0] - xh[2] - lf * xh[3] / V)  # self-aligning torque estimate
    # tau_eq = Jeq (dd_r - lam e_dot) + Beq d_dot + Fs tanh(d_dot/vs) + tau_e - Jeq K sat(s/phi)
    u[0] = (
        Jeq * (ddd_r - lam * e_dot)
        + Beq * xh[1]
        + Fs * np.tanh(xh[1] / vs)
        + tau_e
        - Jeq * K * _clip(s / phi, -1.0, 1.0)
    )


def sbw_reference(t: np.ndarray, n_theta: float, aggressive: bool) -> np.ndarray:
    """(N, 2) hand-wheel reference [theta_h, theta_h_dot]: per 20 s cycle a double lane change
    (one-period sine of 4 s) then straight driving; amplitude 0.04 rad at the front wheel
    (0.08 aggressive), alternating sides."""
    cycle, length = 20.0, 4.0
    amp = 0.08 if aggressive else 0.04
    tc = np.mod(t, cycle)
    side = np.where(np.mod(np.floor(t / cycle), 2.0) == 0.0, 1.0, -1.0)
    delta = np.where(tc < length, side * amp * np.sin(2.0 * np.pi * tc / length), 0.0)
    ref = np.zeros((t.size, 2))
    ref[:, 0] = n_theta * delta
    dt = t[1] - t[0] if t.size > 1 else 1.0
    ref[:, 1] = np.gradient(ref[:, 0], dt)
    return ref


def sbw_params(model) -> np.ndarray:
    p = model.p
    return np.array(
        [
            p["Jeq"],
            p["Beq"],
            p["Fs"],
            p["Cf"],
            p["lc"] + p["lp"],
            p["lf"],
            p["V"],
            p["vs"],
            p.get("N_theta", 12.0),
            0.1,
            0.5,
            0.2,
            10.0,
            1.0,
            10.0,
            3.0,
            0.1,
        ]
    )


# ---- dc_motor --------------------------------------------------------------------------------
# cp: kp, ki, u_lo, u_hi, n_wheels, then per wheel (speed state index, speed per state unit),
#     then the feed-forward input per m/s
# cs: one integrator per wheel
# r:  commanded speed (m/s)
@njit(cache=True)
def dcm_control(cp, cs, r, xh, dt, u):
    kp, ki, lo, hi, nw = cp[0], cp[1], cp[2], cp[3], int(cp[4])
    ff = cp[5 + 2 * nw]
    for w in range(nw):
        e = r[0] - cp[6 + 2 * w] * xh[int(cp[5 + 2 * w])]
        v = ff * r[0] + kp * e + ki * cs[w]
        # anti-windup: integrate only while unsaturated or when the error unwinds it
        if (lo < v < hi) or (v >= hi and e < 0.0) or (v <= lo and e > 0.0):
            cs[w] += e * dt
        u[w] = _clip(v, lo, hi)


def dcm_reference(t: np.ndarray, modes: tuple[float, ...], hold: float, rng) -> np.ndarray:
    """(N, 1) commanded speed: constant-speed modes held ``hold`` seconds each, in an order that
    visits every mode (a seeded shuffle per round, so mode changes go up and down)."""
    n_slots = int(np.ceil((t[-1] + 1e-9) / hold)) + 1 if t.size else 1
    order = np.concatenate([rng.permutation(len(modes)) for _ in range(n_slots // len(modes) + 1)])
    speeds = np.asarray(modes, dtype=np.float64)[order[:n_slots]]
    return speeds[np.minimum((t / hold).astype(np.int64), n_slots - 1)][:, None]


def dcm_steps_reference(t: np.ndarray, changes: list[tuple[float, float]]) -> np.ndarray:
    """(N, 1) commanded speed: piecewise constant, ``changes`` = [(from t, speed), ...] with the
    first at t = 0 and increasing times (``--speed 1.0,0.4@30``)."""
    starts = np.array([c[0] for c in changes], dtype=np.float64)
    speeds = np.array([c[1] for c in changes], dtype=np.float64)
    index = np.searchsorted(starts, t + 1e-9, side="right") - 1
    return speeds[np.maximum(index, 0)][:, None]


def dcm_random_reference(t: np.ndarray, modes: tuple[float, ...], hold: tuple[float, float], rng) -> np.ndarray:
    """(N, 1) commanded speed of ``--speed random``: piecewise constant, each speed one of
    ``modes`` (never the previous one) held uniform ``hold`` = (lo, hi) seconds; seeded by ``rng``."""
    end = float(t[-1]) if t.size else 0.0
    changes = [(0.0, float(rng.choice(modes)))]
    at = float(rng.uniform(*hold))
    while at <= end:
        others = [m for m in modes if m != changes[-1][1]]
        changes.append((at, float(others[rng.integers(len(others))])))
        at += float(rng.uniform(*hold))
    return dcm_steps_reference(t, changes)


# ---- hover_uav -------------------------------------------------------------------------------
# cp: the quadcopter's (m, g, Ix, Iy, Iz, kp_xy, kd_xy, kp_z, kd_z, ki_z, kp_att, kd_att, kp_yaw,
#     kd_yaw, tilt_max), ki_att, tau_z_max, then the inverse mixer (4 x 4, row-major): rotor
#     thrust deviations = M^-1 @ wrench deviation
# cs: integrators of the altitude, roll and pitch errors
# r:  x, y, z, roll excitation, pitch excitation, yaw
@njit(cache=True)
def hover_control(cp, cs, r, xh, dt, u):
    m, g = cp[0], cp[1]
    ax = cp[5] * (r[0] - xh[0]) - cp[6] * xh[3]
    ay = cp[5] * (r[1] - xh[1]) - cp[6] * xh[4]
    # linearised: vx' = g pitch, vy' = -g roll
    theta_d = _clip(ax / g + r[4], -cp[14], cp[14])
    phi_d = _clip(-ay / g + r[3], -cp[14], cp[14])
    ez, er, ep = r[2] - xh[2], phi_d - xh[6], theta_d - xh[7]
    # integral action (clamped): a rotor that delivers less than commanded is compensated
    cs[0] = _clip(cs[0] + ez * dt, -2.0, 2.0)
    cs[1] = _clip(cs[1] + er * dt, -0.5, 0.5)
    cs[2] = _clip(cs[2] + ep * dt, -0.5, 0.5)
    w0 = m * (cp[7] * ez - cp[8] * xh[5] + cp[9] * cs[0])
    w1 = cp[2] * (cp[10] * er - cp[11] * xh[9] + cp[15] * cs[1])
    w2 = cp[3] * (cp[10] * ep - cp[11] * xh[10] + cp[15] * cs[2])
    # yaw has the least authority (three rotors cannot hold it): clipped so it never takes the
    # rotors' thrust from roll, pitch and altitude
    w3 = _clip(cp[4] * (cp[12] * _wrap(r[5] - xh[8]) - cp[13] * xh[11]), -cp[16], cp[16])
    for i in range(4):
        b = 17 + 4 * i
        u[i] = cp[b] * w0 + cp[b + 1] * w1 + cp[b + 2] * w2 + cp[b + 3] * w3


def hover_reference(t: np.ndarray, aggressive: bool, settle: float) -> np.ndarray:
    """(N, 6) reference [x, y, z, roll excitation, pitch excitation, yaw] of the hover_uav: hold
    the hover point; from ``settle`` on, roll and pitch set-point excitation (two sines each,
    0.08 + 0.04 rad; aggressive: doubled) and a slow yaw swing (0.2 rad at 0.05 Hz), faded in
    over 1 s."""
    scale = 2.0 if aggressive else 1.0
    te = np.clip(t - settle, 0.0, None)
    env = np.where(t >= settle, np.sin(0.5 * np.pi * np.clip(te, 0.0, 1.0)) ** 2, 0.0)
    ref = np.zeros((t.size, 6))
    ref[:, 3] = env * scale * (0.08 * np.sin(2.0 * np.pi * 0.4 * te) + 0.04 * np.sin(2.0 * np.pi * 1.3 * te))
    ref[:, 4] = env * scale * (0.08 * np.sin(2.0 * np.pi * 0.3 * te + 1.0) + 0.04 * np.sin(2.0 * np.pi * 1.1 * te))
    ref[:, 5] = env * 0.2 * np.sin(2.0 * np.pi * 0.05 * te)
    return ref


def hover_params(model, aggressive: bool) -> np.ndarray:
    """The quadcopter's gains (`quad_params`, nominal parameters), the roll and pitch integral
    gain 0.2 wn_att^2, the yaw torque limit 0.05 N m, and the inverse mixer."""
    quad = quad_params(model, aggressive)
    extra = [0.2 * quad[10], 0.05]
    return np.concatenate([quad, extra, np.linalg.inv(model.mixer_matrix()).ravel()])


@njit(cache=True)
def control(ctrl_id, cp, cs, r, xh, dt, u):
    if ctrl_id == QUAD_CTRL:
        quad_control(cp, cs, r, xh, dt, u)
    elif ctrl_id == SBW_CTRL:
        sbw_control(cp, cs, r, xh, dt, u)
    elif ctrl_id == HOVER_CTRL:
        hover_control(cp, cs, r, xh, dt, u)
    else:
        dcm_control(cp, cs, r, xh, dt, u)


follow_dependencies(__name__)  # the disk cache filed by what the kernels compile (logscan.numba_cache)
