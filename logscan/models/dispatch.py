"""Dispatch of the numba model functions on the model id: one branch per known id, raise on others.

The EKF kernel calls one model's two in-place functions (`IN_PLACE[model_id]`: no allocation)
through `model_predict_into` / `model_meas_into`, which numba resolves at compile time for a
literal model id; `predict_into` and `meas_into` branch on the id at run time to the same
functions; `predict`, `f_disc`, `h_meas`, `H_meas` are the allocating versions (simulator, numpy
views of a model). Each model's kernel module declares its id; `MODEL_IDS` lists them. An unknown
id raises ValueError inside numba; `check_model_id` catches it at the Python level first (Model
creation, `run_ekf`), with a clear ModelError.

Shapes: p the model's packed parameter vector, x (n,), u (nu,), F (n, n); a group's h goes to
rows r:r+m of hx (m_total,), its H to rows r:r+m of Hs (m_total, n); kv, xs (n,) and A, J, Jn
(n, n) are the RK4 work arrays, R3 (3, 3) and D3 (3, 3, 3) the quadcopter's.
"""

from __future__ import annotations

from numba import njit, typeof, types
from numba.core.typing.typeof import Purpose
from numba.extending import overload

from logscan.errors import ModelError
from logscan.models.ins_kernels import (
    INS_ID,
    ins_boxplus_into,
    ins_H,
    ins_h,
    ins_meas_into,
    ins_predict,
    ins_predict_into,
)
from logscan.models.linear_kernels import (
    DC_MOTOR_ID,
    LINEAR_ID,
    lin_AB,
    lin_f,
    lin_H,
    lin_h,
    lin_meas_into,
    lin_predict_into,
)
from logscan.models.quadcopter_kernels import (
    QUADCOPTER_ID,
    quad_H,
    quad_h,
    quad_meas_into,
    quad_rk4_predict_into,
)
from logscan.models.rk4 import rk4_f, rk4_predict, rk4_predict_into
from logscan.models.steer_by_wire_kernels import STEER_BY_WIRE_ID, sbw_H, sbw_h, sbw_H_row_into
from logscan.models.unicycle_kernels import UNICYCLE_ID, uni_H, uni_h, uni_meas_into, uni_predict, uni_predict_into
from logscan.models.wheeled_kernels import (
    WHEELED_ID,
    wheeled_H,
    wheeled_h,
    wheeled_meas_into,
    wheeled_predict,
    wheeled_predict_into,
)
from logscan.numba_cache import follow_dependencies

# the hover UAV (logscan.models.hover_uav) packs its exactly discretised A, B, C like a linear
# model and runs the linear kernels under an id of its own
HOVER_UAV_ID = 4

MODEL_IDS = {
    QUADCOPTER_ID: "quadcopter",
    STEER_BY_WIRE_ID: "steer_by_wire",
    DC_MOTOR_ID: "dc_motor",
    LINEAR_ID: "linear",
    HOVER_UAV_ID: "hover_uav",
    INS_ID: "ins",
    UNICYCLE_ID: "unicycle",
    WHEELED_ID: "wheeled",
}


def check_model_id(model_id: int, model_name: str) -> None:
    """ModelError unless every dispatcher has a branch for ``model_id``."""
    if model_id not in MODEL_IDS:
        known = ", ".join(f"{i} ({name})" for i, name in MODEL_IDS.items())
        raise ModelError(
            f"model {model_name!r} has model_id {model_id}, which no numba kernel dispatches",
            hint=f"known model ids: {known}; a new model adds a branch to every dispatcher in "
            "logscan/models/dispatch.py",
        )


@njit(cache=True)
def predict(model_id, p, x, u, dt):
    """(f(x, u), F(x, u)) of the discrete model `model_id`."""
    if model_id == DC_MOTOR_ID or model_id == LINEAR_ID or model_id == HOVER_UAV_ID:
        Ad, Bd = lin_AB(p)
        return lin_f(p, x, u), Ad.copy()
    if model_id == QUADCOPTER_ID or model_id == STEER_BY_WIRE_ID:
        return rk4_predict(model_id, p, x, u, dt)
    if model_id == INS_ID:
        return ins_predict(p, x, u, dt)
    if model_id == UNICYCLE_ID:
        return uni_predict(p, x, u, dt)
    if model_id == WHEELED_ID:
        return wheeled_predict(p, x, u, dt)
    raise ValueError("predict: unknown model id")


@njit(cache=True, inline="always")
def lin_step_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """predict_into of the linear models (dc_motor, linear, hover_uav)."""
    lin_predict_into(p, x, u, x_next, F)


@njit(cache=True, inline="always")
def quad_step_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """predict_into of the quadcopter (RK4 on the 3x3 blocks of its Jacobian)."""
    quad_rk4_predict_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn)


@njit(cache=True, inline="always")
def sbw_step_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """predict_into of the steer-by-wire model (generic RK4)."""
    rk4_predict_into(STEER_BY_WIRE_ID, p, x, u, dt, x_next, F, kv, xs, A, J, Jn)


@njit(cache=True, inline="always")
def ins_step_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """predict_into of the ins model (strapdown step, error-state Jacobian)."""
    ins_predict_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn)


@njit(cache=True, inline="always")
def uni_step_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """predict_into of the unicycle (Euler step)."""
    uni_predict_into(p, x, u, dt, x_next, F)


@njit(cache=True, inline="always")
def wheeled_step_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """predict_into of the wheeled model (Euler step)."""
    wheeled_predict_into(p, x, u, dt, x_next, F)


@njit(cache=True)
def predict_into(model_id, p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """predict() without allocation: f(x, u) into x_next, F(x, u) into F (kv, xs (n,) and
    A, J, Jn (n, n) are work arrays)."""
    if model_id == DC_MOTOR_ID or model_id == LINEAR_ID or model_id == HOVER_UAV_ID:
        lin_step_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn)
    elif model_id == QUADCOPTER_ID:
        quad_step_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn)
    elif model_id == STEER_BY_WIRE_ID:
        sbw_step_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn)
    elif model_id == INS_ID:
        ins_step_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn)
    elif model_id == UNICYCLE_ID:
        uni_step_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn)
    elif model_id == WHEELED_ID:
        wheeled_step_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn)
    else:
        raise ValueError("predict_into: unknown model id")


@njit(cache=True)
def f_disc(model_id, p, x, u, dt):
    """f(x, u) of the discrete model `model_id` (no Jacobian: the simulator's truth)."""
    if model_id == DC_MOTOR_ID or model_id == LINEAR_ID or model_id == HOVER_UAV_ID:
        return lin_f(p, x, u)
    if model_id == QUADCOPTER_ID or model_id == STEER_BY_WIRE_ID:
        return rk4_f(model_id, p, x, u, dt)
    if model_id == INS_ID:
        return ins_predict(p, x, u, dt)[0]
    if model_id == UNICYCLE_ID:
        return uni_predict(p, x, u, dt)[0]
    if model_id == WHEELED_ID:
        return wheeled_predict(p, x, u, dt)[0]
    raise ValueError("f_disc: unknown model id")


@njit(cache=True)
def h_meas(model_id, gid, p, x, u):
    """h(x, u) of group `gid`."""
    if model_id == QUADCOPTER_ID:
        return quad_h(p, gid, x, u)
    if model_id == STEER_BY_WIRE_ID:
        return sbw_h(p, gid, x, u)
    if model_id == DC_MOTOR_ID or model_id == LINEAR_ID or model_id == HOVER_UAV_ID:
        return lin_h(p, gid, x, u)
    if model_id == INS_ID:
        return ins_h(p, gid, x, u)
    if model_id == UNICYCLE_ID:
        return uni_h(p, gid, x, u)
    if model_id == WHEELED_ID:
        return wheeled_h(p, gid, x, u)
    raise ValueError("h_meas: unknown model id")


@njit(cache=True)
def H_meas(model_id, gid, p, x, u):
    """H = dh/dx of group `gid`."""
    if model_id == QUADCOPTER_ID:
        return quad_H(p, gid, x, u)
    if model_id == STEER_BY_WIRE_ID:
        return sbw_H(p, gid, x, u)
    if model_id == DC_MOTOR_ID or model_id == LINEAR_ID or model_id == HOVER_UAV_ID:
        return lin_H(p, gid, x, u)
    if model_id == INS_ID:
        return ins_H(p, gid, x, u)
    if model_id == UNICYCLE_ID:
        return uni_H(p, gid, x, u)
    if model_id == WHEELED_ID:
        return wheeled_H(p, gid, x, u)
    raise ValueError("H_meas: unknown model id")


@njit(cache=True, inline="always")
def lin_meas_rows_into(gid, p, x, u, r, hx, Hs, R3, D3):
    """meas_into of the linear models."""
    lin_meas_into(p, gid, x, u, r, hx, Hs)


@njit(cache=True, inline="always")
def quad_meas_rows_into(gid, p, x, u, r, hx, Hs, R3, D3):
    """meas_into of the quadcopter."""
    quad_meas_into(p, gid, x, u, r, hx, Hs, R3, D3, True)


@njit(cache=True, inline="always")
def sbw_meas_rows_into(gid, p, x, u, r, hx, Hs, R3, D3):
    """meas_into of the steer-by-wire model (linear outputs: hx = H x)."""
    sbw_H_row_into(p, gid, Hs, r)
    t = 0.0
    for j in range(4):
        t += Hs[r, j] * x[j]
    hx[r] = t


@njit(cache=True, inline="always")
def ins_meas_rows_into(gid, p, x, u, r, hx, Hs, R3, D3):
    """meas_into of the ins model."""
    ins_meas_into(p, gid, x, u, r, hx, Hs, R3, D3, True)


@njit(cache=True, inline="always")
def uni_meas_rows_into(gid, p, x, u, r, hx, Hs, R3, D3):
    """meas_into of the unicycle."""
    uni_meas_into(p, gid, x, u, r, hx, Hs)


@njit(cache=True, inline="always")
def wheeled_meas_rows_into(gid, p, x, u, r, hx, Hs, R3, D3):
    """meas_into of the wheeled model."""
    wheeled_meas_into(p, gid, x, u, r, hx, Hs)


@njit(cache=True, inline="always")
def additive_boxplus_into(p, x, dx, out):
    """x (+) dx of the models whose state adds: out = x + dx."""
    for i in range(x.size):
        out[i] = x[i] + dx[i]


@njit(cache=True, inline="always")
def ins_boxplus(p, x, dx, out):
    """x (+) dx of the ins model (the attitude rotates)."""
    ins_boxplus_into(p, x, dx, out)


@njit(cache=True)
def meas_into(model_id, gid, p, x, u, r, hx, Hs, R3, D3):
    """h_meas and H_meas without allocation: h of group gid into hx[r:r+m], H into
    Hs[r:r+m, :] (R3 (3, 3) and D3 (3, 3, 3) are the quadcopter's work arrays)."""
    if model_id == QUADCOPTER_ID:
        quad_meas_rows_into(gid, p, x, u, r, hx, Hs, R3, D3)
    elif model_id == STEER_BY_WIRE_ID:
        sbw_meas_rows_into(gid, p, x, u, r, hx, Hs, R3, D3)
    elif model_id == DC_MOTOR_ID or model_id == LINEAR_ID or model_id == HOVER_UAV_ID:
        lin_meas_rows_into(gid, p, x, u, r, hx, Hs, R3, D3)
    elif model_id == INS_ID:
        ins_meas_rows_into(gid, p, x, u, r, hx, Hs, R3, D3)
    elif model_id == UNICYCLE_ID:
        uni_meas_rows_into(gid, p, x, u, r, hx, Hs, R3, D3)
    elif model_id == WHEELED_ID:
        wheeled_meas_rows_into(gid, p, x, u, r, hx, Hs, R3, D3)
    else:
        raise ValueError("meas_into: unknown model id")


# model id -> (predict_into, meas_into, boxplus_into) of that model alone, without the model_id
# argument
IN_PLACE = {
    QUADCOPTER_ID: (quad_step_into, quad_meas_rows_into, additive_boxplus_into),
    STEER_BY_WIRE_ID: (sbw_step_into, sbw_meas_rows_into, additive_boxplus_into),
    DC_MOTOR_ID: (lin_step_into, lin_meas_rows_into, additive_boxplus_into),
    LINEAR_ID: (lin_step_into, lin_meas_rows_into, additive_boxplus_into),
    HOVER_UAV_ID: (lin_step_into, lin_meas_rows_into, additive_boxplus_into),
    INS_ID: (ins_step_into, ins_meas_rows_into, ins_boxplus),
    UNICYCLE_ID: (uni_step_into, uni_meas_rows_into, additive_boxplus_into),
    WHEELED_ID: (wheeled_step_into, wheeled_meas_rows_into, additive_boxplus_into),
}


# The EKF kernel's calls: resolved while numba compiles the kernel for a literal model id
# (`numba.literally(model_id)` there), to that model's function alone. The kernel is then compiled
# and cached once per model, only for the models a run uses, instead of every model's dynamics
# in one kernel (a third of its cold compile).
def model_predict_into(model_id, p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """predict_into of the model ``model_id`` (a compile-time constant; numba code only)."""
    raise NotImplementedError("model_predict_into is resolved by numba at compile time")


def model_meas_into(model_id, gid, p, x, u, r, hx, Hs, R3, D3):
    """meas_into of the model ``model_id`` (a compile-time constant; numba code only)."""
    raise NotImplementedError("model_meas_into is resolved by numba at compile time")


def model_boxplus_into(model_id, p, x, dx, out):
    """out = x (+) dx of the model ``model_id`` (a compile-time constant; numba code only)."""
    raise NotImplementedError("model_boxplus_into is resolved by numba at compile time")


def _literal_kernel(model_id, which: int):
    if isinstance(model_id, types.IntegerLiteral) and model_id.literal_value in IN_PLACE:
        return IN_PLACE[model_id.literal_value][which]
    return None  # numba then tries the literal type, or reports no implementation


@overload(model_predict_into, inline="always")
def _model_predict_into(model_id, p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    kernel = _literal_kernel(model_id, 0)
    if kernel is not None:

        def impl(model_id, p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
            kernel(p, x, u, dt, x_next, F, kv, xs, A, J, Jn)

        return impl


@overload(model_meas_into, inline="always")
def _model_meas_into(model_id, gid, p, x, u, r, hx, Hs, R3, D3):
    kernel = _literal_kernel(model_id, 1)
    if kernel is not None:

        def impl(model_id, gid, p, x, u, r, hx, Hs, R3, D3):
            kernel(gid, p, x, u, r, hx, Hs, R3, D3)

        return impl


@overload(model_boxplus_into, inline="always")
def _model_boxplus_into(model_id, p, x, dx, out):
    kernel = _literal_kernel(model_id, 2)
    if kernel is not None:

        def impl(model_id, p, x, dx, out):
            kernel(p, x, dx, out)

        return impl


def compiled_for_model(kernel, args: tuple):
    """``kernel``'s compiled entry point for ``args``, its first argument (the model id) as a literal.

    A kernel that calls `numba.literally(model_id)` is one specialisation per model, but calling its
    dispatcher with a plain int re-types the whole kernel (~0.15 s) on every call before it switches
    to the literal; compiling (or loading from the cache) the literal signature skips that."""
    signature = (types.literal(int(args[0])), *(typeof(a, Purpose.argument) for a in args[1:]))
    return kernel.compile(signature)


def call_literal(kernel, *args):
    """kernel(*args) compiled for the literal model id args[0] (`compiled_for_model`)."""
    return compiled_for_model(kernel, args)(*args)


follow_dependencies(__name__)
