"""Numba functions of the steer-by-wire model: front-wheel subsystem + single-track vehicle.

Shapes: p (SBW_N_PARAMS,) packed by `SteerByWire.param_vector` (layout SP_* below), x (4,)
[delta_f, delta_f_dot, beta, gamma], u (1,) [tau_eq], continuous d (4,) and A (4, 4); every
measurement group has one output: H into row r of Hs (m, 4). Discretised by `logscan.models.rk4`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from logscan.models.model_kernels import ModelKernels, additive_boxplus_into, register
from logscan.models.rk4 import rk4_f, rk4_predict, rk4_predict_into
from logscan.numba_cache import follow_dependencies

STEER_BY_WIRE_ID = 1  # its registered id (logscan.models.model_kernels)

# ---- parameter layout -------------------------------------------------------------------------
(SP_JEQ, SP_BEQ, SP_FS, SP_CF, SP_CR, SP_LF, SP_LR, SP_LC, SP_LP, SP_M, SP_IZ, SP_V, SP_VS) = range(13)
SBW_N_PARAMS = 13


@njit(cache=True)
def sbw_fA(p, x, u, d, A, want_A):
    """Jeq d2_dd + Beq d_dot + Fs tanh(d_dot/vs) + tau_e = tau_eq, with the self-aligning torque
    tau_e = Cf (lc + lp) (delta_f - beta - lf gamma / V); bicycle model for beta and gamma.
    A: the paper's section V.B Jacobian, with d tanh(d_dot/vs)/d d_dot in place of the sign's."""
    Jeq, Beq, Fs = p[SP_JEQ], p[SP_BEQ], p[SP_FS]
    Cf, Cr, lf, lr = p[SP_CF], p[SP_CR], p[SP_LF], p[SP_LR]
    lt = p[SP_LC] + p[SP_LP]
    M, Iz, V, vs = p[SP_M], p[SP_IZ], p[SP_V], p[SP_VS]
    delta, dd, beta, gamma = x[0], x[1], x[2], x[3]
    th = np.tanh(dd / vs)
    a22 = -(Cf + Cr) / (M * V)
    a23 = -1.0 + (Cr * lr - Cf * lf) / (M * V * V)
    a32 = (Cr * lr - Cf * lf) / Iz
    a33 = -(Cr * lr * lr + Cf * lf * lf) / (Iz * V)
    d[0] = dd
    tau_e = Cf * lt * (delta - beta - lf * gamma / V)
    d[1] = (u[0] - Beq * dd - Fs * th - tau_e) / Jeq
    d[2] = a22 * beta + a23 * gamma + Cf / (M * V) * delta
    d[3] = a32 * beta + a33 * gamma + Cf * lf / Iz * delta
    if not want_A:
        return
    A[:, :] = 0.0
    A[0, 1] = 1.0
    A[1, 0] = -Cf * lt / Jeq
    A[1, 1] = -(Beq + Fs * (1.0 - th * th) / vs) / Jeq
    A[1, 2] = Cf * lt / Jeq
    A[1, 3] = Cf * lt * lf / (Jeq * V)
    A[2, 0] = Cf / (M * V)
    A[2, 2] = a22
    A[2, 3] = a23
    A[3, 0] = Cf * lf / Iz
    A[3, 2] = a32
    A[3, 3] = a33


@njit(cache=True)
def sbw_H_row_into(p, gid, Hs, r):
    """Groups: 0 steering_angle (delta_f), 1 yaw_rate (gamma),
    2 lateral_accel a_y = V (beta_dot + gamma) (linear in the state): H into row r of Hs."""
    for j in range(4):
        Hs[r, j] = 0.0
    if gid == 0:
        Hs[r, 0] = 1.0
    elif gid == 1:
        Hs[r, 3] = 1.0
    else:
        Cf, Cr, lf, lr = p[SP_CF], p[SP_CR], p[SP_LF], p[SP_LR]
        M, V = p[SP_M], p[SP_V]
        Hs[r, 0] = Cf / M
        Hs[r, 2] = -(Cf + Cr) / M
        Hs[r, 3] = (Cr * lr - Cf * lf) / (M * V)


@njit(cache=True)
def sbw_H(p, gid, x, u):
    H = np.zeros((1, 4))
    sbw_H_row_into(p, gid, H, 0)
    return H


@njit(cache=True)
def sbw_h(p, gid, x, u):
    H = sbw_H(p, gid, x, u)
    return H @ x


@njit(cache=True)
def sbw_predict(p, x, u, dt):
    """(f(x, u), F(x, u)) by the generic RK4 step (allocating)."""
    return rk4_predict(STEER_BY_WIRE_ID, p, x, u, dt)


@njit(cache=True)
def sbw_f(p, x, u, dt):
    """f(x, u): the RK4 step alone (the simulator's truth)."""
    return rk4_f(STEER_BY_WIRE_ID, p, x, u, dt)


@njit(cache=True, inline="always")
def sbw_step_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """predict_into of the steer-by-wire model (generic RK4)."""
    rk4_predict_into(STEER_BY_WIRE_ID, p, x, u, dt, x_next, F, kv, xs, A, J, Jn)


@njit(cache=True, inline="always")
def sbw_meas_rows_into(gid, p, x, u, r, hx, Hs, R3, D3):
    """meas_into of the steer-by-wire model (linear outputs: hx = H x)."""
    sbw_H_row_into(p, gid, Hs, r)
    t = 0.0
    for j in range(4):
        t += Hs[r, j] * x[j]
    hx[r] = t


register(
    ModelKernels(
        STEER_BY_WIRE_ID,
        "steer_by_wire",
        predict=sbw_predict,
        f_disc=sbw_f,
        h_meas=sbw_h,
        H_meas=sbw_H,
        predict_into=sbw_step_into,
        meas_into=sbw_meas_rows_into,
        boxplus_into=additive_boxplus_into,
        fA=sbw_fA,
    )
)
follow_dependencies(__name__)
