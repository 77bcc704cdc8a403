"""Whether the UBIKF can filter an interval model: the states of its undetectable modes.

The UBIKF (logscan.filters.ubikf) refuses an interval model whose unstable or marginal modes no
measurement sees (its covariance bound would grow without limit); this module finds those modes.
"""

from __future__ import annotations

import numpy as np

from logscan.errors import ModelError
from logscan.models.interval_model import IntervalModel


def unobservable_unstable_states(model: IntervalModel, rtol: float = 1e-9, margin: float = 1e-6) -> list[str]:
    """The states in the undetectable subspace of (A_m, C_m): the modes with |lambda| >= 1 - margin
    of the unobservable subspace (the largest A_m-invariant subspace in null(C_m), by orthogonal
    deflation with rank decisions relative to |A_m|, |C_m|)."""
    A, C = model.A_m, model.C_m
    n = A.shape[0]
    scale_A = max(np.linalg.norm(A, 2), 1.0)
    scale_C = max(np.linalg.norm(C, 2) if C.size else 0.0, np.finfo(float).tiny)

    def null_space(M, scale):
        if M.shape[0] == 0:
            return np.eye(M.shape[1])
        _, s, Vt = np.linalg.svd(M)
        rank = int(np.sum(s > rtol * scale))
        return Vt[rank:].T

    V = null_space(C, scale_C)  # null(C)
    while V.shape[1]:
        # {x in span V: A x in span V}
        N = null_space(A @ V - V @ (V.T @ A @ V), scale_A)
        if N.shape[1] == V.shape[1]:
            break
        V = V @ N  # orthonormal columns still
    if not V.shape[1]:
        return []
    import scipy.linalg  # here: only an interval model with unobservable modes needs it (0.25 s to import)

    _, Zs, sdim = scipy.linalg.schur(V.T @ A @ V, output="complex", sort=lambda lam: abs(lam) >= 1.0 - margin)
    if sdim == 0:
        return []
    U = np.abs(V @ Zs[:, :sdim])
    weight = np.sqrt(np.sum(U**2, axis=1))
    return [model.state_names[i] for i in range(n) if weight[i] > 1e-6]


def check_detectable(model: IntervalModel) -> None:
    """ModelError naming the states whose unstable or marginal modes no measurement sees."""
    states = unobservable_unstable_states(model)
    if states:
        raise ModelError(
            f"the interval model is not detectable: (A_m, C_m) cannot observe {', '.join(states)}",
            hint="add a measurement group that observes these states, or make their dynamics stable",
        )
