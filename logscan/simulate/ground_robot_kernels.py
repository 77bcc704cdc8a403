"""The numba closed loop of `logscan simulate ground_robot`: plant, on-board filters and controllers
of the checkpointing / roll-forward-recovery paper's hierarchical ground robot, one inner step
(100 Hz) at a time.

Shapes (N inner steps of period p.dt, No = N // ratio outer steps of period ratio * p.dt):
 x0 (3,) true [x, y, theta]; m0 (2, 2) true [i, w] of the left and right motor; integ0 (2,) PID
 integrators; Ad (2, 2), Bd (2,) the motors' discrete model; Qo (3, 3) outer process noise per
 outer step, Qm (2, 2) a motor's per inner step; W_o (N, 3) unicycle process noise draws (per
 inner step in `wheels` coupling, rows 0 .. No-1 per outer step otherwise), W_m (N, 2, 2) motors';
 E_o (No, 3), E_m (N, 2) standard normal sensor noise; A_o (No, 3), A_m (N, 2) attack offsets
 added to the mocap and encoder readings (0 outside the attacks).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from logscan.numba_cache import follow_dependencies


class RobotParams(NamedTuple):
    """Scalar settings of the loop (floats, so numba sees one homogeneous tuple)."""

    dt: float  # inner period (s)
    ratio: float  # inner steps per outer step
    radius: float  # reference circle radius (m), x_ref = radius [cos t, sin t]
    l: float  # dynamic inversion offset (m)
    k1: float
    k2: float
    Rw: float  # wheel radius (m)
    Lw: float  # wheel base (m)
    Kp: float
    Ki: float
    Kd: float
    v_max: float  # |motor voltage| limit (V); inf: none
    r_mocap: float  # mocap noise std (m, m, rad)
    r_enc: float  # encoder noise std (rad/s)
    wheels: float  # 1: the unicycle moves with the motors' wheel speeds; 0: with the commanded (v, w)


@njit(cache=True)
def wrap_angle(a):
    # to [-pi, pi)
    return (a + np.pi) % (2.0 * np.pi) - np.pi


@njit(cache=True)
def dynamic_inversion(xh, t, p):
    """(v, w) of the paper's eq. 25 from the estimate xh = [x, y, theta] at time t, tracking
    x_ref = radius [cos t, sin t] (its eq. 35) with x_ref dot = radius [-sin t, cos t]."""
    c, s = np.cos(xh[2]), np.sin(xh[2])
    ax = -p.radius * np.sin(t) + p.k1 * (p.radius * np.cos(t) - xh[0])
    ay = p.radius * np.cos(t) + p.k2 * (p.radius * np.sin(t) - xh[1])
    # [v; w] = [[cos, sin], [-sin / l, cos / l]] [ax; ay]
    return c * ax + s * ay, (-s * ax + c * ay) / p.l


@njit(cache=True)
def wheel_references(v, w, p):
    """(left, right) wheel-speed references of eq. 39: (2 v -+ w Lw) / (2 Rw)."""
    return (2.0 * v - w * p.Lw) / (2.0 * p.Rw), (2.0 * v + w * p.Lw) / (2.0 * p.Rw)


@njit(cache=True)
def body_speeds(w_left, w_right, p):
    """(v, w) of the robot from its wheel speeds, the inverse of eq. 39."""
    return p.Rw * (w_right + w_left) / 2.0, p.Rw * (w_right - w_left) / p.Lw


@njit(cache=True)
def motor_kf(x, P, V_prev, z, Ad, Bd, Qm, r2, predict):
    """One step of a motor's KF in place: predict with the voltage applied over the last period
    (x = Ad x + Bd V; P = Ad P Ad^T + Q), then update on the encoder (H = [0, 1])."""
    if predict:
        x0 = Ad[0, 0] * x[0] + Ad[0, 1] * x[1] + Bd[0] * V_prev
        x1 = Ad[1, 0] * x[0] + Ad[1, 1] * x[1] + Bd[1] * V_prev
        x[0], x[1] = x0, x1
        P[:, :] = Ad @ P @ Ad.T + Qm
    # y = z - H x; S = H P H^T + R; K = P H^T / S
    y = z - x[1]
    S = P[1, 1] + r2
    K = P[:, 1] / S
    x[0] += K[0] * y
    x[1] += K[1] * y
    # Joseph form (I - K H) P (I - K H)^T + K R K^T
    IKH = np.eye(2)
    IKH[0, 1] -= K[0]
    IKH[1, 1] -= K[1]
    P[:, :] = IKH @ P @ IKH.T + r2 * np.outer(K, K)


@njit(cache=True)
def outer_ekf(x, P, u_prev, z, dt_o, Qo, Ro, predict):
    """One step of the outer EKF in place: the unicycle's Euler step with the last commanded
    (v, w) and its Jacobian (eqs. 23, 36), then the mocap update (H = I, theta's innovation
    wrapped)."""
    if predict:
        c, s = np.cos(x[2]), np.sin(x[2])
        F = np.eye(3)
        F[0, 2] = -u_prev[0] * s * dt_o
        F[1, 2] = u_prev[0] * c * dt_o
        x[0] += u_prev[0] * c * dt_o
        x[1] += u_prev[0] * s * dt_o
        x[2] += u_prev[1] * dt_o
        P[:, :] = F @ P @ F.T + Qo
    y = z - x
    y[2] = wrap_angle(y[2])
    S = P + Ro
    # K = P S^-1 (solve, S symmetric)
    K = np.linalg.solve(S, P).T
    x += K @ y
    IK = np.eye(3) - K
    P[:, :] = IK @ P @ IK.T + K @ Ro @ K.T


@njit(cache=True)
def robot_loop(p, x0, m0, integ0, Ad, Bd, Qo, Qm, W_o, W_m, E_o, E_m, A_o, A_m):
    """Run the closed loop; returns the logged and true series (see the module docstring for the
    arguments): x_true (No, 3), m_true (N, 2, 2), u_o (No, 2) commanded (v, w), w_ref (No, 2),
    V (N, 2) applied voltages, z_o (No, 3) mocap, z_m (N, 2) encoders, xh_o (No, 3), Ph_o (No, 3)
    outer estimate and variance, xh_m (N, 2, 2), Ph_m (N, 2, 2) motor estimates and variances.
    Input u_k is computed at t_k and applied over [t_k, t_{k+1}); the filters predict step k with
    u_{k-1}."""
    N = W_m.shape[0]
    ratio = int(p.ratio)
    No = N // ratio
    dt_o = p.dt * ratio
    x_true, u_o, w_ref = np.zeros((No, 3)), np.zeros((No, 2)), np.zeros((No, 2))
    z_o, xh_o, Ph_o = np.zeros((No, 3)), np.zeros((No, 3)), np.zeros((No, 3))
    m_true, xh_m, Ph_m = np.zeros((N, 2, 2)), np.zeros((N, 2, 2)), np.zeros((N, 2, 2))
    V, z_m = np.zeros((N, 2)), np.zeros((N, 2))
    X, M = x0.copy(), m0.copy()
    xo, Po = x0.copy(), Qo.copy()  # the on-board filters start at the true state
    xm, Pm = m0.copy(), np.zeros((2, 2, 2))
    for j in range(2):
        Pm[j] = Qm
    Ro = np.eye(3) * p.r_mocap**2
    integ, e_prev = integ0.copy(), np.zeros(2)
    V_prev, u_prev, ref = np.zeros(2), np.zeros(2), np.zeros(2)
    for k in range(N):
        outer = k % ratio == 0 and k // ratio < No
        for j in range(2):  # encoders at t_k, then each motor's KF
            m_true[k, j] = M[j]
            z_m[k, j] = M[j, 1] + p.r_enc * E_m[k, j] + A_m[k, j]
            motor_kf(xm[j], Pm[j], V_prev[j], z_m[k, j], Ad, Bd, Qm, p.r_enc**2, k > 0)
            xh_m[k, j] = xm[j]
            Ph_m[k, j, 0], Ph_m[k, j, 1] = Pm[j, 0, 0], Pm[j, 1, 1]
        if outer:  # mocap at t_k, the outer EKF, then the outer controller
            i = k // ratio
            x_true[i] = X
            for c in range(3):
                z_o[i, c] = X[c] + p.r_mocap * E_o[i, c] + A_o[i, c]
            z_o[i, 2] = wrap_angle(z_o[i, 2])
            outer_ekf(xo, Po, u_prev, z_o[i].copy(), dt_o, Qo, Ro, i > 0)
            xh_o[i], Ph_o[i] = xo, np.diag(Po)
            v, w = dynamic_inversion(xo, k * p.dt, p)
            u_o[i, 0], u_o[i, 1] = v, w
            ref[0], ref[1] = wheel_references(v, w, p)
            w_ref[i] = ref
            u_prev[0], u_prev[1] = v, w
            if p.wheels == 0.0:  # the unicycle moves with the commanded (v, w) for one outer step
                c, s = np.cos(X[2]), np.sin(X[2])
                X[0] += v * c * dt_o + W_o[i, 0]
                X[1] += v * s * dt_o + W_o[i, 1]
                X[2] += w * dt_o + W_o[i, 2]
        for j in range(2):  # PID on the estimated wheel-speed error
            e = ref[j] - xm[j, 1]
            if k == 0:
                e_prev[j] = e  # no derivative kick at the start
            integ[j] += e * p.dt
            Vj = p.Kp * e + p.Ki * integ[j] + p.Kd * (e - e_prev[j]) / p.dt
            e_prev[j] = e
            V[k, j] = min(max(Vj, -p.v_max), p.v_max)
        if p.wheels != 0.0:  # Euler step of the unicycle with the wheels' speeds at t_k
            v_a, w_a = body_speeds(M[0, 1], M[1, 1], p)
            c, s = np.cos(X[2]), np.sin(X[2])
            X[0] += v_a * c * p.dt + W_o[k, 0]
            X[1] += v_a * s * p.dt + W_o[k, 1]
            X[2] += w_a * p.dt + W_o[k, 2]
        for j in range(2):  # motors: x_{k+1} = Ad x_k + Bd V_k + w_k (eq. 26 with "x_k +")
            M[j] = Ad @ M[j] + Bd * V[k, j] + W_m[k, j]
        V_prev[:] = V[k]
    return x_true, m_true, u_o, w_ref, V, z_o, z_m, xh_o, Ph_o, xh_m, Ph_m


follow_dependencies(__name__)  # the disk cache filed by what the kernels compile (logscan.numba_cache)
