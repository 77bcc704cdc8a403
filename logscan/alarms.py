"""Turning a statistic and its threshold series into alarm intervals (the one shared alarm logic).

Every detector produces a statistic series and upper (and/or lower) threshold series on the grid;
``alarm_intervals`` turns them into ``AlarmInterval`` objects with persistence, hold-off, minimum
duration and warm-up. Rules, in order:

1. A sample is *judged* where ``valid`` is True (default: everywhere) and it is not in warm-up.
   Samples that are not judged are skipped: they neither raise nor break a run of exceedances
   (e.g. a 10 Hz group on a 100 Hz grid is judged at its update steps only). Warm-up samples are
   not judged and DO break a run: an alarm never contains a warm-up sample.
2. A judged sample *exceeds* when ``statistic > upper`` or ``statistic < lower``, or when the
   statistic is not finite (NaN, +-inf: a detector that cannot compute its statistic on a valid
   sample has seen something wrong). A non-finite threshold never causes an exceedance by itself
   (that bound is "not defined here"), but a non-finite statistic still does.
3. Persistence: an alarm starts at the ``n_persist``-th consecutive exceeding judged sample;
   ``start`` is that sample's time, ``first_exceed`` the time of the run's first exceedance.
4. Hold-off: once on, the alarm stays on until there is no exceedance for more than
   ``hold_off_s`` seconds: any later exceedance (even a single sample) at most ``hold_off_s``
   after the previous one extends it. ``end`` is the time of the alarm's last exceeding sample,
   so ``end - start`` is the raised duration (0 for a one-sample alarm).
5. Minimum duration: alarms with ``end - start < min_duration_s`` are dropped.
6. Seen from a time (``from_t``: a window's first step, the grid before it a lead-in judged for
   rules 3-5 only): an alarm that ends before it is dropped; one under way there starts at its first
   exceedance from it, and its first exceedance, peak and count are those from it on. So a window
   shows the alarms the whole log has in it, even where their persistence began before it.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from typing import NamedTuple, overload

import numpy as np
from numpy.typing import ArrayLike

from logscan.errors import InternalError
from logscan.json_policy import jsonable


@dataclass
class AlarmInterval:
    """One alarm: [start, end] seconds on the analysis grid, and where it peaked.

    peak_value / peak_threshold: the statistic and the threshold it crossed at the sample with the
    largest excess over its threshold; peak_ratio = peak_value / peak_threshold (None when that
    ratio is undefined: threshold 0 or non-finite, or a non-finite statistic).
    bound: which bound the peak crossed, "upper", "lower" or "nonfinite".
    """

    start: float
    end: float
    first_exceed: float
    peak_time: float
    peak_value: float
    peak_threshold: float | None
    peak_ratio: float | None
    bound: str
    n_exceed: int  # exceeding samples inside the alarm
    signal: str = ""
    detector: str = ""
    # a sequential test's estimate of when the change began (e.g. the CUSUM's last zero before the
    # crossing), so latency can be read back to the onset; None: the detector gives none
    change_time: float | None = None

    @property
    def duration(self) -> float:
        return self.end - self.start

    def to_dict(self) -> dict:
        out = asdict(self)
        out["duration"] = self.duration
        return jsonable(out)


# Tolerance (seconds) for time comparisons, so a hold-off of exactly two grid periods is not
# lost to floating-point rounding of the grid times.
_TIME_EPS = 1e-9


@overload
def _as_series(name: str, value: None, n: int) -> None: ...
@overload
def _as_series(name: str, value: ArrayLike, n: int) -> np.ndarray: ...
def _as_series(name: str, value: ArrayLike | None, n: int) -> np.ndarray | None:
    if value is None:
        return None
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        return np.broadcast_to(arr, (n,))  # read only: a view, not n copies
    if arr.shape != (n,):
        raise InternalError(f"alarm_intervals: {name} has shape {arr.shape}, expected ({n},) or a scalar")
    return arr


def sample_masks(t: np.ndarray, valid, warmup, warmup_s: float) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(judged, in_warmup) boolean masks over the grid (rule 1 of the module docstring: a sample is
    judged where it is valid; not in warm-up), None for "every sample is judged" and "no sample is
    in warm-up": the usual cases cost no (N,) pass."""
    n = t.size
    judged = None
    if valid is not None:
        judged = np.asarray(valid, dtype=bool)
        if judged.shape != (n,):
            raise InternalError(f"alarm_intervals: valid has shape {judged.shape}, expected ({n},)")
    in_warmup = None
    if warmup is not None:
        if isinstance(warmup, (int, np.integer)) and not isinstance(warmup, bool):
            in_warmup = np.zeros(n, dtype=bool)
            in_warmup[: max(int(warmup), 0)] = True
        else:
            in_warmup = np.asarray(warmup, dtype=bool)
            if in_warmup.shape != (n,):
                raise InternalError(f"alarm_intervals: warmup mask has shape {in_warmup.shape}, expected ({n},)")
    if warmup_s > 0 and n:
        leading = t < t[0] + warmup_s - _TIME_EPS
        in_warmup = leading if in_warmup is None else in_warmup | leading
    return judged, in_warmup


def judged_counts(
    t: np.ndarray, judged: np.ndarray | None, alarmable: np.ndarray | None, from_t: float | None
) -> tuple[int, int]:
    """(the judged samples that can raise an alarm (not in warm-up), the judged samples), counted
    over the samples alarms are seen on (rule 6: from ``from_t``; a lead-in's are judged elsewhere);
    None masks: every sample. Their ratio is the statistic's judged share (block mode sums them)."""
    rows = slice(0 if from_t is None else int(np.searchsorted(t, from_t - _TIME_EPS)), t.size)

    def count(mask: np.ndarray | None) -> int:
        return rows.stop - rows.start if mask is None else int(np.count_nonzero(mask[rows]))

    return count(alarmable), count(judged)


def alarm_intervals(
    t: np.ndarray,
    statistic: np.ndarray,
    upper=None,
    lower=None,
    *,
    n_persist: int = 1,
    hold_off_s: float = 0.0,
    min_duration_s: float = 0.0,
    warmup=None,
    warmup_s: float = 0.0,
    valid=None,
    signal: str = "",
    detector: str = "",
    from_t: float | None = None,
) -> list[AlarmInterval]:
    """Alarm intervals of ``statistic`` against ``upper`` / ``lower`` (scalars or (N,) series).

    warmup: an (N,) bool mask of samples where no alarm may be raised, or an int number of leading
    samples; warmup_s: leading seconds (from t[0]) of warm-up, combined with ``warmup``.
    valid: (N,) bool, samples to judge at all (others are skipped). from_t: only the alarms seen
    from this time on. See the module docstring for the exact rules.
    """
    t = np.asarray(t, dtype=np.float64)
    if t.ndim != 1:
        raise InternalError(f"alarm_intervals: t must be 1-D, got shape {t.shape}")
    judged, in_warmup = sample_masks(t, valid, warmup, warmup_s)
    return judged_alarms(
        t,
        statistic,
        upper,
        lower,
        judged,
        in_warmup,
        n_persist=n_persist,
        hold_off_s=hold_off_s,
        min_duration_s=min_duration_s,
        signal=signal,
        detector=detector,
        from_t=from_t,
    )


def judged_alarms(
    t: np.ndarray,
    statistic: np.ndarray,
    upper,
    lower,
    judged: np.ndarray | None,
    in_warmup: np.ndarray | None,
    *,
    n_persist: int = 1,
    hold_off_s: float = 0.0,
    min_duration_s: float = 0.0,
    signal: str = "",
    detector: str = "",
    from_t: float | None = None,
) -> list[AlarmInterval]:
    """`alarm_intervals` on the grid times ``t`` (float64) with its masks made (`sample_masks`);
    ``from_t``: the alarms seen from that time on (rule 6)."""
    if t.ndim != 1:
        raise InternalError(f"alarm_intervals: t must be 1-D, got shape {t.shape}")
    n = t.size
    x = _as_series("statistic", statistic, n)
    hi = _as_series("upper", upper, n)
    lo = _as_series("lower", lower, n)
    if hi is None and lo is None:
        raise InternalError("alarm_intervals: give an upper or a lower threshold")
    if n_persist < 1:
        raise InternalError(f"alarm_intervals: n_persist must be >= 1, got {n_persist}")
    samples = _exceedances(t, x, hi, lo, judged, in_warmup)
    if samples is None:
        return []
    spans = _alarm_spans(samples, n_persist, hold_off_s, min_duration_s)
    if spans is not None and from_t is not None:
        spans = _seen_from(samples, spans, from_t)
    if spans is None:
        return []
    return _intervals(samples, *spans, signal, detector)


class _Exceedances(NamedTuple):
    """The exceeding samples (rule 2), in grid order. Runs, chains, peaks and counts (rules 3-5)
    involve exceeding samples only: the other samples an alarm may hold (judged or in warm-up, the
    "considered" ones) matter only by their number between two exceedances, held here as ranks."""

    steps: np.ndarray  # each exceedance's grid index
    rank: np.ndarray  # its position among the considered samples: consecutive ranks are one run
    warm_before: np.ndarray  # warm-up samples before it: one between two exceedances breaks a chain
    x: np.ndarray  # the statistic, (N,)
    t: np.ndarray  # the times, (N,)
    hi: np.ndarray | None  # the upper threshold, (N,) (None: none given)
    lo: np.ndarray | None  # the lower threshold, (N,) (None: none given)


def _exceedances(t, x, hi, lo, judged: np.ndarray | None, in_warmup: np.ndarray | None) -> _Exceedances | None:
    """The judged samples over or under a bound or not finite, out of warm-up (rule 2); None when
    none exceeds. A few boolean passes over the grid, no copy of the series."""
    exceed = _outside(x, hi, lo)
    if judged is not None:
        exceed &= judged
    if in_warmup is not None:
        exceed &= ~in_warmup
    index = np.flatnonzero(exceed)
    if index.size == 0:
        return None
    if judged is None:  # every sample is considered
        rank = index
    else:
        considered = judged if in_warmup is None else judged | in_warmup
        rank = np.searchsorted(np.flatnonzero(considered), index)
    warm_before = np.zeros(index.size, np.int64) if in_warmup is None else _count_in_prefix(in_warmup, index)
    return _Exceedances(index, rank, warm_before, x, t, hi, lo)


def _outside(x: np.ndarray, hi: np.ndarray | None, lo: np.ndarray | None) -> np.ndarray:
    """(N,) bool: over ``hi``, under ``lo`` or not finite. Finite constant bounds (the usual case)
    take two comparisons: not (lo <= x <= hi), a missing bound being infinite, holds exactly then."""
    with np.errstate(invalid="ignore"):
        if _finite_constant(hi) and _finite_constant(lo):
            inside = x <= hi[0] if hi is not None else x < np.inf
            inside &= x >= lo[0] if lo is not None else x > -np.inf
            return np.logical_not(inside, out=inside)
        exceed = ~np.isfinite(x)
        if hi is not None:
            exceed |= x > hi
        if lo is not None:
            exceed |= x < lo
    return exceed


def _finite_constant(bound: np.ndarray | None) -> bool:
    """Whether a bound is absent or one finite value on every sample (a broadcast scalar)."""
    return bound is None or (bound.strides == (0,) and bound.size > 0 and bool(np.isfinite(bound[0])))


def _count_in_prefix(mask: np.ndarray, index: np.ndarray) -> np.ndarray:
    """How many of ``mask`` are True before each of ``index`` (ascending)."""
    return np.searchsorted(np.flatnonzero(mask), index)


def _alarm_spans(
    samples: _Exceedances, n_persist: int, hold_off_s: float, min_duration_s: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(start, last, first exceedance) of each alarm as positions among the exceedances, after
    persistence, hold-off and minimum duration (rules 3-5); None when no alarm is left."""
    ts = samples.t[samples.steps]
    # Runs of consecutive exceedances: a run starts where the rank jumps (a considered sample that
    # does not exceed, or a warm-up one, lies between).
    run_start = np.flatnonzero(np.concatenate(([True], np.diff(samples.rank) != 1)))
    run_last = np.concatenate((run_start[1:] - 1, [samples.steps.size - 1]))
    run_len = run_last - run_start + 1
    # A run is bridged to the previous one when the gap between exceedances is <= hold_off_s and
    # no warm-up sample lies between them; a chain is a maximal sequence of bridged runs.
    gap = ts[run_start[1:]] - ts[run_last[:-1]]
    warm_between = samples.warm_before[run_start[1:]] > samples.warm_before[run_last[:-1]]
    new_chain = np.concatenate(([True], (gap > hold_off_s + _TIME_EPS) | warm_between))
    chain = np.cumsum(new_chain) - 1
    chain_last_run = np.concatenate((np.flatnonzero(new_chain)[1:] - 1, [run_start.size - 1]))
    # Within each chain the alarm starts at the first run long enough to persist and lasts to the
    # chain's last exceedance.
    qualifying = np.flatnonzero(run_len >= n_persist)
    if qualifying.size == 0:
        return None
    chains, first = np.unique(chain[qualifying], return_index=True)
    first_run = qualifying[first]
    a_first = run_start[first_run]
    a_start = a_first + n_persist - 1
    a_last = run_last[chain_last_run[chains]]
    durations = ts[a_last] - ts[a_start]
    keep_alarm = durations >= min_duration_s - _TIME_EPS

    i0, i1, f0 = a_start[keep_alarm], a_last[keep_alarm], a_first[keep_alarm]
    if i0.size == 0:
        return None
    return i0, i1, f0


def _seen_from(
    samples: _Exceedances, spans: tuple[np.ndarray, np.ndarray, np.ndarray], from_t: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The alarm spans (positions among the exceedances) seen from ``from_t`` on (rule 6): those
    ending before it dropped, the others' start and first exceedance no earlier than the first
    exceedance at or after it; None when none is left."""
    i0, i1, f0 = spans
    first_from = int(np.searchsorted(samples.t[samples.steps], from_t - _TIME_EPS, side="left"))
    keep = i1 >= first_from
    if not keep.any():
        return None
    return np.maximum(i0[keep], first_from), i1[keep], np.maximum(f0[keep], first_from)


def _intervals(
    samples: _Exceedances, i0: np.ndarray, i1: np.ndarray, f0: np.ndarray, signal: str, detector: str
) -> list[AlarmInterval]:
    """The alarms over exceedances [i0, i1] (first exceedance f0) with the peak of each."""
    x, his, los = samples.x, samples.hi, samples.lo

    def excess(position: np.ndarray) -> np.ndarray:
        """Excess over the crossed bound at these exceedances, which picks the peak sample;
        non-finite statistics rank highest. (Every sample between an alarm's exceedances that does
        not exceed ranks lowest: it is never its peak.)"""
        at = samples.steps[position]
        v = x[at]
        with np.errstate(invalid="ignore"):
            above = v - his[at] if his is not None else np.full(at.size, -np.inf)
            below = los[at] - v if los is not None else np.full(at.size, -np.inf)
        return np.where(np.isfinite(v), np.fmax(above, below), np.inf)

    peak = samples.steps[_segment_argmax(excess, i0, i1)]
    value = x[peak]
    is_nonfinite = ~np.isfinite(value)
    with np.errstate(invalid="ignore"):
        over = value > his[peak] if his is not None else np.zeros(peak.size, dtype=bool)
    crossed_upper = over | (is_nonfinite & (his is not None))
    threshold = np.where(crossed_upper, _at(his, peak), _at(los, peak))
    bound = np.where(is_nonfinite, "nonfinite", np.where(over, "upper", "lower"))
    # a finite value far beyond a small threshold: the ratio overflows to inf (the JSON's null)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        ratio = value / threshold
    ratio_ok = np.isfinite(value) & np.isfinite(threshold) & (threshold != 0.0)
    n_exceed = i1 - f0 + 1  # every sample from the first exceedance to the last that exceeds
    ts = samples.t
    columns = zip(
        ts[samples.steps[i0]].tolist(),
        ts[samples.steps[i1]].tolist(),
        ts[samples.steps[f0]].tolist(),
        ts[peak].tolist(),
        value.tolist(),
        np.where(np.isfinite(threshold), threshold, np.nan).tolist(),
        np.isfinite(threshold).tolist(),
        ratio.tolist(),
        ratio_ok.tolist(),
        bound.tolist(),
        n_exceed.tolist(),
    )
    return [
        AlarmInterval(
            start, end, first, t_peak, v, thr if thr_ok else None, r if r_ok else None, b, int(k), signal, detector
        )
        for start, end, first, t_peak, v, thr, thr_ok, r, r_ok, b, k in columns
    ]


def _at(series: np.ndarray | None, index: np.ndarray) -> np.ndarray:
    return np.full(index.size, np.nan) if series is None else series[index]


def _segment_argmax(values_at, first: np.ndarray, last: np.ndarray) -> np.ndarray:
    """Index of the (first) maximum of values over [first[k], last[k]] for each disjoint segment k;
    ``values_at(index)`` gives the values at those indices (only the segments' are computed)."""
    lengths = last - first + 1
    segment = np.repeat(np.arange(first.size), lengths)
    offsets = np.concatenate(([0], np.cumsum(lengths)[:-1]))
    index = np.arange(lengths.sum()) - np.repeat(offsets, lengths) + np.repeat(first, lengths)
    # sort by segment, then by descending value, then by position: the first row of each segment
    order = np.lexsort((index, -values_at(index), segment))
    return index[order[offsets]]


def merge_close(intervals: Iterable[AlarmInterval], gap_s: float, *, by_signal: bool = True) -> list[AlarmInterval]:
    """Merge alarms whose gap (next start - previous end) is at most ``gap_s`` seconds.

    by_signal=True merges only alarms of the same (detector, signal); False merges across signals
    and names the merged alarm's signals "a,b" (in order of first appearance). The merged alarm
    keeps the earliest start and first_exceed, the latest end, the summed exceedance count and the
    peak of the part with the largest peak ratio (non-finite peaks first). Result sorted by start.
    """
    items = sorted(intervals, key=lambda a: (a.start, a.end))
    groups: dict[tuple[str, str], list[AlarmInterval]] = {}
    for alarm in items:
        key = (alarm.detector, alarm.signal) if by_signal else ("", "")
        groups.setdefault(key, []).append(alarm)
    merged: list[AlarmInterval] = []
    for parts in groups.values():
        current = [parts[0]]
        end = parts[0].end
        for alarm in parts[1:]:
            if alarm.start - end <= gap_s + _TIME_EPS:
                current.append(alarm)
                end = max(end, alarm.end)
            else:
                merged.append(_combine(current))
                current, end = [alarm], alarm.end
        merged.append(_combine(current))
    return sorted(merged, key=lambda a: (a.start, a.end, a.detector, a.signal))


def peak_rank(alarm: AlarmInterval) -> float:
    """How high an alarm peaked, to rank alarms by: its peak/threshold; a non-finite statistic
    highest, an undefined ratio lowest."""
    if alarm.bound == "nonfinite":
        return np.inf
    return alarm.peak_ratio if alarm.peak_ratio is not None else -np.inf


def true_runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(first index, index after the last) of each run of True in the 1-D ``mask``."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], np.asarray(mask, dtype=np.int8), [0]))))
    return edges[::2], edges[1::2]


def _joined(names: Sequence[str]) -> str:
    return ",".join(dict.fromkeys(n for n in names if n))


def _combine(parts: list[AlarmInterval]) -> AlarmInterval:
    if len(parts) == 1:
        return parts[0]
    peak = max(parts, key=peak_rank)
    return AlarmInterval(
        start=min(a.start for a in parts),
        end=max(a.end for a in parts),
        first_exceed=min(a.first_exceed for a in parts),
        peak_time=peak.peak_time,
        peak_value=peak.peak_value,
        peak_threshold=peak.peak_threshold,
        peak_ratio=peak.peak_ratio,
        bound=peak.bound,
        n_exceed=sum(a.n_exceed for a in parts),
        signal=_joined([a.signal for a in parts]),
        detector=_joined([a.detector for a in parts]),
        change_time=min((a.change_time for a in parts if a.change_time is not None), default=None),
    )
