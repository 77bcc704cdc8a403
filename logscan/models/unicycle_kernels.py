"""Numba functions of the unicycle (the checkpointing / roll-forward-recovery paper's ground robot,
outer loop).

Shapes: p (UNI_N_PARAMS,) packed by `Unicycle.param_vector` (no entry is read: the step needs only
dt), x (3,) [x, y, theta], u (2,) [v, w], F (3, 3); the groups measure states directly: `mocap`
(gid 0) all three, `position` (gid 1) x and y, `heading` (gid 2) theta: h into hx[r:r+m], H into
Hs[r:r+m, :].
"""

from __future__ import annotations

import numpy as np
from numba import njit

from logscan.models.model_kernels import ModelKernels, additive_boxplus_into, register
from logscan.numba_cache import follow_dependencies

UNICYCLE_ID = 6  # its registered id (logscan.models.model_kernels)
UNI_N_PARAMS = 1


@njit(cache=True)
def uni_predict_into(p, x, u, dt, x_next, F):
    """Euler step of the paper's eq. 23 (with the "x_k +" its print omits) and its Jacobian
    (eq. 36: F = I + A dt); no allocation."""
    c = np.cos(x[2])
    s = np.sin(x[2])
    v = u[0]
    # x_{k+1} = x_k + [v cos th, v sin th, w] dt
    x_next[0] = x[0] + v * c * dt
    x_next[1] = x[1] + v * s * dt
    x_next[2] = x[2] + u[1] * dt
    for i in range(3):
        for j in range(3):
            F[i, j] = 1.0 if i == j else 0.0
    # dx/dth = -v sin th dt, dy/dth = v cos th dt
    F[0, 2] = -v * s * dt
    F[1, 2] = v * c * dt


@njit(cache=True)
def uni_predict(p, x, u, dt):
    """(f(x, u), F(x, u)), allocating."""
    x_next = np.empty(3)
    F = np.empty((3, 3))
    uni_predict_into(p, x, u, dt, x_next, F)
    return x_next, F


@njit(cache=True)
def _group_states(gid):
    """The states a group reads directly: mocap (0) all three, position (1) x and y, heading (2) theta."""
    if gid == 1:
        return 0, 2
    if gid == 2:
        return 2, 3
    return 0, 3


@njit(cache=True)
def uni_meas_into(p, gid, x, u, r, hx, Hs):
    """mocap: z = [x, y, theta] (eq. 24; the EKF wraps theta's innovation); position: [x, y];
    heading: [theta]. Into hx[r:r+m], H (rows of I) into Hs[r:r+m, :]."""
    first, stop = _group_states(gid)
    for i in range(stop - first):
        hx[r + i] = x[first + i]
        for j in range(3):
            Hs[r + i, j] = 1.0 if j == first + i else 0.0


@njit(cache=True)
def _measure(p, gid, x, u):
    """(h, H) of one group, freshly allocated."""
    first, stop = _group_states(gid)
    hx = np.empty(stop - first)
    Hs = np.empty((stop - first, 3))
    uni_meas_into(p, gid, x, u, 0, hx, Hs)
    return hx, Hs


@njit(cache=True)
def uni_h(p, gid, x, u):
    return _measure(p, gid, x, u)[0]


@njit(cache=True)
def uni_H(p, gid, x, u):
    return _measure(p, gid, x, u)[1]


@njit(cache=True)
def uni_f(p, x, u, dt):
    """f(x, u): the Euler step alone."""
    return uni_predict(p, x, u, dt)[0]


@njit(cache=True, inline="always")
def uni_step_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """predict_into of the unicycle (Euler step)."""
    uni_predict_into(p, x, u, dt, x_next, F)


@njit(cache=True, inline="always")
def uni_meas_rows_into(gid, p, x, u, r, hx, Hs, R3, D3):
    """meas_into of the unicycle."""
    uni_meas_into(p, gid, x, u, r, hx, Hs)


register(
    ModelKernels(
        UNICYCLE_ID,
        "unicycle",
        predict=uni_predict,
        f_disc=uni_f,
        h_meas=uni_h,
        H_meas=uni_H,
        predict_into=uni_step_into,
        meas_into=uni_meas_rows_into,
        boxplus_into=additive_boxplus_into,
    )
)
follow_dependencies(__name__)
