"""Numeric core of the adaptive transient fault model (A-TFM): training curves, knees, row selection, WI/SI.

docs/algorithms.md section 4 (papers/adaptive-transient-fault-model.txt). A sensor's transient fault model is
(eps, e, w): within any w consecutive samples at most e readings are farther than eps from the truth.
 - Training, per sensor and mode: err_i = |y_i - ref_i| (ref_i = median of the other sensors),
   e(eps, w) = max over windows of w samples (never crossing a segment) of count(err > eps), on a grid
   of N_EPS points from 0 to 3 x the 99th percentile of err. The knee of each curve, among points with
   e/w < 0.5 (Lemma 4), maximises 1 - eps/eps_max - e/w (distance below the diagonal from (0, 1) to
   (eps_max, 0)); ties go to the larger eps (the conservative bound).
 - Lookup table: one row per trained mode; eps is made non-decreasing with the mode (running maximum);
   a step uses the smallest mode >= max(commanded, measured - margin) ("next higher").
 - Detection: WI_ij when [y_i -+ eps_i] and [y_j -+ eps_j] do not overlap; SI_ij when WI_ij occurred more
   than e_i + e_j times in the last w steps. A sensor in SI with every other one (a majority, for 4+) is
   named. The hybrid KF + A-TFM applies the same count to a Kalman residual: count(|r| > eps) > e.
Everything is vectorised over samples; loops run only over sensors, windows, segments' bookkeeping and
chunks of the eps grid.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

DEFAULT_WINDOWS = (25, 50, 100, 200)
N_EPS = 201  # eps grid points (>= 200)
EPS_MAX_FACTOR = 3.0  # eps_max = 3 x the 99th percentile of the errors
KNEE_MAX_RATIO = 0.5  # Lemma 4: only points with e/w < 0.5
TIE_TOLERANCE = 1e-12

_EPS_FLOOR = 1e-9  # eps_max when the errors give no scale (all zero, or none)
_SELECT_TOLERANCE = 1e-9  # a selection value of 1.0 (as 0.9999999999) still selects the 1.0 row


@dataclass
class Knee:
    """The knee (eps, e) of one e(eps, w) curve."""

    w: int
    eps: float
    e: int


@dataclass
class SensorTraining:
    """One sensor in one mode: the e(eps, w) curves and their knees."""

    eps: np.ndarray  # the grid
    counts: np.ndarray  # (len(eps), len(windows)) int64
    windows: tuple[int, ...]
    knees: list[Knee]  # one per window
    n_samples: int  # finite errors over all segments


def _check_window(w: int) -> int:
    if int(w) != w or w < 1:
        raise ValueError(f"window must be a positive integer, got {w!r}")
    return int(w)


def _median_of_finite(others: np.ndarray) -> np.ndarray:
    """Row-wise median of the finite entries of (N, k) ``others``; NaN for a row without one.
    np.sort puts NaN last, so a row's m finite values are its first m entries (no all-NaN warnings
    from np.nanmedian)."""
    ordered = np.sort(others, axis=1)
    m = np.isfinite(ordered).sum(axis=1)
    rows = np.arange(ordered.shape[0])
    # median = (x[(m - 1) // 2] + x[m // 2]) / 2 (the same entry twice when m is odd)
    lo = ordered[rows, np.maximum(m - 1, 0) // 2]
    hi = ordered[rows, np.minimum(m // 2, ordered.shape[1] - 1)]
    median = 0.5 * (lo + hi)
    return np.where(m > 0, median, np.nan)


def reference_errors(values: np.ndarray) -> np.ndarray:
    """(N, s) readings of s >= 2 redundant sensors in one unit (NaN: no reading) -> (N, s)
    err_i = |y_i - ref_i|, ref_i = median of the other sensors' finite readings (with two others
    their mean; with one other, that one). NaN where y_i is NaN or no other sensor has a reading."""
    y = np.asarray(values, dtype=float)
    if y.ndim != 2 or y.shape[1] < 2:
        raise ValueError(f"reference_errors needs (N, s) readings with s >= 2, got shape {y.shape}")
    y = np.where(np.isfinite(y), y, np.nan)
    err = np.empty_like(y)
    for i in range(y.shape[1]):
        # err_i = |y_i - median_{j != i} y_j|
        ref = _median_of_finite(np.delete(y, i, axis=1))
        err[:, i] = np.abs(y[:, i] - ref)
    return err


def eps_grid(errors: np.ndarray, n: int = N_EPS) -> np.ndarray:
    """n points from 0 to eps_max = EPS_MAX_FACTOR x the 99th percentile of the finite errors
    (not the max: one outlier moved the knee from 0.10 to 0.70). eps_max > 0 always (a tiny
    positive floor when all errors are 0 or there are none)."""
    if int(n) != n or n < 2:
        raise ValueError(f"the eps grid needs at least 2 points, got {n!r}")
    err = np.asarray(errors, dtype=float).ravel()
    finite = err[np.isfinite(err)]
    # eps_max = 3 x p99(err)
    eps_max = EPS_MAX_FACTOR * float(np.percentile(finite, 99)) if finite.size else 0.0
    if not eps_max > 0:
        # over 99 % of the errors are exactly 0 (a quantised sensor): the largest is the only scale left
        largest = float(finite.max()) if finite.size else 0.0
        eps_max = EPS_MAX_FACTOR * largest if largest > 0 else _EPS_FLOOR
    return np.linspace(0.0, eps_max, int(n))


def _window_layout(starts: np.ndarray, lengths: np.ndarray, w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where windows of w samples lie in the concatenated segments.

    Returns (valid, short_lo, short_hi): valid[p] is True when the window starting at p stays inside
    one segment (p = 0 .. N - w; empty when N < w); short_lo/short_hi bound the segments shorter than
    w, each of which counts as one short window.
    """
    total = int(lengths.sum())
    short = (lengths > 0) & (lengths < w)
    if total < w:
        return np.zeros(0, dtype=bool), starts[short], starts[short] + lengths[short]
    segment = np.repeat(np.arange(lengths.size), lengths)
    offset = np.arange(total) - starts[segment]
    # the window [p, p + w) fits when offset(p) <= length - w
    fits = offset <= (lengths - w)[segment]
    return fits[: total - w + 1], starts[short], starts[short] + lengths[short]


def max_window_counts(
    segments: Sequence[np.ndarray], eps: np.ndarray, windows: Sequence[int], chunk: int = 16
) -> np.ndarray:
    """(len(eps), len(windows)) int64: e(eps, w) = max over every segment and every run of w
    consecutive samples inside one segment of count(err > eps). Windows never cross segments.
    A segment shorter than w counts as one (short) window. NaN never exceeds. Vectorised:
    cs = cumsum(err[None, :] > eps[:, None], axis=1) then max(cs[:, w:] - cs[:, :-w]) per w,
    chunked over eps (``chunk`` eps rows at a time) to bound memory."""
    eps = np.asarray(eps, dtype=float).ravel()
    windows = [_check_window(w) for w in windows]
    if chunk < 1:
        raise ValueError(f"chunk must be >= 1, got {chunk!r}")
    parts = [np.asarray(segment, dtype=float).ravel() for segment in segments]
    counts = np.zeros((eps.size, len(windows)), dtype=np.int64)
    lengths = np.array([part.size for part in parts], dtype=np.int64)
    if eps.size == 0 or lengths.sum() == 0:
        return counts
    # one cumulative sum over all segments; windows that cross a boundary are masked out
    err = np.concatenate(parts)
    starts = np.concatenate(([0], np.cumsum(lengths)[:-1]))
    layouts = [_window_layout(starts, lengths, w) for w in windows]
    cs = np.zeros((min(chunk, eps.size), err.size + 1), dtype=np.int32)
    for lo in range(0, eps.size, chunk):
        block = eps[lo : lo + chunk]
        rows = cs[: block.size]
        # cs[:, k] = count(err[:k] > eps); the leading cs[:, 0] = 0 lets the window at sample 0 count
        # (NaN > eps is False: a missing error never exceeds)
        np.cumsum(err[None, :] > block[:, None], axis=1, dtype=np.int32, out=rows[:, 1:])
        for k, (w, (valid, short_lo, short_hi)) in enumerate(zip(windows, layouts)):
            best = np.zeros(block.size, dtype=np.int64)
            if valid.any():
                # count(err > eps) over [p, p + w) = cs[p + w] - cs[p]
                best = np.max(rows[:, w:] - rows[:, :-w], axis=1, where=valid, initial=0)
            if short_lo.size:
                best = np.maximum(best, np.max(rows[:, short_hi] - rows[:, short_lo], axis=1))
            counts[lo : lo + block.size, k] = best
    return counts


def knee(eps: np.ndarray, e: np.ndarray, w: int) -> tuple[float, int]:
    """The knee of one e(eps, w) curve: among points with e/w < KNEE_MAX_RATIO, the one maximising
    1 - eps/eps_max - e/w (eps_max = eps[-1]); among maxima equal within TIE_TOLERANCE the largest
    eps. Returns (eps_k, e_k). If no point has e/w < 0.5 (cannot happen with a proper grid, since
    e(eps_max) is small), return (eps[-1], int(e[-1]))."""
    eps = np.asarray(eps, dtype=float).ravel()
    e = np.asarray(e).ravel()
    w = _check_window(w)
    ratio = e / w
    allowed = ratio < KNEE_MAX_RATIO
    if not allowed.any():
        return float(eps[-1]), int(e[-1])
    scale = eps[-1] if eps[-1] > 0 else 1.0
    # distance below the diagonal from (0, 1) to (eps_max, 0), up to the factor 1/sqrt(1 + 1/eps_max^2):
    # d = 1 - eps/eps_max - e/w; the values lie on a lattice, hence the tie rule (larger eps is conservative)
    distance = 1.0 - eps / scale - ratio
    best = distance[allowed].max()
    ties = np.flatnonzero(allowed & (distance >= best - TIE_TOLERANCE))
    k = ties[np.argmax(eps[ties])]
    return float(eps[k]), int(e[k])


def train_sensor(
    segments: Sequence[np.ndarray], windows: Sequence[int] = DEFAULT_WINDOWS, n: int = N_EPS
) -> SensorTraining:
    """eps_grid over all segments' errors pooled, max_window_counts, knee per window."""
    parts = [np.asarray(segment, dtype=float).ravel() for segment in segments]
    pooled = np.concatenate(parts) if parts else np.zeros(0)
    windows = tuple(_check_window(w) for w in windows)
    grid = eps_grid(pooled, n)
    counts = max_window_counts(parts, grid, windows)
    knees = [Knee(w, *knee(grid, counts[:, k], w)) for k, w in enumerate(windows)]
    return SensorTraining(grid, counts, windows, knees, int(np.isfinite(pooled).sum()))


def monotone_envelope(eps_by_mode: np.ndarray) -> np.ndarray:
    """eps per trained mode value, sorted by mode ascending -> running maximum (eps non-decreasing
    with the mode value). Works along axis 0, so an (n_modes, n_sensors) table is enveloped per
    sensor; a NaN entry (mode not trained) takes the maximum of the rows below it."""
    # eps'_m = max_{k <= m} eps_k (measured rows were not monotone: GPS 0.146 at 1.0 vs 0.138 at 1.3)
    return np.fmax.accumulate(np.asarray(eps_by_mode, dtype=float), axis=0)


def select_rows(
    modes: np.ndarray, commanded: np.ndarray, measured: np.ndarray, margin: float
) -> tuple[np.ndarray, np.ndarray]:
    """Row of the lookup table per step: the smallest trained mode >= max(commanded, measured -
    margin) ("next higher", sound); ``modes`` ascending. Returns (row index int64 per step,
    above_top bool per step: the selection value exceeds the top row, which is then used).
    NaN selection value (no command and no measurement) -> the top row, above_top False.
    Use np.searchsorted with a small tolerance (1e-9) so 1.0 selects the 1.0 row."""
    modes = np.asarray(modes, dtype=float).ravel()
    if modes.size == 0:
        raise ValueError("select_rows needs at least one trained mode")
    # selection value v = max(commanded, measured - margin); fmax: a missing one leaves the other
    value = np.fmax(np.asarray(commanded, dtype=float), np.asarray(measured, dtype=float) - margin)
    # row = min{m : mode_m >= v} (NaN sorts past the end, so it lands on the top row)
    row = np.searchsorted(modes, value - _SELECT_TOLERANCE, side="left")
    top = modes.size - 1
    above_top = (row > top) & ~np.isnan(value)
    return np.minimum(row, top).astype(np.int64), np.asarray(above_top, dtype=bool)


def weak_inconsistency(y_i, eps_i, y_j, eps_j) -> np.ndarray:
    """WI_ij per step: the intervals [y_i - eps_i, y_i + eps_i] and [y_j - eps_j, y_j + eps_j] do not
    overlap (|y_i - y_j| > eps_i + eps_j). False where either reading is NaN."""
    with np.errstate(invalid="ignore"):
        # WI_ij(t): |y_i - y_j| > eps_i + eps_j (NaN compares False)
        return np.abs(np.asarray(y_i, dtype=float) - y_j) > np.add(eps_i, eps_j)


def window_counts(flags: np.ndarray, w: int) -> np.ndarray:
    """Per step, the number of True flags among the last w steps (fewer at the start), int64,
    via a cumulative sum."""
    w = _check_window(w)
    cs = np.cumsum(np.asarray(flags, dtype=bool), axis=0, dtype=np.int64)
    # count(t) = cs[t] - cs[t - w]: the flags in (t - w, t]
    counts = cs.copy()
    counts[w:] -= cs[:-w]
    return counts


def strong_inconsistency(
    values: np.ndarray, eps: np.ndarray, e: np.ndarray, w: int
) -> dict[tuple[int, int], tuple[np.ndarray, np.ndarray]]:
    """values (N, s); eps, e (N, s) per-step parameters of each sensor (from the selected row).
    For every pair i < j: (count of WI_ij over the last w steps, threshold e_i + e_j per step).
    SI_ij where count > threshold. eps and e may also be (s,): the same parameters at every step."""
    y = np.asarray(values, dtype=float)
    if y.ndim != 2:
        raise ValueError(f"strong_inconsistency needs (N, s) readings, got shape {y.shape}")
    eps = np.broadcast_to(np.asarray(eps, dtype=float), y.shape)
    e = np.broadcast_to(np.asarray(e), y.shape)
    pairs = {}
    for i in range(y.shape[1]):
        for j in range(i + 1, y.shape[1]):
            wi = weak_inconsistency(y[:, i], eps[:, i], y[:, j], eps[:, j])
            # SI_ij(t): count of WI_ij over (t - w, t] > e_i + e_j
            pairs[(i, j)] = (window_counts(wi, w), e[:, i] + e[:, j])
    return pairs


def attribute(si: dict[tuple[int, int], np.ndarray], n_sensors: int) -> list[np.ndarray]:
    """si: pair -> (N,) bool SI. Returns per sensor an (N,) bool: the sensor is named at a step
    when it is in SI with every other sensor of the group (for groups of 4+: with a majority of
    the others). Steps where some pair is in SI but no sensor is named are the caller's "pair"
    attribution (compute nothing for that here). A group of two never names a sensor: its one pair
    cannot tell which of the two is at fault, so that is always a pair attribution."""
    if n_sensors < 2:
        raise ValueError(f"attribution needs a group of at least 2 sensors, got {n_sensors}")
    flags = [np.asarray(pair_si, dtype=bool) for pair_si in si.values()]
    n_steps = flags[0].shape[0] if flags else 0
    if n_sensors == 2:
        return [np.zeros(n_steps, dtype=bool) for _ in range(n_sensors)]
    partners = np.zeros((n_sensors, n_steps), dtype=np.int64)
    for (i, j), pair_si in zip(si, flags):
        partners[i] += pair_si
        partners[j] += pair_si
    others = n_sensors - 1
    # named: in SI with all others (n <= 3), or with more than half of them (n >= 4)
    needed = others if n_sensors <= 3 else others // 2 + 1
    return list(partners >= needed)


def residual_counts(residual: np.ndarray, eps: np.ndarray, w: int) -> np.ndarray:
    """Hybrid KF + A-TFM: per step count(|r| > eps_step) over the last w steps (NaN never exceeds);
    the alarm is count > e_step."""
    with np.errstate(invalid="ignore"):
        # exceed(t) = |r(t)| > eps(t)
        exceed = np.abs(np.asarray(residual, dtype=float)) > eps
    return window_counts(exceed, w)
