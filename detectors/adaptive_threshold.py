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

from logscan.numba_cache import follow_dependencies

# The kernels allocate nothing and call no other numba function: their output arrays come from
# numpy in the wrappers, and the ring's push and sums are written out in the loop. numba's generic
# np.full / np.zeros, min / max and each helper compile apart (types, LLVM, linking into the caller):
# the first run after install paid about 1 s for `adaptive_band` alone, 0.3 s like this.


@njit(cache=True)
def _band_kernel(e, defined, window, rho, s_floor, mu, s, lower, upper, exceed, warm, ring):
    """`adaptive_band` into its output arrays (mu, s, lower, upper: NaN; exceed, warm: False;
    ring: ``window`` zeros), written only at the steps with a band."""
    count = head = 0
    total = 0.0  # the full ring's sum in index order (as the moments add it), when known
    known = False
    for k in range(e.shape[0]):
        if not defined[k]:
            continue
        value = e[k]
        if count == window:
            if not known:  # the ring just filled (it stays full: pushes keep ``total`` from here on)
                total, known = 0.0, True
                for i in range(window):
                    total += ring[i]
            m = total / count
            # (sum of (ring - m)^2, the next step's sum if ``value`` enters at ``head``), both in
            # index order: two independent chains of additions run in about the time of one
            sq = 0.0
            pushed = 0.0
            for i in range(window):
                d = ring[i] - m
                sq += d * d
                pushed += value if i == head else ring[i]
            root = np.sqrt(sq / count)
            floor = s_floor[k]
            sd = floor if floor > root else root  # max(root, floor), as Python's max picks
            mu[k] = m
            s[k] = sd
            lower[k] = m - rho * sd
            upper[k] = m + rho * sd
            warm[k] = True
            # NaN-safe: a non-finite value is outside every band and never enters the window
            if not (abs(value - m) <= rho * sd):
                exceed[k] = True
                continue
            total = pushed
        elif not np.isfinite(value):
            continue
        ring[head] = value  # the push: overwrites the oldest sample once full
        count = count + 1 if count < window else window
        head = head + 1 if head + 1 < window else 0


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
    mu, s, lower, upper = (np.full(n, np.nan) for _ in range(4))
    exceed = np.zeros(n, dtype=np.bool_)
    warm = np.zeros(n, dtype=np.bool_)
    _band_kernel(e, defined, window, rho, s_floor, mu, s, lower, upper, exceed, warm, np.zeros(window))
    return mu, s, lower, upper, exceed, warm


def compile_kernels() -> None:
    """Compile (or load) `adaptive_band`'s kernel for the types its detectors pass: the first run
    calls it while the EKF compiles in its own process."""
    adaptive_band(np.zeros(2), np.ones(2, dtype=np.bool_), 1, 1.0, np.zeros(2))


@njit(cache=True)
def _trailing_kernel(values, defined, window, mean, var, ring):
    """`trailing_mean_var` into ``mean`` and ``var`` (NaN), with a ring of ``window`` zeros."""
    count = head = 0
    for k in range(values.shape[0]):
        if not defined[k] or not np.isfinite(values[k]):
            continue
        ring[head] = values[k]
        count = count + 1 if count < window else window
        head = head + 1 if head + 1 < window else 0
        if count == window:  # exact moments, two passes over the ring in index order
            total = 0.0
            for i in range(count):
                total += ring[i]
            m = total / count
            sq = 0.0
            for i in range(count):
                d = ring[i] - m
                sq += d * d
            mean[k], var[k] = m, sq / count


def trailing_mean_var(values, defined, window):
    """Exact mean and population variance of the last ``window`` defined, finite values up to and
    including each step (NaN until ``window`` values were seen)."""
    n = values.shape[0]
    mean, var = np.full(n, np.nan), np.full(n, np.nan)
    _trailing_kernel(values, defined, window, mean, var, np.zeros(window))
    return mean, var


follow_dependencies(__name__)  # the disk cache filed by what the kernels compile (logscan.numba_cache)
