"""Trace decimation for reports: min/max per bucket, alarm edges and NaN gaps kept, vectorised.

A trace of N samples is cut into equal buckets of consecutive samples; each bucket contributes the
sample holding its minimum and the sample holding its maximum (in time order), plus its first NaN
when it has one, so a gap in the data still breaks the drawn line. Samples the caller must keep
(the first and last sample of every alarm interval) are added on top, and the bucket count is
chosen so the total never exceeds ``max_points``. Optionally, interior samples of runs of
identical values are dropped afterwards (a flat threshold becomes two points): that does not
change the drawn polyline.

Everything is numpy (reshape + reductions); there is no per-sample Python loop.
"""

from __future__ import annotations

import math

import numpy as np

DEFAULT_MAX_POINTS = 5000


def bucket_width(n: int, max_points: int, n_keep: int = 0, has_nan: bool = False) -> int:
    """Samples per bucket used by :func:`decimate_indices` for a trace of ``n`` samples.

    Each bucket costs 2 points (3 when the trace has NaNs); ``n_keep`` kept samples plus the
    first and last sample are paid for first. Returns 1 when no decimation is needed.
    """
    if n <= max_points:
        return 1
    per_bucket = 3 if has_nan else 2
    available = max(max_points - n_keep - 2, per_bucket)
    n_buckets = max(available // per_bucket, 1)
    return max(math.ceil(n / n_buckets), 1)


def collapsed(values: np.ndarray) -> np.ndarray:
    """A broadcast constant (as results keep a constant threshold: one value, stride 0) as its one
    element, anything else as it is: what holds for it holds for every sample, and numpy reduces a
    stride-0 array sample by sample, slower than a real one."""
    return values[:1] if values.ndim == 1 and values.size and values.strides[0] == 0 else values


def sorted_unique(*arrays) -> np.ndarray:
    """The sorted distinct values of the (integer index) arrays together: ``np.union1d`` and
    ``np.unique`` without their hashing, which on a trace's few thousand indices took ten times
    as long as a sort."""
    values = np.sort(np.concatenate([np.asarray(a, dtype=np.int64).ravel() for a in arrays]))
    return values[np.concatenate(([True], values[1:] != values[:-1]))] if values.size else values


def _thin_keep(keep: np.ndarray, n: int, max_points: int) -> np.ndarray:
    """Valid, unique, sorted keep indices; evenly thinned to half the budget if there are more."""
    keep = sorted_unique(keep)
    keep = keep[(keep >= 0) & (keep < n)]
    limit = max(max_points // 2, 1)
    if keep.size > limit:
        keep = keep[np.linspace(0, keep.size - 1, limit).round().astype(np.int64)]
    return keep


def _flat_interior(y: np.ndarray) -> np.ndarray:
    """Mask of samples equal to both neighbours (interior of a run of identical values)."""
    inner = np.zeros(y.size, dtype=bool)
    if y.size >= 3:
        inner[1:-1] = (y[1:-1] == y[:-2]) & (y[1:-1] == y[2:])  # NaN != NaN: gaps never dropped
    return inner


def _bucket_extremes(y: np.ndarray, isnan: np.ndarray | None, width: int) -> np.ndarray:
    """Per bucket of ``width`` consecutive samples (the last one shorter): the index of its first
    minimum, of its first maximum (NaN ignored) and of its first NaN (``isnan``: None when ``y`` has
    none). The full buckets are a reshaped view of ``y``, not a padded copy."""
    n_full = y.size // width
    if collapsed(y) is not y:  # a broadcast constant: each bucket's first sample is its first least,
        return np.arange(0, y.size, width, dtype=np.int64)  # greatest and NaN alike
    parts = [_extremes_of(y[: n_full * width].reshape(n_full, width), None if isnan is None else
                          isnan[: n_full * width].reshape(n_full, width), 0)]  # fmt: skip
    if n_full * width < y.size:  # the last, shorter bucket
        tail = slice(n_full * width, y.size)
        parts.append(_extremes_of(y[tail][None, :], None if isnan is None else isnan[tail][None, :], n_full * width))
    return np.concatenate(parts)


def _extremes_of(blocks: np.ndarray, nan_blocks: np.ndarray | None, start: int) -> np.ndarray:
    """`_bucket_extremes` of equal buckets (rows of ``blocks``), the first starting at sample ``start``."""
    offsets = start + np.arange(blocks.shape[0], dtype=np.int64) * blocks.shape[1]
    if nan_blocks is None:  # argmin/argmax give the first extreme, one pass each
        return np.concatenate([offsets + np.argmin(blocks, axis=1), offsets + np.argmax(blocks, axis=1)])
    with np.errstate(invalid="ignore"):
        # fmin/fmax ignore NaN unless the whole bucket is NaN (argmin/argmax would pick the NaN)
        lo = np.fmin.reduce(blocks, axis=1)
        hi = np.fmax.reduce(blocks, axis=1)
    i_min = offsets + np.argmax(blocks == lo[:, None], axis=1)
    i_max = offsets + np.argmax(blocks == hi[:, None], axis=1)
    has_nan = nan_blocks.any(axis=1)
    i_nan = (offsets + np.argmax(nan_blocks, axis=1))[has_nan]
    return np.concatenate([i_min, i_max, i_nan])


def decimate_indices(
    y: np.ndarray,
    max_points: int = DEFAULT_MAX_POINTS,
    *,
    keep: np.ndarray | None = None,
    simplify_flat: bool = False,
    has_nan: bool | None = None,
) -> np.ndarray:
    """Sorted unique indices into ``y`` (1-D) that draw it with at most ``max_points`` points.

    Per bucket of :func:`bucket_width` samples: the index of its minimum and of its maximum
    (NaN ignored; +-inf count as values), and its first NaN if any. ``keep`` indices (e.g. alarm
    edges) and the first and last sample are always included (``keep`` is thinned evenly if it
    alone exceeds half the budget). ``simplify_flat`` then drops kept samples that equal both
    kept neighbours, except ``keep`` samples. ``has_nan``: whether ``y`` holds a NaN, when the
    caller knows (None: looked for here, a pass over ``y``).
    """
    y = np.asarray(y)
    if y.ndim != 1:
        raise ValueError(f"decimate_indices needs a 1-D series, got shape {y.shape}")
    if max_points < 16:
        raise ValueError(f"max_points must be >= 16, got {max_points}")
    n = y.size
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    keep_idx = _thin_keep(np.zeros(0) if keep is None else keep, n, max_points)
    if has_nan is None:  # the least value is NaN when one is: one pass, no mask
        has_nan = bool(np.isnan(collapsed(y).min()))
    width = bucket_width(n, max_points, keep_idx.size, has_nan)
    if width == 1:
        idx = np.arange(n, dtype=np.int64)
    else:
        idx = np.concatenate([_bucket_extremes(y, np.isnan(y) if has_nan else None, width), [0, n - 1]])
    idx = sorted_unique(idx, keep_idx)
    if simplify_flat and idx.size >= 3:
        drop = _flat_interior(y[idx])
        if keep_idx.size:
            drop &= ~_member(idx, keep_idx)
        idx = idx[~drop]
    return idx


def _member(values: np.ndarray, sorted_set: np.ndarray) -> np.ndarray:
    """Mask of ``values`` found in the sorted, non-empty ``sorted_set`` (``np.isin`` by bisection)."""
    at = np.minimum(np.searchsorted(sorted_set, values), sorted_set.size - 1)
    return sorted_set[at] == values


def edge_indices(t: np.ndarray, spans) -> np.ndarray:
    """Indices of the grid samples at the start and end of each (start, end) span (seconds).

    The sample at a time is the first grid point >= it (clipped to the grid), matching how
    alarm intervals are stamped with grid times.
    """
    t = np.asarray(t, dtype=np.float64)
    pairs = np.asarray(list(spans), dtype=np.float64).reshape(-1, 2)
    if t.size == 0 or pairs.size == 0:
        return np.zeros(0, dtype=np.int64)
    idx = np.searchsorted(t, pairs.ravel(), side="left")
    return sorted_unique(np.clip(idx, 0, t.size - 1))


def decimate(
    t: np.ndarray,
    y: np.ndarray,
    max_points: int = DEFAULT_MAX_POINTS,
    *,
    keep: np.ndarray | None = None,
    simplify_flat: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """``(t[idx], y[idx])`` for :func:`decimate_indices`; flat runs simplified by default."""
    t = np.asarray(t)
    y = np.asarray(y)
    if t.shape != y.shape:
        raise ValueError(f"t and y differ in shape: {t.shape} vs {y.shape}")
    idx = decimate_indices(y, max_points, keep=keep, simplify_flat=simplify_flat)
    return t[idx], y[idx]
