"""Numba functions of the `wheeled` model (a planar wheeled ground robot whose wheels slip).

Shapes: p (WHEELED_N_PARAMS,) = [tau_g] packed by `Wheeled.param_vector`, x (8,) [x, y, psi, b_w, s,
g_x, g_y, c], u (2,) [v, w], F (8, 8); `position` (gid 0) measures x + g_x, y + g_y (the receiver's
slowly wandering error g), `heading` (gid 1) psi, `wheel_yaw_rate` (gid 2) c (w - b_w): the yaw rate
the wheels imply, c times the true one (a skid-steer's turning slip). h into hx[r:r+m], H into
Hs[r:r+m, :].
"""

from __future__ import annotations

import numpy as np
from numba import njit

from logscan.models.model_kernels import ModelKernels, additive_boxplus_into, register
from logscan.numba_cache import follow_dependencies

WHEELED_ID = 7  # its registered id (logscan.models.model_kernels)
WHEELED_N_PARAMS = 1
WHEELED_N = 8


@njit(cache=True)
def wheeled_predict_into(p, x, u, dt, x_next, F):
    """Euler step and its Jacobian F = df/dx; no allocation::

    x_{k+1}   = x_k + s v cos(psi) dt        (v: the wheels' forward speed, s: its scale)
    y_{k+1}   = y_k + s v sin(psi) dt
    psi_{k+1} = psi_k + (w - b_w) dt         (w: the yaw rate input, b_w: its bias)
    b_w, s, c constant (random walks through Q)
    g_{k+1}   = exp(-dt / tau_g) g_k         (the GNSS error: first-order Gauss-Markov, p[0] = tau_g)
    """
    c = np.cos(x[2])
    sn = np.sin(x[2])
    v = u[0]
    scale = x[4]
    x_next[0] = x[0] + scale * v * c * dt
    x_next[1] = x[1] + scale * v * sn * dt
    x_next[2] = x[2] + (u[1] - x[3]) * dt
    x_next[3] = x[3]
    x_next[4] = x[4]
    decay = np.exp(-dt / p[0])
    x_next[5] = decay * x[5]
    x_next[6] = decay * x[6]
    x_next[7] = x[7]
    for i in range(WHEELED_N):
        for j in range(WHEELED_N):
            F[i, j] = 1.0 if i == j else 0.0
    F[0, 2] = -scale * v * sn * dt  # dx/dpsi
    F[0, 4] = v * c * dt  # dx/ds
    F[1, 2] = scale * v * c * dt  # dy/dpsi
    F[1, 4] = v * sn * dt  # dy/ds
    F[2, 3] = -dt  # dpsi/db_w
    F[5, 5] = decay
    F[6, 6] = decay


@njit(cache=True)
def wheeled_predict(p, x, u, dt):
    """(f(x, u), F(x, u)), allocating."""
    x_next = np.empty(WHEELED_N)
    F = np.empty((WHEELED_N, WHEELED_N))
    wheeled_predict_into(p, x, u, dt, x_next, F)
    return x_next, F


@njit(cache=True)
def _group_states(gid):
    """The rows of a group and the states they start from: position (0) x and y, heading (1) psi,
    wheel_yaw_rate (2) one row."""
    if gid == 1:
        return 2, 3
    if gid == 2:
        return 7, 8
    return 0, 2


@njit(cache=True)
def wheeled_meas_into(p, gid, x, u, r, hx, Hs):
    """position: z = [x + g_x, y + g_y]; heading: z = [psi] (the EKF wraps its innovation);
    wheel_yaw_rate: z = c (w - b_w). Into hx[r:r+m], H into Hs[r:r+m, :]."""
    first, stop = _group_states(gid)
    if gid == 2:
        for j in range(WHEELED_N):
            Hs[r, j] = 0.0
        rate = u[1] - x[3]
        hx[r] = x[7] * rate
        Hs[r, 3] = -x[7]  # dh/db_w
        Hs[r, 7] = rate  # dh/dc
        return
    for i in range(stop - first):
        hx[r + i] = x[first + i]
        for j in range(WHEELED_N):
            Hs[r + i, j] = 1.0 if j == first + i else 0.0
        if gid == 0:  # the receiver's error adds to the position it reports
            hx[r + i] += x[5 + i]
            Hs[r + i, 5 + i] = 1.0


@njit(cache=True)
def _measure(p, gid, x, u):
    """(h, H) of one group, freshly allocated."""
    first, stop = _group_states(gid)
    hx = np.empty(stop - first)
    Hs = np.empty((stop - first, WHEELED_N))
    wheeled_meas_into(p, gid, x, u, 0, hx, Hs)
    return hx, Hs


@njit(cache=True)
def wheeled_h(p, gid, x, u):
    return _measure(p, gid, x, u)[0]


@njit(cache=True)
def wheeled_H(p, gid, x, u):
    return _measure(p, gid, x, u)[1]


@njit(cache=True)
def wheeled_f(p, x, u, dt):
    """f(x, u): the Euler step alone."""
    return wheeled_predict(p, x, u, dt)[0]


@njit(cache=True, inline="always")
def wheeled_step_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """predict_into of the wheeled model (Euler step)."""
    wheeled_predict_into(p, x, u, dt, x_next, F)


@njit(cache=True, inline="always")
def wheeled_meas_rows_into(gid, p, x, u, r, hx, Hs, R3, D3):
    """meas_into of the wheeled model."""
    wheeled_meas_into(p, gid, x, u, r, hx, Hs)


register(
    ModelKernels(
        WHEELED_ID,
        "wheeled",
        predict=wheeled_predict,
        f_disc=wheeled_f,
        h_meas=wheeled_h,
        H_meas=wheeled_H,
        predict_into=wheeled_step_into,
        meas_into=wheeled_meas_rows_into,
        boxplus_into=additive_boxplus_into,
    )
)
follow_dependencies(__name__)
