"""Time sanity (docs/algorithms.md section 8.1): where a log's channels are dense, and how large the
analysis grid may be.

A run of samples split from the rest of its channel by a gap over ``OUTLIER_GAP_SPACINGS`` median
spacings (and over ``OUTLIER_MIN_GAP_S``), holding at most ``OUTLIER_MAX_SHARE`` of the channel's
samples and lying outside the span of every channel's largest run by more than that gap, is an
outlying run (a clock jump, a bad timestamp): `dense_span` drops it and `outlier_warnings` says so.
A grid over ``MAX_GRID_STEPS`` steps is an InputError, computed before anything is allocated
(`grid`); ``start_s``/``end_s`` cut the grid to a window of the log (`check_window` first).
"""

from __future__ import annotations

import shlex
from collections.abc import Mapping

import numpy as np

from logscan.errors import InputError, UsageError

NS = 1_000_000_000
# A 24-hour log at 100 Hz is 8.64e6 steps; 1e8 steps of a 12-state trace would take tens of GB.
MAX_GRID_STEPS = 50_000_000
OUTLIER_GAP_SPACINGS = 1000  # a break in a channel: a gap over 1000 median spacings ...
OUTLIER_MIN_GAP_S = 10.0  # ... and over 10 s
OUTLIER_MAX_SHARE = 0.01  # an outlying run holds at most 1% of its channel's samples (at least one)
OUTLIER_MIN_SAMPLES = 50  # shorter channels are not searched for outliers
_INT64 = np.iinfo(np.int64)
MAX_WINDOW_S = _INT64.max / NS  # a --start/--end further from the log's start than any time can be


def outlying_runs(t_ns: np.ndarray) -> tuple[tuple[int, int], np.ndarray, np.ndarray, int]:
    """Split sorted unique times at breaks: gaps over max(OUTLIER_GAP_SPACINGS x the median
    spacing, OUTLIER_MIN_GAP_S). Returns (index range [lo, hi) of the largest run, lo and hi
    of the runs holding at most OUTLIER_MAX_SHARE of the samples (at least one sample), and the
    break gap in ns). Channels under OUTLIER_MIN_SAMPLES samples are one run."""
    n = int(t_ns.size)
    none = np.empty(0, np.int64)
    if n < OUTLIER_MIN_SAMPLES:
        return (0, n), none, none, 0
    # exact differences of sorted int64 times, even across the whole int64 range (mod 2**64)
    step = (t_ns[1:].view(np.uint64) - t_ns[:-1].view(np.uint64)).astype(np.float64)
    gap = max(OUTLIER_GAP_SPACINGS * float(np.median(step)), OUTLIER_MIN_GAP_S * NS)
    bounds = np.concatenate(([0], np.flatnonzero(step > gap) + 1, [n]))
    sizes = np.diff(bounds)
    main = int(np.argmax(sizes))
    tiny = sizes <= max(1.0, OUTLIER_MAX_SHARE * n)
    tiny[main] = False
    return (int(bounds[main]), int(bounds[main + 1])), bounds[:-1][tiny], bounds[1:][tiny], int(gap)


def dense_span(times: Mapping[str, np.ndarray], path: str) -> tuple[int, int, dict[str, np.ndarray], tuple[str, str]]:
    """Where the channels ``times`` (name -> sorted unique ns, each non-empty) are dense: their
    (first, last) ns once the outlying runs are dropped, the mask of samples to drop per channel
    that has some, and the channels that start first and end last."""
    if not times:
        raise no_span_error(path)
    runs: dict[int, tuple] = {}  # channels sharing one time array (a topic's fields) split it once
    found = {
        name: (t, runs[id(t)] if id(t) in runs else runs.setdefault(id(t), outlying_runs(t)))
        for name, t in times.items()
    }
    bulk_lo = min(int(t[main[0]]) for t, (main, *_) in found.values())
    bulk_hi = max(int(t[main[1] - 1]) for t, (main, *_) in found.values())
    drops: dict[str, np.ndarray] = {}
    for name, (t, (_, lo, hi, gap)) in found.items():
        # int64 bounds (Python ints: no overflow) outside which a tiny run is dropped
        below, above = max(bulk_lo - gap, int(_INT64.min)), min(bulk_hi + gap, int(_INT64.max))
        far = (t[hi - 1] < below) | (t[lo] > above)
        if not far.any():
            continue
        marks = np.zeros(t.size + 1, np.int64)
        marks[lo[far]] += 1
        marks[hi[far]] -= 1
        drops[name] = np.cumsum(marks[:-1]) > 0

    def kept(name: str) -> np.ndarray:
        return times[name][~drops[name]] if name in drops else times[name]

    first = min(found, key=lambda name: int(kept(name)[0]))
    last = max(found, key=lambda name: int(kept(name)[-1]))
    return int(kept(first)[0]), int(kept(last)[-1]), drops, (first, last)


def no_span_error(path: str) -> InputError:
    """Why a log has no span to analyse: none of its channels the span is taken from has a sample."""
    return InputError(
        "none of the profile's input and measurement channels has a finite sample",
        path=path,
        hint=f"check the profile's channels with `logscan inspect {shlex.quote(str(path))} --channels`",
    )


def outlier_warnings(dropped: Mapping[str, np.ndarray], kept: Mapping[str, int], start_ns: int) -> list[str]:
    """One warning per set of channels that lost the same outlying times (e.g. one CSV row):
    ``dropped`` name -> the times dropped (ns), ``kept`` name -> samples left."""
    same: dict[tuple, list[str]] = {}
    for name, times in dropped.items():
        same.setdefault((times.size, int(times[0]), int(times[-1])), []).append(name)
    warnings = []
    for names in same.values():
        times = dropped[names[0]]
        shown = ", ".join(repr(n) for n in names[:4]) + (f" and {len(names) - 4} more" if len(names) > 4 else "")
        warnings.append(
            f"channel{'s' if len(names) > 1 else ''} {shown}: {times.size} outlying "
            f"sample{'s' if times.size > 1 else ''} dropped at t={_when((times - start_ns) / NS)}, "
            f"far from the other {kept[names[0]]} samples (a clock jump or a bad timestamp); the grid spans "
            "where the channels are dense"
        )
    return warnings


def check_window(start_s: float | None, end_s: float | None) -> None:
    """UsageError unless --start/--end are finite and end > start (checked before any log is read)."""
    for flag, value in (("--start", start_s), ("--end", end_s)):
        if value is not None and not np.isfinite(value):
            raise UsageError(f"{flag} {value} is not a finite number of seconds since the log's start")
        if value is not None and abs(value) > MAX_WINDOW_S:
            raise UsageError(
                f"{flag} {value:g} is beyond any log: int64 nanoseconds span {MAX_WINDOW_S:.3g} s each way",
                hint="give --start/--end in seconds since the log's start",
            )
    if start_s is not None and end_s is not None and end_s <= start_s:
        raise UsageError(f"--end {end_s:g} must be after --start {start_s:g} (seconds since the log's start)")


def grid(
    first: int, last: int, rate_hz: float, window, start_ns: int, ends: tuple[str, str], path: str
) -> tuple[np.ndarray, int]:
    """The grid first + round(k * dt) ns for k = k0 .. k0 + N - 1, cut to ``window`` (start_s,
    end_s since ``start_ns``, either None); its size is checked before anything is allocated."""
    dt_ns = NS / rate_hz
    lo, hi = first, last
    if window is not None:
        start_s, end_s = window
        # Python ints: exact at epoch magnitudes (float64 ns there are 256 ns apart)
        if start_s is not None:
            lo = max(lo, start_ns + round(start_s * NS))
        if end_s is not None:
            hi = min(hi, start_ns + round(end_s * NS))
        if hi - lo < dt_ns:
            span = f"{(first - start_ns) / NS:.3f} .. {(last - start_ns) / NS:.3f} s"
            given = (("--start", start_s), ("--end", end_s))
            asked = " ".join(f"{flag} {value:g}" for flag, value in given if value is not None)
            raise InputError(
                f"the window {asked} holds no two grid steps of the log's channels ({span})",
                path=path,
                hint="give --start/--end in seconds since the log's start, within its span",
            )
    k0 = int(np.ceil((lo - first) / dt_ns - 1e-9))  # the full grid's first point in the window
    steps = (hi - first) / dt_ns - k0  # float: no overflow whatever the span or rate
    if not steps < MAX_GRID_STEPS:
        raise InputError(
            f"span {_span_text((hi - lo) / NS)} at {rate_hz:g} Hz = {_sci(steps)} steps, over the analysis "
            f"grid's limit of {_sci(MAX_GRID_STEPS)} (channels from {ends[0]!r} to {ends[1]!r})",
            path=path,
            hint="check the time unit or pass --start/--end",
        )
    n = max(int(np.floor(steps + 1e-9)) + 1, 0)
    return grid_points(first, k0 + np.arange(n), rate_hz), k0


def grid_points(first: int, k: np.ndarray, rate_hz: float) -> np.ndarray:
    """The grid's points ``k`` (indices from its first, ``first`` ns): g_k = g_0 + round(k * dt) in
    integer ns (exact for any log length float64 can index)."""
    return first + np.round(k * (NS / rate_hz)).astype(np.int64)


def grid_length(first: int, last: int, rate_hz: float) -> int:
    """The number of points of the whole grid from ``first`` to ``last`` ns (`grid` without a window)."""
    return int(np.floor((last - first) / (NS / rate_hz) + 1e-9)) + 1


def _span_text(seconds: float) -> str:
    for unit, size in (("days", 86_400.0), ("h", 3_600.0), ("min", 60.0)):
        if seconds >= 2 * size:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds:.3g} s"


def _sci(x: float) -> str:
    """1.0e8, not 1.0e+08."""
    mantissa, exponent = f"{x:.1e}".split("e") if np.isfinite(x) else (str(x), "0")
    return f"{mantissa}e{int(exponent)}"


def _when(seconds: np.ndarray) -> str:
    """Up to three times (s since the log's start), with days when they are far."""
    shown = [seconds[0], seconds[1], seconds[-1]] if seconds.size > 3 else list(seconds)
    text = [f"{s:.3f} s" + (f" ({s / 86_400.0:+.1f} days)" if abs(s) >= 86_400.0 else "") for s in shown]
    return ", ".join(text[:2]) + ", ..., " + text[2] if seconds.size > 3 else ", ".join(text)
