"""The normalised state check of the encoded EKF (docs/algorithms.md section 1.2): e_x over the
standard deviation the filter predicts for it, judged per sample or summed over a trailing window,
against a fixed bound from the false-alarm budget instead of the adaptive band of eq. 4.

    g_k    = CV_k K_k                                     (1 x m_k; columns not updated are 0)
    pred_k = g_k S_k g_k^T                                the filter's variance of e_x at k
    z_k    = e_x(k) / sqrt(pred_k)                        "normalised": N(0, 1), white, on a consistent filter
    sum_k  = (z over the last W steps where z is defined) / sqrt(W)      "window_sum": N(0, 1) too
    bound  = -ndtri(alpha / 2),  alpha = rate_design / (3600 tests_per_second)    (two-sided)

The innovations of a consistent filter are white, so are the z_k, and a sum of W of them has
variance W: one bound serves every vehicle and window, and the budget sets it as it sets the NIS
test's (union bound over every test, `logscan.detectors.budget.design_rate`). A lasting mean shift
of d standard deviations moves the window sum by d sqrt(W): what e_x's per-sample adaptive band
absorbs within W samples (section 1.10), the sum accumulates.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from logscan.detectors.nis import window_sums

ROW_BLOCK = 16_384  # steps per block of the (N, n) arithmetic: temporaries of ~1.5 MB, numpy speed


def row_blocks(n_steps: int) -> list[slice]:
    """Slices of at most ROW_BLOCK steps covering range(n_steps)."""
    return [slice(start, min(start + ROW_BLOCK, n_steps)) for start in range(0, n_steps, ROW_BLOCK)]


def predicted_variance(cv_of: Callable[[slice], np.ndarray], K: np.ndarray, S: np.ndarray) -> np.ndarray:
    """pred_k = (CV_k K_k) S_k (CV_k K_k)^T per step, a block of steps at a time (K, S padded with
    NaN where a group did not update: those entries count as 0)."""
    n_steps = K.shape[0]
    pred = np.empty(n_steps)
    for rows in row_blocks(n_steps):
        g = np.einsum("kn,knm->km", cv_of(rows), np.nan_to_num(K[rows]))
        pred[rows] = np.einsum("km,kmj,kj->k", g, np.nan_to_num(S[rows]), g)
    return pred


def normalised_series(e_x: np.ndarray, defined: np.ndarray, pred: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(z, valid): z = e_x / sqrt(pred) where e_x is defined. A step whose predicted variance is not
    positive (the update did not move the check state: g = 0) carries no evidence and is not judged;
    a non-finite e_x (a diverged filter) stays NaN and judged, an exceedance."""
    with np.errstate(invalid="ignore", divide="ignore"):
        z = e_x / np.sqrt(pred)
    informative = pred > 0.0  # NaN-safe: a NaN variance is no information either
    valid = defined & (informative | ~np.isfinite(e_x))
    z[~valid] = np.nan
    return z, valid


def window_sum(z: np.ndarray, valid: np.ndarray, window: int) -> tuple[np.ndarray, np.ndarray]:
    """(sum_k, warm): the sum of z over the last ``window`` valid steps up to k, over sqrt(window),
    at each valid step (NaN elsewhere); warm where the window is full. A non-finite z makes every
    window holding it infinite (an exceedance), as in the NIS test's sums."""
    steps = np.flatnonzero(valid)
    if steps.size == z.size:  # every step judged: the sums are the series (no copy onto a NaN grid)
        sums, _, full = window_sums(z, np.ones(z.size, dtype=np.int64), window)
        return sums / np.sqrt(window), full
    out = np.full(z.size, np.nan)
    warm = np.zeros(z.size, dtype=bool)
    if steps.size:
        sums, _, full = window_sums(z[steps], np.ones(steps.size, dtype=np.int64), window)
        out[steps] = sums / np.sqrt(window)
        warm[steps[full]] = True
    return out, warm


def normal_bound(rate_design_per_hour: float, tests_per_second: float) -> float:
    """The two-sided N(0, 1) bound whose exceedances, one test per judged step, stay within
    ``rate_design_per_hour`` by the union bound: -ndtri(alpha / 2), alpha = rate / (3600 tests/s)."""
    from scipy.special import ndtri  # here: scipy.special is paid only when the check runs

    alpha = rate_design_per_hour / (3600.0 * max(tests_per_second, 1e-9))
    return float(-ndtri(min(alpha, 1.0) / 2.0))
