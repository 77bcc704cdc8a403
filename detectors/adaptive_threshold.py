"""Adaptive mu +- rho*s thresholds over a trailing window of samples that did not exceed their own band.

docs/algorithms.md section 1c, eq. 4 of the encoded-EKF paper: the band at step k is the exact mean and
standard deviation of the last W accepted samples before k. A sample that exceeds its band (or is
non-finite) never enters the window, so a fault cannot widen its own threshold. The window's
moments are computed exactly from the ring buffer at every step (two passes, O(W)): running sums
lose the small samples next to a huge one and keep the error after it leaves (naive running sums
produced thousands of spurious exceedances in the prototype).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _ring_push(ring, count, head, value):
    """Append ``value``, overwriting the oldest sample when full; returns (count, head)."""
    ring[head] = value
    window = ring.shape[0]
    return min(count + 1, window), (head + 1) % window


@njit(cache=True)
def _ring_moments(ring, count):
    """Exact mean and population variance of the first ``count`` ring entries (two passes)."""
    total = 0.0
    for i in range(count):
        total += ring[i]
    m = total / count
    sq = 0.0
    for i in range(count):
        d = ring[i] - m
        sq += d * d
    return m, sq / count


@njit(cache=True)
def _ring_sum(ring):
    """The sum of every ring entry, in index order (as `_ring_moments` adds them)."""
    total = 0.0
    for i in range(ring.shape[0]):
        total += ring[i]
    return total


@njit(cache=True)
def _spread_and_pushed_sum(ring, m, head, value):
    """(sum of (ring - m)^2, sum of the ring with ``value`` at ``head``), both in index order: the
    second is the next step's sum when ``value`` enters the window. Two independent chains of
    additions in one loop run in about the time of one (each addition waits for the previous)."""
    sq = 0.0
    pushed = 0.0
    for i in range(ring.shape[0]):
        d = ring[i] - m
        sq += d * d
        pushed += value if i == head else ring[i]
    return sq, pushed


@njit(cache=True)
def adaptive_band(e, defined, window, rho, s_floor):
    """Band of ``e`` over a trailing window of accepted samples.

    e:       (N,) statistic (NaN allowed: counts as an exceedance where defined and warm).
    defined: (N,) bool, steps where the statistic exists (e.g. steps with a measurement update).
    s_floor: (N,) lower bound of the spread s at each step (zeros: the plain rule of eq. 4).
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
    count = head = np.int64(0)  # not literal zeros: they would compile the ring helpers twice
    total = 0.0  # the full ring's sum in index order (as `_ring_moments` adds), when known
    known = False
    for k in range(n):
        if not defined[k]:
            continue
        value = e[k]
        if count == window:
            if not known:  # the ring just filled (it stays full: pushes keep ``total`` from here on)
                total, known = _ring_sum(ring), True
            m = total / count
            sq, pushed_total = _spread_and_pushed_sum(ring, m, head, value)
            var = sq / count
            sd = max(np.sqrt(var), s_floor[k])
            mu[k] = m
            s[k] = sd
            lower[k] = m - rho * sd
            upper[k] = m + rho * sd
            warm[k] = True
            # NaN-safe: a non-finite value is outside every band and never enters the window
            if not (abs(value - m) <= rho * sd):
                exceed[k] = True
                continue
            total = pushed_total
        elif not np.isfinite(value):
            continue
        count, head = _ring_push(ring, count, head, value)
    return mu, s, lower, upper, exceed, warm


def compile_kernels() -> None:
    """Compile (or load) `adaptive_band` for the types its detectors pass: the first run calls it
    while the EKF compiles in its own process."""
    adaptive_band(np.zeros(2), np.ones(2, dtype=np.bool_), 1, 1.0, np.zeros(2))


@njit(cache=True)
def trailing_mean_var(values, defined, window):
    """Exact mean and population variance of the last ``window`` defined, finite values up to and
    including each step (NaN until ``window`` values were seen)."""
    n = values.shape[0]
    mean = np.full(n, np.nan)
    var = np.full(n, np.nan)
    ring = np.zeros(window)
    count = head = np.int64(0)  # not literal zeros: they would compile the ring helpers twice
    for k in range(n):
        if not defined[k] or not np.isfinite(values[k]):
            continue
        count, head = _ring_push(ring, count, head, values[k])
        if count == window:
            mean[k], var[k] = _ring_moments(ring, count)
    return mean, var
