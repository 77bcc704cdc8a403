"""The hybrid KF + A-TFM's count threshold sized for the false-alarm budget (docs/algorithms.md 4.4).

The thesis's threshold e is the largest count of ``|r| > eps`` in any w consecutive training
samples: a sample maximum of a few minutes per mode, which new data exceeds (24 false alarms per
hour on healthy runs). Here e comes from a model of the exceedances fitted on the same training
segments, extrapolated to the tail the budget asks for:

- Exceedance-count model: the exceedances of a channel in one mode come in runs (consecutive
  exceedances); runs start as a Poisson process of ``nu`` per update and their lengths L are
  i.i.d. with the channel's empirical run-length law f (pooled over its modes). The count in a
  window of w updates is then compound Poisson: Poisson(nu w) runs, each of f's length, whose law
  follows by Panjer's recursion.
- Margin for the estimate: nu is the upper end of the exact 95 % Poisson interval of the runs seen
  (k runs in n training updates: chi2.ppf(0.975, 2k + 2) / (2 n)), never the point estimate.
- Alarms, not exceedances: an alarm starts at an update whose count rises above e, so the newest
  sample exceeds eps and belongs to a run (probability nu E[L] per update); given that, the count
  is at most that run's length L* (f size-biased, j f_j / E[L]) plus the compound Poisson count of
  the window. Per update: P(alarm starts) <= nu E[L] P(C_w + L* > e).
- The budget, as `nis`: a union bound over every update of every channel checked,
  P(alarm starts) <= rate_design / (3600 tests per second) (`detectors.budget.design_rate`).

e is the smallest count meeting that, and never below the thesis's knee e.
"""

from __future__ import annotations

import numpy as np

CONFIDENCE = 0.95  # the two-sided exact Poisson interval whose upper end is taken for nu


def run_lengths(exceed: np.ndarray) -> np.ndarray:
    """Lengths of the runs of consecutive True in a 1-D boolean array (one segment)."""
    x = np.concatenate(([False], np.asarray(exceed, dtype=bool), [False]))
    edges = np.flatnonzero(x[1:] != x[:-1])  # starts and ends alternate
    return edges[1::2] - edges[0::2]


def run_statistics(segments: list[np.ndarray], eps: float) -> tuple[int, int, np.ndarray]:
    """(updates, runs, histogram of run lengths: index = length) of ``|r| > eps`` over the
    segments (NaN never exceeds; a run never crosses a segment)."""
    lengths = [run_lengths(np.asarray(s, dtype=np.float64).ravel() > eps) for s in segments]
    joined = np.concatenate(lengths) if lengths else np.zeros(0, dtype=np.int64)
    n = int(sum(np.isfinite(np.asarray(s, dtype=np.float64)).sum() for s in segments))
    return n, int(joined.size), np.bincount(joined, minlength=2).astype(np.int64)


def run_rate_upper(runs: int, updates: int) -> float:
    """nu: the upper end of the exact 95 % Poisson interval of ``runs`` over ``updates``."""
    from scipy.special import chdtri  # chdtri(d, q) = chi2.ppf(1 - q, d)

    return float(chdtri(2 * runs + 2, (1.0 - CONFIDENCE) / 2.0)) / (2.0 * max(updates, 1))


def compound_poisson_pmf(mean_runs: float, lengths: np.ndarray, n_max: int) -> np.ndarray:
    """P(C = c), c = 0 .. n_max, C = the sum of Poisson(``mean_runs``) lengths of law ``lengths``
    (a pmf over 0, 1, ...; lengths[0] = 0): Panjer's recursion
    g_0 = exp(-lambda), g_c = lambda / c sum_{j=1}^{c} j f_j g_{c-j}."""
    f = np.zeros(n_max + 1)
    m = min(lengths.size, n_max + 1)
    f[1:m] = lengths[1:m]
    g = np.zeros(n_max + 1)
    g[0] = np.exp(-mean_runs)
    j = np.arange(n_max + 1, dtype=np.float64)
    for c in range(1, n_max + 1):  # n_max = w + a longest run: a few hundred steps, once per table row
        g[c] = mean_runs / c * np.dot(j[1 : c + 1] * f[1 : c + 1], g[c - 1 :: -1][:c])
    return g


def alarm_start_tail(nu: float, histogram: np.ndarray, w: int) -> np.ndarray:
    """Per update, the bound on P(an alarm starts) at each threshold e = 0 .. w:
    nu E[L] P(C_w + L* > e) (the module's docstring)."""
    counts = np.asarray(histogram, dtype=np.float64)
    if counts[1:].sum() <= 0:
        counts = np.zeros(2)
        counts[1] = 1.0  # no run seen: runs of one (the rate nu still carries the 95 % upper end)
    f = counts / counts.sum()
    lengths = np.arange(f.size, dtype=np.float64)
    mean_length = float(np.dot(lengths, f))
    size_biased = lengths * f / mean_length
    n_max = w + f.size
    g = compound_poisson_pmf(nu * w, f, n_max)
    total = np.convolve(g, size_biased)[: n_max + 1]  # C_w + L*
    beyond = np.clip(1.0 - np.cumsum(total), 0.0, 1.0)  # P(C_w + L* > e)
    return nu * mean_length * beyond[: w + 1]


def budget_count(nu: float, histogram: np.ndarray, w: int, alpha: float) -> int:
    """The smallest e in 0 .. w whose alarm-start bound is within ``alpha`` per update (w when none
    is: the count can never exceed w)."""
    tail = alarm_start_tail(nu, histogram, w)
    within = np.flatnonzero(tail <= alpha)
    return int(within[0]) if within.size else int(w)
