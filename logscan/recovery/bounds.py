"""Error bounds of a recovered estimate: the k-sigma bound and T_max, and the paper's worst case.

Reported bound (the specification's choice, it covered 99.8-100 % of samples in the prototype):
    bound_k = k_sigma * sqrt(diag P_R,k)
with P_R the covariance propagated through the recovery (the re-filter's posterior, or the
roll-forward's P_R = F P_R F^T + Q). T_max of a state with allowed error E: the first time the bound
exceeds E, counted from the anomaly's first alarmed time.

Worst case, the checkpointing paper's Proposition 5.1 (with the omega_{k+1} term its proof in A.2
carries), j steps after the checkpoint:
    B_j = Abar^j eps_delta + sum_{i=0..j} Abar^i eps_w + Phibar,      B_0 = eps_delta
 - Abar: the elementwise maximum of |F_k| (discrete Jacobians df/dx) over the recovered span, F_k
   evaluated along the recovered trajectory (|prod F| <= prod |F_k| <= Abar^j elementwise);
 - eps_delta: the estimation error bound at the checkpoint, k_sigma * sqrt(diag P_post(k1)) (the
   paper's assumption (14) made concrete with the filter's own covariance);
 - eps_w: the process noise bound, k_sigma * sqrt(diag Q);
 - Phibar: taken as 0 (simplification: the accumulated second-order Taylor terms are not bounded;
   the bound is exact for linear models, the paper's Corollary 5.2, and first order otherwise).
It grows like Abar^j and is vacuous in practice (the specification measured 17 m at the first
alarmed sample, ~250 m at the end); it is reported beside the k-sigma bound, labelled worst case.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from logscan.models.dispatch import call_literal
from logscan.recovery.kernels import jacobian_bound


def k_sigma_bound(P: np.ndarray, k_sigma: float) -> np.ndarray:
    """(J, n) k_sigma * sqrt(diag P) of (J, n, n) covariances (negative rounding clipped to 0)."""
    return k_sigma * np.sqrt(np.maximum(np.einsum("kii->ki", P), 0.0))


def t_max(t: np.ndarray, bound: np.ndarray, allowed: Mapping[int, float], t_detect: float) -> dict[int, float | None]:
    """State index -> first time (minus t_detect) where bound > E; None when it never does in ``t``."""
    out: dict[int, float | None] = {}
    for i, E in allowed.items():
        over = np.flatnonzero(bound[:, i] > E)
        out[i] = float(t[over[0]] - t_detect) if over.size else None
    return out


def matrix_powers(A: np.ndarray, J: int) -> np.ndarray:
    """(J, n, n) A^0 .. A^(J-1), by doubling: log2(J) batched products, no loop over steps."""
    n = A.shape[0]
    powers = np.eye(n)[None].repeat(max(J, 1), axis=0)
    with np.errstate(over="ignore", invalid="ignore"):
        have = 1
        while have < J:
            take = min(have, J - have)
            # A^(have + i) = A^have A^i,  A^have = A^(have - 1) A
            powers[have : have + take] = (powers[have - 1] @ A) @ powers[:take]
            have += take
    return powers[:J]


def proposition_51(Abar: np.ndarray, eps_delta: np.ndarray, eps_w: np.ndarray, J: int) -> np.ndarray:
    """(J, n) B_j = Abar^j eps_delta + sum_{i=0..j} Abar^i eps_w (B_0 = eps_delta); inf once the
    powers overflow."""
    if J == 0:
        return np.empty((0, eps_delta.size))
    powers = matrix_powers(np.asarray(Abar, dtype=np.float64), J)
    with np.errstate(over="ignore", invalid="ignore"):
        noise = np.cumsum(powers @ eps_w, axis=0)  # sum_{i=0..j} Abar^i eps_w
        B = powers @ eps_delta + noise
    B[0] = eps_delta
    return np.where(np.isnan(B), np.inf, B)  # inf * 0 in an overflowed power: unbounded


def worst_case(model, dt: float, x: np.ndarray, u: np.ndarray, P_k1: np.ndarray, Q: np.ndarray, k_sigma: float):
    """(J, n) Proposition 5.1 along the recovered trajectory ``x`` (J, n) with inputs ``u``
    (J, nu, non-finite rows already held), from the checkpoint covariance ``P_k1``."""
    p = np.ascontiguousarray(model.param_vector(dt), dtype=np.float64)
    x = np.ascontiguousarray(x, dtype=np.float64)
    Abar = call_literal(jacobian_bound, int(model.model_id), p, x, np.ascontiguousarray(u, dtype=np.float64), float(dt))
    eps_delta = k_sigma * np.sqrt(np.maximum(np.diag(P_k1), 0.0))
    eps_w = k_sigma * np.sqrt(np.maximum(np.diag(Q), 0.0))
    return proposition_51(Abar, eps_delta, eps_w, x.shape[0])
