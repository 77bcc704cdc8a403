"""Adaptive mu +- rho*s thresholds over a trailing window of samples that did not exceed their own band.

ALGORITHMS.md section 1, eq. 4 of the encoded-EKF paper: the band at step k is the exact mean and
standard deviation of the last W accepted samples before k. A sample that exceeds its band (or is
non-finite) never enters the window, so a fault cannot widen its own threshold. Sums are kept
incrementally but recomputed from the ring buffer every W insertions, so one huge sample leaving
the window cannot leave round-off behind (naive running sums produced thousands of spurious
exceedances in the prototype).
"""

from __future__ import annotations

import numpy as np
from numba import njit

# Ring-buffer bookkeeping, kept in one float array so the helpers stay plain njit functions.
_COUNT, _HEAD, _INSERTED, _SUM, _SUM_SQ = 0, 1, 2, 3, 4


@njit(cache=True)
def _ring_push(ring, state, value):
    """Append ``value`` to the window, dropping the oldest when full; exact sums every W pushes."""
    window = ring.shape[0]
    count = int(state[_COUNT])
    head = int(state[_HEAD])
    if count == window:
        old = ring[head]
        state[_SUM] -= old
        state[_SUM_SQ] -= old * old
    else:
        count += 1
    ring[head] = value
    state[_SUM] += value
    state[_SUM_SQ] += value * value
    state[_HEAD] = (head + 1) % window
    state[_COUNT] = count
    state[_INSERTED] += 1
    if state[_INSERTED] >= window:
        total = 0.0
        total_sq = 0.0
        for i in range(count):
            total += ring[i]
            total_sq += ring[i] * ring[i]
        state[_SUM] = total
        state[_SUM_SQ] = total_sq
        state[_INSERTED] = 0


@njit(cache=True)
def _ring_moments(state, window):
    """Mean and population variance of a full window: mu = S1/W, s^2 = S2/W - mu^2 (clipped at 0)."""
    m = state[_SUM] / window
    var = state[_SUM_SQ] / window - m * m
    return m, (var if var > 0.0 else 0.0)


@njit(cache=True)
def adaptive_band(e, defined, window, rho):
    """Band of ``e`` over a trailing window of accepted samples.

    e:       (N,) statistic (NaN allowed: counts as an exceedance where defined and warm).
    defined: (N,) bool, steps where the statistic exists (e.g. steps with a measurement update).
    Returns (mu, s, lower, upper, exceed, warm):
      mu, s          window mean and standard deviation before each step (NaN where undefined),
      lower, upper   mu -+ rho*s,
      exceed         (N,) bool, defined and outside the band (never during warm-up),
      warm           (N,) bool, True once the window holds W samples (alarms allowed).
    """
    n = e.shape[0]
    mu = np.full(n, np.nan)
    s = np.full(n, np.nan)
    lower = np.full(n, np.nan)
    upper = np.full(n, np.nan)
    exceed = np.zeros(n, dtype=np.bool_)
    warm = np.zeros(n, dtype=np.bool_)
    ring = np.zeros(window)
    state = np.zeros(5)
    for k in range(n):
        if not defined[k]:
            continue
        value = e[k]
        if state[_COUNT] == window:
            m, var = _ring_moments(state, window)
            sd = np.sqrt(var)
            mu[k] = m
            s[k] = sd
            lower[k] = m - rho * sd
            upper[k] = m + rho * sd
            warm[k] = True
            # NaN-safe: a non-finite value is outside every band and never enters the window
            if not (abs(value - m) <= rho * sd):
                exceed[k] = True
                continue
        elif not np.isfinite(value):
            continue
        _ring_push(ring, state, value)
    return mu, s, lower, upper, exceed, warm


@njit(cache=True)
def trailing_mean_var(values, defined, window):
    """Exact mean and population variance of the last ``window`` defined, finite values up to and
    including each step (NaN until ``window`` values were seen)."""
    n = values.shape[0]
    mean = np.full(n, np.nan)
    var = np.full(n, np.nan)
    ring = np.zeros(window)
    state = np.zeros(5)
    for k in range(n):
        if not defined[k] or not np.isfinite(values[k]):
            continue
        _ring_push(ring, state, values[k])
        if state[_COUNT] == window:
            mean[k], var[k] = _ring_moments(state, window)
    return mean, var
