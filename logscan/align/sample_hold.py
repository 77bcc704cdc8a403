"""Holding one channel onto the grid: cleaning (sort, deduplicate, drop non-finite samples), the
compiled zero-order hold with its staleness limit, gaps, and which steps changed."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, types

from logscan.log import TIMES_CHUNK, read_in_chunks
from logscan.numba_cache import OneSignature, follow_dependencies

# ------------------------------------------------------------------------------------------------
# Implementation
# ------------------------------------------------------------------------------------------------

_NS = 1_000_000_000
_NEVER_STALE_NS = np.iinfo(np.int64).max // 4  # stale_s = inf
_CHUNK = TIMES_CHUNK  # times per step of `_increasing`


@dataclass
class _Clean:
    """One channel after cleaning: sorted unique int64 ns times with finite float64 values."""

    t: np.ndarray
    values: np.ndarray
    samples: int
    nonfinite: int
    unsorted: int
    duplicates: int
    outliers: int = 0  # outlying samples dropped (see `outlying_runs`)


def stale_ns(stale_s: float) -> int:
    """A staleness limit in integer nanoseconds (inf: never stale)."""
    if not np.isfinite(stale_s):
        return int(_NEVER_STALE_NS)
    return int(round(stale_s * _NS))


@dataclass
class _TimeOrder:
    """How one time array is put in order: the stable sort (None: already sorted) and the samples
    kept after it (None: all, no duplicate times). The channels of a topic share their time array:
    it is examined once for all of them (`clean_samples`'s ``order``)."""

    t: np.ndarray  # the times it was found for (int64)
    t_clean: np.ndarray  # sorted, each time once: shared by the channels cleaned with it
    sort: np.ndarray | None
    keep: np.ndarray | None
    unsorted: int
    duplicates: int


def time_order(t_ns: np.ndarray) -> _TimeOrder:
    """The stable sort and the duplicate times dropped (the last of each kept) of ``t_ns``."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    if _increasing(t_ns):  # the usual case, in one pass: in order, each time once
        return _TimeOrder(t_ns, t_ns, None, None, 0, 0)
    unsorted = int(np.count_nonzero(t_ns[1:] < t_ns[:-1]))
    sort = np.argsort(t_ns, kind="stable") if unsorted else None
    t_sorted = t_ns if sort is None else t_ns[sort]
    last_of_run = np.ones(t_sorted.size, dtype=bool)
    last_of_run[:-1] = t_sorted[1:] != t_sorted[:-1]
    duplicates = int(t_sorted.size - np.count_nonzero(last_of_run))
    keep = last_of_run if duplicates else None
    t_clean = t_sorted if keep is None else t_sorted[keep]
    return _TimeOrder(t_ns, t_clean, sort, keep, unsorted, duplicates)


def _increasing(t_ns: np.ndarray) -> bool:
    """Whether each time of ``t_ns`` is after the one before, `_CHUNK` at a time: a long log's
    times held on disk are not touched whole at once (`logscan.log.read_in_chunks`)."""
    return all(bool((part[1:] > part[:-1]).all()) for part in read_in_chunks(t_ns, _CHUNK, overlap=1))


def clean_samples(t_ns: np.ndarray, values: np.ndarray, order: _TimeOrder | None = None) -> _Clean:
    """Stable-sort by time, drop duplicate timestamps (keep the last), then drop non-finite values.
    ``order``: `time_order` of ``t_ns``, when it is known (another channel of the same times)."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    values = np.asarray(values, dtype=np.float64)
    samples = int(t_ns.size)
    order = time_order(t_ns) if order is None else order
    unsorted, duplicates = order.unsorted, order.duplicates
    t_ns = order.t_clean
    if order.sort is not None:
        values = values[order.sort]
    if order.keep is not None:
        values = values[order.keep]
    finite = np.isfinite(values)
    nonfinite = int(finite.size - np.count_nonzero(finite))
    if nonfinite:
        t_ns, values = t_ns[finite], values[finite]
    return _Clean(t_ns, values, samples, nonfinite, unsorted, duplicates)


@njit(cache=True)
def _hold_kernel(t_ns, values, grid_ns, limit_ns, z, fresh):  # pragma: no cover - compiled
    # One merge pass over two sorted arrays: i = max{i : t_i <= g_k} (-1: none yet).
    i = -1
    n_t = t_ns.size
    for k in range(grid_ns.size):
        g = grid_ns[k]
        while i + 1 < n_t and t_ns[i + 1] <= g:
            i += 1
        if i >= 0 and g - t_ns[i] <= limit_ns:
            z[k] = values[i]
            fresh[k] = k == 0 or t_ns[i] > grid_ns[k - 1]
        else:
            z[k] = np.nan
            fresh[k] = False


# z and fresh are often columns of 2-D arrays ("A" layout), sometimes whole arrays ("C"); the
# samples are sometimes read-only (as read from a mapped file): one compile for all of them
_IN = {"layout": "C", "readonly": True}
_hold_one = OneSignature(
    _hold_kernel,
    (
        types.Array(types.int64, 1, **_IN),
        types.Array(types.float64, 1, **_IN),
        types.Array(types.int64, 1, **_IN),
        types.int64,
        types.float64[:],
        types.boolean[:],
    ),
)


def hold(t_ns: np.ndarray, values: np.ndarray, grid_ns: np.ndarray, limit_ns: int, z=None, fresh=None):
    """Zero-order hold of sorted unique samples onto ``grid_ns`` within ``limit_ns``.

    Returns (z, fresh): z[k] = the latest sample at or before grid_ns[k] if it is at most
    ``limit_ns`` old, else NaN; fresh[k] = that sample is newer than grid_ns[k-1] (for k = 0:
    any sample within the limit). A compiled merge of the two sorted arrays, O(N + M);
    ``z`` / ``fresh`` may be given (e.g. a column of a 2-D array) to be written in place.
    """
    n = grid_ns.size
    z = np.empty(n) if z is None else z
    fresh = np.empty(n, dtype=np.bool_) if fresh is None else fresh
    _hold_one(
        np.ascontiguousarray(t_ns, dtype=np.int64),
        np.ascontiguousarray(values, dtype=np.float64),
        np.ascontiguousarray(grid_ns, dtype=np.int64),
        np.int64(limit_ns),
        z,
        fresh,
    )
    return z, fresh


@njit(cache=True)
def _gap_kernel(t_ns, i0, i1, g0, g1, limit_ns, starts, ends):  # pragma: no cover - compiled
    # Stretches without a sample inside [g0, g1] longer than the limit; edges: the last sample
    # before g0 (else g0), every sample in [g0, g1] (t_ns[i0:i1]), then g1. Writes up to
    # starts.size of them (pass empty arrays to only count) and returns how many there are.
    prev = t_ns[i0 - 1] if i0 > 0 else g0
    count = 0
    for i in range(i0, i1 + 1):
        cur = t_ns[i] if i < i1 else g1
        if cur - prev > limit_ns:
            if count < starts.size:
                starts[count] = prev
                ends[count] = cur
            count += 1
        prev = cur
    return count


def _gaps(t_ns: np.ndarray, limit_ns: int, grid_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(start_ns, end_ns) of every stretch of the grid span without a sample for > limit_ns.

    A stretch starts at the last sample before the span when there is one, else at the span
    start, and the one after the last sample ends at the span end; each counts only when it
    exceeds the limit.
    """
    g0, g1 = np.int64(grid_ns[0]), np.int64(grid_ns[-1])
    # the samples in [g0, g1], found by numpy: numba's searchsorted (about 1 s) or a bisection in
    # a kernel of its own would compile in the first run
    i0, i1 = int(np.searchsorted(t_ns, g0, side="left")), int(np.searchsorted(t_ns, g1, side="right"))
    args = (t_ns, i0, i1, g0, g1, np.int64(limit_ns))
    count = _gap_kernel(*args, np.empty(0, np.int64), np.empty(0, np.int64))
    starts, ends = np.empty(count, np.int64), np.empty(count, np.int64)
    _gap_kernel(*args, starts, ends)
    return starts, ends


def changed_steps(z: np.ndarray) -> np.ndarray:
    """(N,) bool: the grid steps where at least one column of ``z`` (N, m) holds a finite value
    that differs from the step before (step 0: any finite value). A held value changes only when
    a new sample arrives, so these are the new samples that are not repeats (``fresh =
    "on_change"``); a value back after a stale gap (NaN before it) counts as changed."""
    finite = np.isfinite(z)
    out = np.zeros(z.shape[0], dtype=bool)
    if z.shape[0]:
        out[0] = finite[0].any()
        out[1:] = ((z[1:] != z[:-1]) & finite[1:]).any(axis=1)
    return out


follow_dependencies(__name__)  # the cached hold kernels are stamped with time_sanity's source too
