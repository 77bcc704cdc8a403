"""The encoded EKF's coding vector inside the filter, and the predicted variance of its state check.

The encoded state check is e_x = CV_k (x_prior_k - x_post_k) (docs/algorithms.md section 1). Its
variance predicted by the update is CV_k K_k S_k K_k^T CV_k^T, and for the optimal gain
K S K^T = P H^T S^-1 H P = V^T V with V = L^-1 H P (S = L L^T), the matrix the kernel already
forms for K: so the variance is |V CV_k|^2, a few multiply-adds per step, and K and S need never be
kept or filtered again (`logscan.needs.CodedVariance` asks for it).

CV_k is the detector's (Lemma 1 with the sum bound): sigma_i = max(sqrt(P_prior_ii), floor_i),
CV_i = c_k / sigma_i, c_k = min(1, r_max / sum_i 1 / sigma_i), here in float64 from the filter's own
P_prior (the detector's from the trace's float32 diag(P): the two differ in the 7th digit, a scale).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from logscan.models.base import Model
from logscan.needs import CodedVariance
from logscan.numba_cache import follow_dependencies


@njit(cache=True, error_model="numpy", no_cpython_wrapper=True)
def coding_vector_into(P, floor, r_max, cv):
    """CV of the prior covariance P into ``cv`` (the module docstring's formula)."""
    n = cv.size
    inverse_sum = 0.0
    for i in range(n):
        sigma = np.sqrt(P[i, i])
        if not sigma >= floor[i]:  # the floor, NaN-safe like np.fmax: a NaN sigma takes the floor
            sigma = floor[i]
        cv[i] = 1.0 / sigma
        inverse_sum += cv[i]
    c = min(1.0, r_max / inverse_sum)
    for i in range(n):
        cv[i] *= c


@njit(cache=True, error_model="numpy", no_cpython_wrapper=True)
def coded_variance(V, m, n, cv):
    """CV K S K^T CV^T = |V CV|^2 (V = L^-1 H P, m x n): the predicted variance of e_x."""
    total = 0.0
    for a in range(m):
        Va = V[a]
        t = 0.0
        for i in range(n):
            t += Va[i] * cv[i]
        total += t * t
    return total


def coding_arguments(coding: CodedVariance | None, model: Model) -> tuple[np.ndarray, float]:
    """The kernel's (floor (n,), r_max) for ``coding``; (an empty floor, 0) when none is asked."""
    if coding is None:
        return np.empty(0), 0.0
    floor = float(coding.sigma_floor) * np.asarray(model.state_scale(), dtype=np.float64)
    return np.ascontiguousarray(floor), float(coding.r_max)


follow_dependencies(__name__)  # the disk cache filed by what the kernels compile (logscan.numba_cache)
