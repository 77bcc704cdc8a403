"""A channel's times across a whole file as the runs `time_sanity.outlying_runs` splits them into
(`TimeRuns`), found in passes over them a batch at a time (`time_runs`) instead of from one array:
a window of a long log (`Log.read_as_window`, `logscan.readers.mcap.window`) needs its file's dense
span, not every time (a 24-hour log's index times of the wanted channels are 263 MiB); they are
found once per file (`runs_of`: block mode's blocks share them). `dense_runs` is `dense_span` on
them; docs/algorithms.md section 8.1 says what a window read takes from them.

The only order statistic `outlying_runs` takes is the median spacing; it is selected exactly over
the bits of the spacings as float64 (a positive float's bits order as its value), 20 bits a pass,
until the bits left cannot be set (an integer spacing under 2**53 ns has no bits below its
magnitude): two passes for spacings under 2**29 ns (0.54 s), a third for longer ones. Memory:
a batch of times and a histogram of 2**20 counts, whatever the log's length.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass

import numpy as np

from logscan.log import WholeTimes
from logscan.timebase.time_sanity import (
    NS,
    OUTLIER_GAP_SPACINGS,
    OUTLIER_MAX_SHARE,
    OUTLIER_MIN_GAP_S,
    OUTLIER_MIN_SAMPLES,
    no_span_error,
)

_BITS = 20  # bits of the spacings' float64 patterns selected per pass: 2**20 counts (8 MiB)
_INT64 = np.iinfo(np.int64)
_MIN_GAP = OUTLIER_MIN_GAP_S * NS  # every break is wider than this (float, as `outlying_runs` compares)


@dataclass
class TimeRuns:
    """A channel's sorted unique times (``n`` of them, ``first`` .. ``last`` ns) split at breaks
    wider than ``gap`` ns into runs (``starts``/``ends``: each one's first and last time,
    ``sizes``); ``main``, the largest (the first of equals); ``tiny``, those `outlying_runs` may
    drop. ``fetch(lo, hi)``: the times from ``lo`` to ``hi`` ns (a run's, when it is dropped)."""

    n: int
    first: int
    last: int
    gap: int
    starts: np.ndarray
    ends: np.ndarray
    sizes: np.ndarray
    main: int
    tiny: np.ndarray
    fetch: Callable[[int, int], np.ndarray]

    @property
    def size(self) -> int:
        return self.n


Batches = Callable[[], Iterator[np.ndarray]]  # each call: the times again, sorted unique batches in order


def runs_of(whole: WholeTimes) -> TimeRuns | None:
    """The runs of a topic's times across its file (`time_runs`), found once and kept with them."""
    if whole.runs is None:
        whole.runs = time_runs(whole.batches, whole.fetch)
    return whole.runs


def time_runs(batches: Batches, fetch: Callable[[int, int], np.ndarray]) -> TimeRuns | None:
    """The runs of the times ``batches`` gives (sorted, unique, each batch after the one before),
    as `outlying_runs` finds them in the whole array; None when there are none."""
    n, first, last, wide = _first_pass(batches)
    if n == 0:
        return None
    if n < OUTLIER_MIN_SAMPLES:  # one run, as `outlying_runs` leaves it
        one = np.array([first], dtype=np.int64), np.array([last], dtype=np.int64)
        return TimeRuns(n, first, last, 0, *one, np.array([n]), 0, np.zeros(1, dtype=bool), fetch)
    gap = max(OUTLIER_GAP_SPACINGS * median_step(batches, n - 1), _MIN_GAP)
    at, steps, before, after = wide
    cut = steps > gap
    bounds = np.concatenate(([0], at[cut] + 1, [n]))
    sizes = np.diff(bounds)
    starts = np.concatenate(([first], after[cut])).astype(np.int64)
    ends = np.concatenate((before[cut], [last])).astype(np.int64)
    main = int(np.argmax(sizes))
    tiny = sizes <= max(1.0, OUTLIER_MAX_SHARE * n)
    tiny[main] = False
    return TimeRuns(n, first, last, int(gap), starts, ends, sizes, main, tiny, fetch)


def _first_pass(batches: Batches) -> tuple[int, int, int, tuple[np.ndarray, ...]]:
    """(count, first, last, and the steps wider than any break can be narrower than: where (index
    of the time before), how wide (float64), the times either side)."""
    n, first, previous = 0, 0, None
    parts: list[tuple[np.ndarray, ...]] = []
    for t in batches():
        if not t.size:
            continue
        joined = t if previous is None else np.concatenate(([previous], t))
        steps = _steps(joined)
        wide = np.flatnonzero(steps > _MIN_GAP)
        if wide.size:
            offset = n - (0 if previous is None else 1)
            parts.append((wide + offset, steps[wide], joined[wide], joined[wide + 1]))
        if previous is None:
            first = int(t[0])
        n += int(t.size)
        previous = int(t[-1])
    if previous is None:
        return 0, 0, 0, ()
    empty = (np.empty(0, np.int64), np.empty(0), np.empty(0, np.int64), np.empty(0, np.int64))
    wide_steps = tuple(np.concatenate(cols) for cols in zip(*parts)) if parts else empty
    return n, first, previous, wide_steps


def _steps(t: np.ndarray) -> np.ndarray:
    """The spacings of sorted int64 times as `outlying_runs` takes them (exact mod 2**64, float64)."""
    return (t[1:].view(np.uint64) - t[:-1].view(np.uint64)).astype(np.float64)


def median_step(batches: Batches, m: int) -> float:
    """``np.median`` of the ``m`` spacings of the times ``batches`` gives, without holding them."""
    k = (m - 1) // 2
    low_bits, below, alike = _select_bits(batches, k)
    low = _as_float(low_bits)
    if m % 2:
        return float(np.median(np.array([low])))
    # the next spacing: as wide, or the least spacing wider than the k-th
    high = low if k + 1 < below + alike else _as_float(_least_above(batches, low_bits))
    return float(np.median(np.array([low, high])))


def _as_float(bits: int) -> float:
    return float(np.array([bits], dtype=np.uint64).view(np.float64)[0])


def _select_bits(batches: Batches, k: int) -> tuple[int, int, int]:
    """The float64 bits of the k-th least spacing (0-based), how many spacings are less, and how
    many have its bits: the bits above ``top`` are known (``prefix``), each pass counts the
    spacings under them by the next `_BITS` bits."""
    prefix, top, below = 0, 64, 0
    while True:
        shift = max(0, top - _BITS)
        counts = np.zeros(1 << (top - shift), dtype=np.int64)
        for steps in _step_bits(batches):
            if top < 64:
                steps = steps[(steps >> np.uint64(top)) == np.uint64(prefix)]
            part = (steps >> np.uint64(shift)) & np.uint64(counts.size - 1)
            counts += np.bincount(part.astype(np.intp), minlength=counts.size)
        cumulative = np.cumsum(counts)
        bin_ = int(np.searchsorted(cumulative, k - below, side="right"))
        below += int(cumulative[bin_ - 1]) if bin_ else 0
        prefix, top = (prefix << (top - shift)) | bin_, shift
        magnitude = ((prefix << shift) >> 52 & 0x7FF) - 1023
        if shift == 0 or shift <= 52 - magnitude:  # an integer spacing under 2**53 sets no lower bit
            return prefix << shift, below, int(counts[bin_])


def _step_bits(batches: Batches) -> Iterator[np.ndarray]:
    """The float64 bits (uint64) of the spacings, a batch at a time."""
    previous = None
    for t in batches():
        if t.size:
            joined = t if previous is None else np.concatenate(([previous], t))
            yield _steps(joined).view(np.uint64)
            previous = int(t[-1])


def _least_above(batches: Batches, bits: int) -> int:
    least = np.iinfo(np.uint64).max
    for steps in _step_bits(batches):
        wider = steps[steps > np.uint64(bits)]
        if wider.size:
            least = min(least, int(wider.min()))
    return least


def dense_runs(runs: Mapping[str, TimeRuns], path: str) -> tuple[int, int, dict[str, np.ndarray], tuple[str, str]]:
    """`dense_span` of channels known by their runs (name -> `TimeRuns`): (first, last) ns once
    the outlying runs are dropped, the runs to drop per channel that has some (bool per run), and
    the channels that start first and end last."""
    if not runs:
        raise no_span_error(path)
    bulk_lo = min(int(r.starts[r.main]) for r in runs.values())
    bulk_hi = max(int(r.ends[r.main]) for r in runs.values())
    drops: dict[str, np.ndarray] = {}
    for name, r in runs.items():
        below, above = max(bulk_lo - r.gap, int(_INT64.min)), min(bulk_hi + r.gap, int(_INT64.max))
        far = r.tiny & ((r.ends < below) | (r.starts > above))
        if far.any():
            drops[name] = far

    def kept(name: str) -> tuple[int, int]:
        r = runs[name]
        if name not in drops:
            return r.first, r.last
        left = np.flatnonzero(~drops[name])
        return int(r.starts[left[0]]), int(r.ends[left[-1]])

    first = min(runs, key=lambda name: kept(name)[0])
    last = max(runs, key=lambda name: kept(name)[1])
    return kept(first)[0], kept(last)[1], drops, (first, last)


def dropped_times(r: TimeRuns, drop: np.ndarray) -> np.ndarray:
    """The times of the runs ``drop`` (bool per run) of ``r``, read again (`TimeRuns.fetch`)."""
    parts: Iterable[np.ndarray] = (r.fetch(int(r.starts[k]), int(r.ends[k])) for k in np.flatnonzero(drop).tolist())
    return np.concatenate(list(parts))
