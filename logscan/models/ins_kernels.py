"""Numba functions of the IMU-driven `ins` model: strapdown prediction, error-state Jacobian,
measurements and the multiplicative attitude update (box-plus).

Frames: world = local NED tangent plane (flat, non-rotating Earth), body = FRD. R = R(roll, pitch,
yaw) is the body-to-world rotation Rz(yaw) Ry(pitch) Rx(roll) (`quad_rotation_into`).

State x (16): p_NED (0:3), v_NED (3:6), roll, pitch, yaw (6:9), gyro bias (9:12), accelerometer
bias (12:15), barometer offset (15). The filter's covariance is over the error state
dx = [dp, dv, dtheta, dbg, dba, db_baro], where the attitude error dtheta is a body-frame rotation
vector: R_true = R Exp(dtheta). F and H are the exact first-order Jacobians with respect to dx,
and the update applies x (+) dx (`ins_boxplus_into`): additive everywhere except the attitude,
which is rotated. The Euler angles only store the nominal attitude; no Jacobian goes through them.

Shapes: p (INS_N_PARAMS,) packed by `Ins.param_vector` (layout IP_*), u (6,) = gyro (rad/s),
specific force (m/s^2), both body frame; F (16, 16); a group's rows r:r+m of hx and Hs (m, 16).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from logscan.models.model_kernels import ModelKernels, register
from logscan.models.quadcopter_kernels import quad_rotation_into
from logscan.numba_cache import follow_dependencies

INS_ID = 5  # its registered id (logscan.models.model_kernels)
INS_N = 16

# ---- parameter layout -------------------------------------------------------------------------
(IP_G,) = range(1)
INS_N_PARAMS = 1

# groups
INS_GNSS_POSITION, INS_GNSS_VELOCITY, INS_BARO, INS_HEADING, INS_ATTITUDE, INS_ODOMETRY = range(6)


@njit(cache=True, no_cpython_wrapper=True)
def _skew_into(w0, w1, w2, S):
    """S = [w]x, the cross-product matrix (S v = w x v)."""
    S[0, 0] = 0.0
    S[0, 1] = -w2
    S[0, 2] = w1
    S[1, 0] = w2
    S[1, 1] = 0.0
    S[1, 2] = -w0
    S[2, 0] = -w1
    S[2, 1] = w0
    S[2, 2] = 0.0


@njit(cache=True)
def so3_exp_jr_into(w0, w1, w2, E, Jr):
    """E = Exp(w) (Rodrigues) and Jr = the right Jacobian of SO(3) at w:
    Exp(w) = I + a [w]x + b [w]x^2,  Jr(w) = I - b [w]x + c [w]x^2,
    a = sin t / t, b = (1 - cos t) / t^2, c = (t - sin t) / t^3, t = |w| (Taylor series below 1e-4)."""
    t2 = w0 * w0 + w1 * w1 + w2 * w2
    t = np.sqrt(t2)
    if t < 1e-4:
        a = 1.0 - t2 / 6.0
        b = 0.5 - t2 / 24.0
        c = 1.0 / 6.0 - t2 / 120.0
    else:
        a = np.sin(t) / t
        b = (1.0 - np.cos(t)) / t2
        c = (t - np.sin(t)) / (t2 * t)
    # [w]x^2 = w w^T - t^2 I
    W = ((0.0, -w2, w1), (w2, 0.0, -w0), (-w1, w0, 0.0))
    w = (w0, w1, w2)
    for i in range(3):
        for j in range(3):
            W2 = w[i] * w[j] - (t2 if i == j else 0.0)
            eye = 1.0 if i == j else 0.0
            E[i, j] = eye + a * W[i][j] + b * W2
            Jr[i, j] = eye - b * W[i][j] + c * W2


@njit(cache=True, no_cpython_wrapper=True)
def euler_from_rotation(R):
    """(roll, pitch, yaw) of R = Rz(yaw) Ry(pitch) Rx(roll); pitch in [-pi/2, pi/2], yaw in
    (-pi, pi]."""
    s = -R[2, 0]
    s = min(1.0, max(-1.0, s))
    return np.arctan2(R[2, 1], R[2, 2]), np.arcsin(s), np.arctan2(R[1, 0], R[0, 0])


@njit(cache=True, no_cpython_wrapper=True)
def euler_rate_matrix_into(phi, theta, Em, r0):
    """Rows r0:r0+3 of Em, columns 0:3 = E(phi, theta), the map from a body-frame rotation
    (rate) to the Euler angles' (rate): d(roll, pitch, yaw) = E dtheta for R Exp(dtheta),
    E = [[1, sf tt, cf tt], [0, cf, -sf], [0, sf / ct, cf / ct]]."""
    cf, sf = np.cos(phi), np.sin(phi)
    ct = np.cos(theta)
    tt = np.sin(theta) / ct
    Em[r0, 0] = 1.0
    Em[r0, 1] = sf * tt
    Em[r0, 2] = cf * tt
    Em[r0 + 1, 0] = 0.0
    Em[r0 + 1, 1] = cf
    Em[r0 + 1, 2] = -sf
    Em[r0 + 2, 0] = 0.0
    Em[r0 + 2, 1] = sf / ct
    Em[r0 + 2, 2] = cf / ct


@njit(cache=True, no_cpython_wrapper=True)
def _mat3_mul_into(A, B, C):
    """C = A B (3 x 3)."""
    for i in range(3):
        for j in range(3):
            t = 0.0
            for k in range(3):
                t += A[i, k] * B[k, j]
            C[i, j] = t


@njit(cache=True, no_cpython_wrapper=True)
def _rotate_euler(x, d0, d1, d2, out, R, E, Jr, M):
    """out[6:9] = the Euler angles of R(x[6:9]) Exp(d) (R, E, Jr, M: 3x3 work arrays)."""
    quad_rotation_into(x[6], x[7], x[8], R)
    so3_exp_jr_into(d0, d1, d2, E, Jr)
    _mat3_mul_into(R, E, M)
    out[6], out[7], out[8] = euler_from_rotation(M)


@njit(cache=True)
def ins_boxplus_into(p, x, dx, out, R3, D3):
    """out = x (+) dx: p, v, biases add; the attitude rotates, R(out) = R(x) Exp(dx[6:9]). R3 (3, 3)
    and D3 (3, 3, 3): work arrays (the EKF's step loop, compiled without numba's reference
    counting, cannot allocate)."""
    for i in range(INS_N):
        out[i] = x[i] + dx[i]
    _rotate_euler(x, dx[6], dx[7], dx[8], out, R3, D3[0], D3[1], D3[2])


@njit(cache=True)
def ins_predict_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """Strapdown step with the IMU held over dt, and its error-state Jacobian F:

        w = u_gyro - b_g,  a_b = u_acc - b_a,  a_n = R a_b + g e3          (NED: gravity down)
        p' = p + v dt + a_n dt^2 / 2,  v' = v + a_n dt,  R' = R Exp(w dt),  biases' = biases
        F: dp' / dv = dt I;  d(p', v') / dtheta = (dt^2 / 2, dt) (-R [a_b]x);
           d(p', v') / db_a = (dt^2 / 2, dt) (-R);  dtheta' / dtheta = Exp(w dt)^T;
           dtheta' / db_g = -Jr(w dt) dt.
    A, J, Jn (n, n) serve as 3x3 work arrays (their leading blocks)."""
    g = p[IP_G]
    R = A[0:3, 0:3]
    E = A[3:6, 0:3]
    Jr = A[6:9, 0:3]
    M = J[0:3, 0:3]
    quad_rotation_into(x[6], x[7], x[8], R)
    w0, w1, w2 = u[0] - x[9], u[1] - x[10], u[2] - x[11]
    ab0, ab1, ab2 = u[3] - x[12], u[4] - x[13], u[5] - x[14]
    h2 = 0.5 * dt * dt
    for i in range(3):
        an = R[i, 0] * ab0 + R[i, 1] * ab1 + R[i, 2] * ab2 + (g if i == 2 else 0.0)
        x_next[i] = x[i] + x[3 + i] * dt + an * h2
        x_next[3 + i] = x[3 + i] + an * dt
    for i in range(9, INS_N):
        x_next[i] = x[i]
    # R' = R Exp(w dt)
    so3_exp_jr_into(w0 * dt, w1 * dt, w2 * dt, E, Jr)
    _mat3_mul_into(R, E, M)
    x_next[6], x_next[7], x_next[8] = euler_from_rotation(M)
    # F
    for i in range(INS_N):
        for j in range(INS_N):
            F[i, j] = 0.0
        F[i, i] = 1.0
    Sk = Jn[0:3, 0:3]
    _skew_into(ab0, ab1, ab2, Sk)
    for i in range(3):
        F[i, 3 + i] = dt
        for j in range(3):
            t = 0.0
            for k in range(3):
                t += R[i, k] * Sk[k, j]
            F[i, 6 + j] = -h2 * t  # -R [a_b]x
            F[3 + i, 6 + j] = -dt * t
            F[i, 12 + j] = -h2 * R[i, j]
            F[3 + i, 12 + j] = -dt * R[i, j]
            F[6 + i, 6 + j] = E[j, i]  # Exp(w dt)^T
            F[6 + i, 9 + j] = -dt * Jr[i, j]


@njit(cache=True)
def ins_predict(p, x, u, dt):
    """(f(x, u), F(x, u)) allocated."""
    x_next, F = np.empty(INS_N), np.empty((INS_N, INS_N))
    work = np.empty((INS_N, INS_N))
    ins_predict_into(p, x, u, dt, x_next, F, np.empty(INS_N), np.empty(INS_N), work, work.copy(), work.copy())
    return x_next, F


@njit(cache=True)
def ins_group_size(gid):
    if gid == INS_BARO or gid == INS_HEADING:
        return 1
    return 3


@njit(cache=True)
def ins_meas_into(p, gid, x, u, r, hx, Hs, R, D, want_H):
    """Groups (h, H = dh/d(error state)):
     0 gnss_position  h = p_NED                    H[:, dp] = I
     1 gnss_velocity  h = v_NED                    H[:, dv] = I
     2 baro           h = -p_D + b_baro (up)       H[0, p_D] = -1, H[0, b_baro] = 1
     3 heading        h = yaw                      H[0, dtheta] = E(roll, pitch)[2, :]
     4 attitude       h = (roll, pitch, yaw)       H[:, dtheta] = E(roll, pitch)
     5 odometry       h = R^T v (body FRD)          H[:, dv] = R^T, H[:, dtheta] = [R^T v]x
    R (3, 3) and D (3, 3, 3) are work arrays."""
    m = ins_group_size(gid)
    if want_H:
        for i in range(m):
            for j in range(INS_N):
                Hs[r + i, j] = 0.0
    if gid == INS_GNSS_POSITION or gid == INS_GNSS_VELOCITY:
        base = 0 if gid == INS_GNSS_POSITION else 3
        for i in range(3):
            hx[r + i] = x[base + i]
            if want_H:
                Hs[r + i, base + i] = 1.0
    elif gid == INS_BARO:
        hx[r] = -x[2] + x[15]
        if want_H:
            Hs[r, 2] = -1.0
            Hs[r, 15] = 1.0
    elif gid == INS_HEADING or gid == INS_ATTITUDE:
        first = 2 if gid == INS_HEADING else 0
        for i in range(first, 3):
            hx[r + i - first] = x[6 + i]
        if want_H:
            Em = D[0]
            euler_rate_matrix_into(x[6], x[7], Em, 0)
            for i in range(first, 3):
                for j in range(3):
                    Hs[r + i - first, 6 + j] = Em[i, j]
    else:  # odometry: body-frame velocity
        quad_rotation_into(x[6], x[7], x[8], R)
        b0 = R[0, 0] * x[3] + R[1, 0] * x[4] + R[2, 0] * x[5]
        b1 = R[0, 1] * x[3] + R[1, 1] * x[4] + R[2, 1] * x[5]
        b2 = R[0, 2] * x[3] + R[1, 2] * x[4] + R[2, 2] * x[5]
        hx[r] = b0
        hx[r + 1] = b1
        hx[r + 2] = b2
        if want_H:
            Sk = D[0]
            _skew_into(b0, b1, b2, Sk)
            for i in range(3):
                for j in range(3):
                    Hs[r + i, 3 + j] = R[j, i]
                    Hs[r + i, 6 + j] = Sk[i, j]


@njit(cache=True)
def ins_h(p, gid, x, u):
    out = np.empty(ins_group_size(gid))
    ins_meas_into(p, gid, x, u, 0, out, np.empty((0, 0)), np.empty((3, 3)), np.empty((3, 3, 3)), False)
    return out


@njit(cache=True)
def ins_H(p, gid, x, u):
    m = ins_group_size(gid)
    H = np.zeros((m, INS_N))
    ins_meas_into(p, gid, x, u, 0, np.empty(m), H, np.empty((3, 3)), np.empty((3, 3, 3)), True)
    return H


@njit(cache=True)
def ins_f(p, x, u, dt):
    """f(x, u): the strapdown step alone."""
    return ins_predict(p, x, u, dt)[0]


@njit(cache=True, inline="always")
def ins_step_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """predict_into of the ins model (strapdown step, error-state Jacobian)."""
    ins_predict_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn)


@njit(cache=True, inline="always")
def ins_meas_rows_into(gid, p, x, u, r, hx, Hs, R3, D3):
    """meas_into of the ins model."""
    ins_meas_into(p, gid, x, u, r, hx, Hs, R3, D3, True)


@njit(cache=True, inline="always")
def ins_boxplus(p, x, dx, out, R3, D3):
    """x (+) dx of the ins model (the attitude rotates)."""
    ins_boxplus_into(p, x, dx, out, R3, D3)


register(
    ModelKernels(
        INS_ID,
        "ins",
        predict=ins_predict,
        f_disc=ins_f,
        h_meas=ins_h,
        H_meas=ins_H,
        predict_into=ins_step_into,
        meas_into=ins_meas_rows_into,
        boxplus_into=ins_boxplus,
    )
)
follow_dependencies(__name__)
