"""Numba functions of the packed discrete linear model (the linear and dc_motor models).

Packed p = [n, nu, G, group_start[G], Ad (n*n), Bd (n*nu), groups...], each group block
= [m, C (m*n), D (m*nu)] (`LinearBase.param_vector`); x (n,), u (nu,), F (n, n); a group's
measurements go to rows r:r+m of hx (m_total,) and Hs (m_total, n). The dc_motor and hover_uav
models pack their exactly discretised A, B, C like a linear model: the three ids run this code.
"""

from __future__ import annotations

from numba import njit

from logscan.models.model_kernels import ModelKernels, additive_boxplus_into, register
from logscan.numba_cache import follow_dependencies

# the registered ids of the models that run on these kernels (logscan.models.model_kernels)
DC_MOTOR_ID = 2
LINEAR_ID = 3
HOVER_UAV_ID = 4


@njit(cache=True)
def lin_dims(p):
    return int(p[0]), int(p[1]), int(p[2])


@njit(cache=True)
def lin_AB(p):
    n, nu, G = lin_dims(p)
    a0 = 3 + G
    Ad = p[a0 : a0 + n * n].reshape((n, n))
    Bd = p[a0 + n * n : a0 + n * n + n * nu].reshape((n, nu))
    return Ad, Bd


@njit(cache=True)
def lin_CD(p, gid):
    n, nu, G = lin_dims(p)
    s = int(p[3 + gid])
    m = int(p[s])
    C = p[s + 1 : s + 1 + m * n].reshape((m, n))
    D = p[s + 1 + m * n : s + 1 + m * n + m * nu].reshape((m, nu))
    return C, D


@njit(cache=True)
def lin_f(p, x, u):
    Ad, Bd = lin_AB(p)
    # x_k = Ad x_{k-1} + Bd u_k
    return Ad @ x + Bd @ u


@njit(cache=True)
def lin_h(p, gid, x, u):
    C, D = lin_CD(p, gid)
    # z = C x + D u
    return C @ x + D @ u


@njit(cache=True)
def lin_H(p, gid, x, u):
    C, D = lin_CD(p, gid)
    return C.copy()


@njit(cache=True)
def lin_meas_into(p, gid, x, u, r, hx, Hs):
    """z = C x + D u of group gid into hx[r:r+m], C into Hs[r:r+m, :] (no allocation)."""
    n, nu, G = lin_dims(p)
    s = int(p[3 + gid])
    m = int(p[s])
    c0 = s + 1
    d0 = c0 + m * n
    for i in range(m):
        t = 0.0
        for j in range(n):
            C_ij = p[c0 + i * n + j]
            Hs[r + i, j] = C_ij
            t += C_ij * x[j]
        for j in range(nu):
            t += p[d0 + i * nu + j] * u[j]
        hx[r + i] = t


@njit(cache=True)
def lin_predict_into(p, x, u, x_next, F):
    """x_next = Ad x + Bd u and F = Ad (no allocation)."""
    n, nu, G = lin_dims(p)
    a0 = 3 + G
    b0 = a0 + n * n
    for i in range(n):
        t = 0.0
        for j in range(n):
            A_ij = p[a0 + i * n + j]
            F[i, j] = A_ij
            t += A_ij * x[j]
        for j in range(nu):
            t += p[b0 + i * nu + j] * u[j]
        x_next[i] = t


@njit(cache=True)
def lin_predict(p, x, u, dt):
    """(f(x, u), F = Ad), allocating."""
    Ad, Bd = lin_AB(p)
    return lin_f(p, x, u), Ad.copy()


@njit(cache=True)
def lin_f_disc(p, x, u, dt):
    """f(x, u) = Ad x + Bd u (dt is packed in Ad, Bd)."""
    return lin_f(p, x, u)


@njit(cache=True, inline="always")
def lin_step_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """predict_into of the linear models (dc_motor, linear, hover_uav)."""
    lin_predict_into(p, x, u, x_next, F)


@njit(cache=True, inline="always")
def lin_meas_rows_into(gid, p, x, u, r, hx, Hs, R3, D3):
    """meas_into of the linear models."""
    lin_meas_into(p, gid, x, u, r, hx, Hs)


def linear_kernels(model_id: int, name: str) -> ModelKernels:
    """The registration of a model that packs its parameters like `LinearBase.param_vector`."""
    return ModelKernels(
        model_id,
        name,
        predict=lin_predict,
        f_disc=lin_f_disc,
        h_meas=lin_h,
        H_meas=lin_H,
        predict_into=lin_step_into,
        meas_into=lin_meas_rows_into,
        boxplus_into=additive_boxplus_into,
    )


register(
    linear_kernels(DC_MOTOR_ID, "dc_motor"),
    linear_kernels(LINEAR_ID, "linear"),
    linear_kernels(HOVER_UAV_ID, "hover_uav"),
)
follow_dependencies(__name__)
