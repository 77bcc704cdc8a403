"""Dispatch of the numba model functions on the model id, built from the registry of model kernels.

The registry is the block of imports below, one line per model: importing a model's kernels module
registers its functions (`register(ModelKernels(...))` at its end, `logscan.models.model_kernels`),
and every dispatcher here is built from `REGISTRY`. A new model is its class module, its kernels
module and one line here.

The EKF kernel calls one model's in-place functions (no allocation) through `model_predict_into`,
`model_meas_into` and `model_boxplus_into`, which numba resolves at compile time for a literal
model id, to that model's functions alone. `predict_into` and `meas_into` branch on the id at run
time to the same functions; `predict`, `f_disc`, `h_meas`, `H_meas` are the allocating versions
(simulator, numpy views of a model); their branches, one per registered model, are generated while
numba compiles them (`by_model`). An unknown id raises ValueError inside numba; `check_model_id`
catches it at the Python level first (Model creation, `run_ekf`), with a clear ModelError.

Shapes: p the model's packed parameter vector, x (n,), u (nu,), F (n, n); a group's h goes to
rows r:r+m of hx (m_total,), its H to rows r:r+m of Hs (m_total, n); kv, xs (n,) and A, J, Jn
(n, n) are the RK4 work arrays, R3 (3, 3) and D3 (3, 3, 3) the quadcopter's.
"""

from __future__ import annotations

from numba import njit, typeof, types
from numba.core.typing.typeof import Purpose
from numba.extending import overload

from logscan.errors import ModelError

# The registry, one line per model: each `<model>_kernels` import registers the kernels of that
# model (`register` at the end of the module) and re-exports its id for its class module.
from logscan.models.ins_kernels import INS_ID as INS_ID
from logscan.models.linear_kernels import DC_MOTOR_ID as DC_MOTOR_ID
from logscan.models.linear_kernels import HOVER_UAV_ID as HOVER_UAV_ID
from logscan.models.linear_kernels import LINEAR_ID as LINEAR_ID
from logscan.models.model_kernels import MODEL_IDS, REGISTRY, by_model, literal_kernel
from logscan.models.quadcopter_kernels import QUADCOPTER_ID as QUADCOPTER_ID
from logscan.models.steer_by_wire_kernels import STEER_BY_WIRE_ID as STEER_BY_WIRE_ID
from logscan.models.unicycle_kernels import UNICYCLE_ID as UNICYCLE_ID
from logscan.models.wheeled_kernels import WHEELED_ID as WHEELED_ID
from logscan.numba_cache import follow_dependencies


def check_model_id(model_id: int, model_name: str) -> None:
    """ModelError unless a model registered its kernels under ``model_id``."""
    if model_id not in REGISTRY:
        known = ", ".join(f"{i} ({MODEL_IDS[i]})" for i in sorted(MODEL_IDS))
        raise ModelError(
            f"model {model_name!r} has model_id {model_id}, which no numba kernel dispatches",
            hint=f"known model ids: {known}; a new model registers its kernels at the end of its kernels "
            "module and adds that module to the registry in logscan/models/dispatch.py",
        )


@njit(cache=True)
def predict(model_id, p, x, u, dt):
    """(f(x, u), F(x, u)) of the discrete model `model_id`."""
    return by_model("predict", 0, model_id, (p, x, u, dt))


@njit(cache=True)
def predict_into(model_id, p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """predict() without allocation: f(x, u) into x_next, F(x, u) into F (kv, xs (n,) and
    A, J, Jn (n, n) are work arrays)."""
    by_model("predict_into", 0, model_id, (p, x, u, dt, x_next, F, kv, xs, A, J, Jn))


@njit(cache=True)
def f_disc(model_id, p, x, u, dt):
    """f(x, u) of the discrete model `model_id` (no Jacobian: the simulator's truth)."""
    return by_model("f_disc", 0, model_id, (p, x, u, dt))


@njit(cache=True)
def h_meas(model_id, gid, p, x, u):
    """h(x, u) of group `gid`."""
    return by_model("h_meas", 0, model_id, (p, gid, x, u))


@njit(cache=True)
def H_meas(model_id, gid, p, x, u):
    """H = dh/dx of group `gid`."""
    return by_model("H_meas", 0, model_id, (p, gid, x, u))


@njit(cache=True)
def meas_into(model_id, gid, p, x, u, r, hx, Hs, R3, D3):
    """h_meas and H_meas without allocation: h of group gid into hx[r:r+m], H into
    Hs[r:r+m, :] (R3 (3, 3) and D3 (3, 3, 3) are the quadcopter's work arrays)."""
    by_model("meas_into", 0, model_id, (gid, p, x, u, r, hx, Hs, R3, D3))


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


def model_boxplus_into(model_id, p, x, dx, out, R3, D3):
    """out = x (+) dx of the model ``model_id`` (a compile-time constant; numba code only); R3, D3
    work arrays."""
    raise NotImplementedError("model_boxplus_into is resolved by numba at compile time")


@overload(model_predict_into, inline="always")
def _model_predict_into(model_id, p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    kernel = literal_kernel(model_id, "predict_into")
    if kernel is not None:

        def impl(model_id, p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
            kernel(p, x, u, dt, x_next, F, kv, xs, A, J, Jn)

        return impl


@overload(model_meas_into, inline="always")
def _model_meas_into(model_id, gid, p, x, u, r, hx, Hs, R3, D3):
    kernel = literal_kernel(model_id, "meas_into")
    if kernel is not None:

        def impl(model_id, gid, p, x, u, r, hx, Hs, R3, D3):
            kernel(gid, p, x, u, r, hx, Hs, R3, D3)

        return impl


@overload(model_boxplus_into, inline="always")
def _model_boxplus_into(model_id, p, x, dx, out, R3, D3):
    kernel = literal_kernel(model_id, "boxplus_into")
    if kernel is not None:

        def impl(model_id, p, x, dx, out, R3, D3):
            kernel(p, x, dx, out, R3, D3)

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
