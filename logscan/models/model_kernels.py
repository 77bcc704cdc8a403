"""A model's numba functions as the dispatch sees them: the registration each `*_kernels.py` makes.

A kernels module ends with `register(ModelKernels(...))`: the model's id and registered name and
its functions, all `@njit`; `logscan.models.dispatch` imports the module (its one registry line)
and builds every dispatcher from `REGISTRY`. Signatures (p the packed parameter vector, x (n,),
u (nu,), F (n, n); a group's h goes to rows r:r+m of hx (m_total,), its H to rows r:r+m of Hs
(m_total, n); kv, xs (n,) and A, J, Jn (n, n) are RK4 work arrays, R3 (3, 3) and D3 (3, 3, 3)
rotation work arrays, free for any model to use):

    predict(p, x, u, dt) -> (x_next, F)          f_disc(p, x, u, dt) -> x_next
    h_meas(p, gid, x, u) -> h (m,)               H_meas(p, gid, x, u) -> H (m, n)
    predict_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn)        (the EKF's: no allocation)
    meas_into(gid, p, x, u, r, hx, Hs, R3, D3)                    (the EKF's: no allocation)
    boxplus_into(p, x, dx, out, R3, D3)          out = x (+) dx (`additive_boxplus_into`: x + dx;
                                                 R3, D3 work: the EKF's step loop cannot allocate)
    fA(p, x, u, d, A, want_A)                    continuous d = f_c(x, u), A = df_c/dx; only for
                                                 the shared RK4 step (`logscan.models.rk4`), else None

`by_model` and `literal_kernel` are the two ways numba code reaches them: a branch per registered
model on a run-time id, or the one model of a compile-time (literal) id.
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple

from numba import njit, types
from numba.extending import overload

from logscan.numba_cache import follow_dependencies


class ModelKernels(NamedTuple):
    """One model's registration: its id, its registered name and its numba functions."""

    model_id: int
    name: str
    predict: Any
    f_disc: Any
    h_meas: Any
    H_meas: Any
    predict_into: Any
    meas_into: Any
    boxplus_into: Any
    fA: Any = None


# model id -> its kernels, and model id -> registered name, filled by `register`
REGISTRY: dict[int, ModelKernels] = {}
MODEL_IDS: dict[int, str] = {}


def register(*kernels: ModelKernels) -> None:
    """Add models to the registry (a kernels module's last statement). An id taken by another
    model is a programming error: ValueError."""
    for entry in kernels:
        taken = MODEL_IDS.get(entry.model_id)
        if taken is not None and taken != entry.name:
            raise ValueError(f"model id {entry.model_id} of {entry.name!r} is taken by {taken!r}")
        REGISTRY[entry.model_id] = entry
        MODEL_IDS[entry.model_id] = entry.name


@njit(cache=True, inline="always")
def additive_boxplus_into(p, x, dx, out, R3, D3):
    """x (+) dx of the models whose state adds: out = x + dx."""
    for i in range(x.size):
        out[i] = x[i] + dx[i]


def literal_kernel(model_id, field: str):
    """The ``field`` function of the model whose id is the numba literal type ``model_id``; None
    when ``model_id`` is not a literal of a registered model (numba then tries the literal type,
    or reports no implementation)."""
    if isinstance(model_id, types.IntegerLiteral) and model_id.literal_value in REGISTRY:
        return getattr(REGISTRY[model_id.literal_value], field)
    return None


@functools.cache
def _tuple_call(kernel, arity: int):
    """A numba function of one tuple that calls ``kernel`` with its ``arity`` items as arguments
    (numba cannot call an inline="always" function with *args)."""
    items = ", ".join(f"args[{i}]" for i in range(arity))
    scope = {"kernel": kernel}
    exec(f"def call(args):\n    return kernel({items})\n", scope)
    return njit(inline="always")(scope["call"])


def by_model(field, index, model_id, args):
    """``field``(*args) of the registered model ``model_id``, the ``index``-th and later in id
    order tried (numba code only: call it with a string literal, 0 and a tuple)."""
    raise NotImplementedError("by_model is resolved by numba at compile time")


@overload(by_model)
def _by_model(field, index, model_id, args):
    # one branch per registered model, resolved while numba compiles the caller: branch `index`
    # tests its id and hands any other id to branch index + 1; past the last one, ValueError
    if not isinstance(field, types.StringLiteral) or not isinstance(index, types.IntegerLiteral):
        return None
    ids = sorted(REGISTRY)
    if index.literal_value >= len(ids):
        message = f"{field.literal_value}: unknown model id"

        def unknown(field, index, model_id, args):
            raise ValueError(message)

        return unknown
    known = ids[index.literal_value]
    call = _tuple_call(getattr(REGISTRY[known], field.literal_value), len(args))
    following = index.literal_value + 1

    def branch(field, index, model_id, args):
        if model_id == known:
            return call(args)
        return by_model(field, following, model_id, args)

    return branch


follow_dependencies(__name__)  # the disk cache filed by what the kernels compile (logscan.numba_cache)
