"""One block's analysis reduced to what the merged verdict and report read (`reduce_block`): its
detectors' series on the grid kept as an envelope of buckets (`envelope`), its filter's series and
aligned signals freed. Block mode (`logscan.pipeline.blocks`) folds each such analysis into the
merged state (`logscan.pipeline.block_fold`) and does not keep it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
from numba import njit

from logscan.alarms import AlarmInterval
from logscan.numba_cache import follow_dependencies
from logscan.pipeline.block_alignment import alignment_figures
from logscan.pipeline.raw_lead import cut_rows
from logscan.report.context_join import own_part
from logscan.report.kept_views import kept_rows
from logscan.report.sensor_figures import REDUCED_POINTS
from logscan.results import Band, DetectorResult
from logscan.verdict.coverage import own_steps

# Each series of the merged log keeps about this many points (two per bucket: the report draws at
# most `logscan.report.decimate.DEFAULT_MAX_POINTS`, 5000, of a series, so ten times that leaves
# its own decimation the choice of which to draw)
MERGED_POINTS = 50_000


def bucket_width(total_steps: int) -> int:
    """Grid steps per bucket for a log of ``total_steps`` (1: every step kept)."""
    return max(1, -(-int(total_steps) * 2 // MERGED_POINTS))


def envelope(values: np.ndarray, width: int) -> np.ndarray:
    """(2 * ceil(N / width), ...) from (N, ...): each bucket of ``width`` steps as its two extremes
    (NaN skipped) in the order they occur, so a peak or a dip of the series survives; a bucket of
    NaN only stays NaN (a gap still breaks the line). Booleans: whether any step of the bucket is
    True, twice. ``width`` 1: ``values`` as they are."""
    values = np.asarray(values)
    if width <= 1:
        return values
    n = values.shape[0]
    buckets = -(-n // width)
    if values.dtype == bool:
        padded = np.zeros((buckets * width, *values.shape[1:]), dtype=bool)
        padded[:n] = values
        anyone = padded.reshape(buckets, width, *values.shape[1:]).any(axis=1)
        return np.repeat(anyone, 2, axis=0)
    columns = np.ascontiguousarray(values.reshape(n, -1), dtype=np.float64)
    pairs = np.empty((2 * buckets, columns.shape[1]))
    _extremes_in_order(columns, width, pairs)
    return pairs.reshape(2 * buckets, *values.shape[1:]).astype(values.dtype, copy=False)


@njit(cache=True)
def _extremes_in_order(values, width, pairs):  # pragma: no cover - compiled
    """Per column of ``values`` (N, K) and bucket of ``width`` rows: its lowest and highest value,
    the first of each where several tie, NaN taken as +inf for the lowest and -inf for the highest
    (a bucket of NaN only: its first value, NaN, twice), into ``pairs`` (2 x buckets, K) in the
    order the two occur, the lowest first where they are one step."""
    n, columns = values.shape
    for c in range(columns):
        for b in range(pairs.shape[0] // 2):
            first = b * width
            low_at = high_at = first
            low, high = np.inf, -np.inf
            for i in range(first, min(first + width, n)):
                v = values[i, c]
                if v != v:  # NaN: neither extreme
                    continue
                if v < low:
                    low, low_at = v, i
                if v > high:
                    high, high_at = v, i
            if low_at > high_at:
                pairs[2 * b, c], pairs[2 * b + 1, c] = values[high_at, c], values[low_at, c]
            else:
                pairs[2 * b, c], pairs[2 * b + 1, c] = values[low_at, c], values[high_at, c]


def envelope_times(t: np.ndarray, width: int) -> np.ndarray:
    """The times of `envelope`'s points: each bucket's first and last step."""
    if width <= 1:
        return t
    first = np.arange(0, t.size, width)
    last = np.minimum(first + width - 1, t.size - 1)
    return np.stack([t[first], t[last]], axis=1).reshape(-1)


def reduced_result(result: DetectorResult, n: int, width: int) -> DetectorResult:
    """``result`` with each of its series on the grid (first axis ``n``) as its envelope, their
    samples and finite ones counted first (``series_counts``: the summary's); its other arrays (not
    on the grid) are left out: what they index is the block's, not the log's."""

    def on_grid(arrays: dict) -> dict:
        return {k: envelope(v, width) for k, v in arrays.items() if np.shape(v)[:1] == (n,)}

    def band(b: Band) -> Band:
        upper = None if b.upper is None else envelope(b.upper, width)
        return Band(upper=upper, lower=None if b.lower is None else envelope(b.lower, width))

    judged = {k: envelope(np.asarray(v, dtype=bool), width) for k, v in result.judged.items() if np.shape(v) == (n,)}
    series = {k: v for k, v in result.series.items() if np.shape(v)[:1] == (n,)}
    return replace(
        result,
        series=on_grid(series),
        series_counts={k: (np.size(v), int(np.count_nonzero(np.isfinite(v)))) for k, v in series.items()},
        thresholds={k: band(b) for k, b in result.thresholds.items()},
        extras=on_grid(result.extras),
        judged=judged,
    )


def reduce_block(
    analysis,
    width: int,
    from_s: float | None = None,
    points: int = REDUCED_POINTS,
    focus_rows: Callable[[str], int] | None = None,
    quoted: Sequence[AlarmInterval] = (),
    carried: Sequence[AlarmInterval] = (),
):
    """The block's analysis, in place, reduced to what the merged one reads: the detectors' series
    as envelopes on the envelope's times (the block's grid ``run.t``), the report's innovations as
    the rows its sensor figures draw with at most ``points`` per series and ``focus_rows(group)``
    inside zoom windows (`kept_rows`; None: all there; and those of ``quoted``, the alarm its first
    incident quotes, `first_quoted`, and of ``carried``, the block before's: the windows a headline
    may open on), the filter's
    trace, aligned signals, raw channels, the context's true state and the suspension's steps freed;
    ``from_s``: the block's own first step, the steps before it a lead-in for the detectors (their
    alarms already seen from it), cut off. Returns it."""
    prepared = analysis.prepared
    t = prepared.run.t
    first = 0 if from_s is None else own_steps(t, from_s)
    # the gate and gap figures of its own steps, before the aligned signals go (the log's lines sum them)
    analysis.alignment = alignment_figures(prepared.run, getattr(prepared.profile, "measurements", {}), first)
    if prepared.trace is not None and first:  # the filter's counts of the block's own steps
        prepared._filter_summary = {**prepared.filter_summary(), **prepared.trace.summary(first)}
    prepared.release_series()  # the filter's counts stay (`filter_summary`)
    if first:
        _cut_lead(analysis, first)
    n = t.size - first
    prepared.grid = (n, float(prepared.run.dt))
    analysis.results = [reduced_result(result, n, width) for result in analysis.results]
    innovations = prepared.innovations  # now, with the detectors' full-rate series freed (the group's view is made)
    if innovations is not None:  # the alarms of the block's own steps: their zoom windows kept in full
        alarms = [a for result in analysis.results for a in result.alarms]
        heads = [*quoted, *_continued(carried, alarms, float(t[first]))]
        innovations = kept_rows(innovations, t, first, alarms, points, focus_rows, heads)
    times = envelope_times(t[first:], width)
    prepared.run = replace(prepared.run, t=times, u=np.empty((times.size, 0)), ground=None, ground_around=None)
    prepared.raw, prepared.context, prepared.innovations = {}, own_part(prepared.context), innovations
    analysis.suspended = None
    return analysis


def first_quoted(analysis, from_s: float) -> list[AlarmInterval]:
    """The alarm quoted by the block's first incident that reaches its own steps (from ``from_s``):
    the window a report's headline may open on (none: empty)."""
    return [i.quoted for i in analysis.incidents if i.quoted is not None and i.quoted.end >= from_s][:1]


def _continued(carried: Sequence[AlarmInterval], alarms: Sequence[AlarmInterval], from_s: float) -> list:
    """The block before's quoted ``carried`` alarms, each to the end of the same check's alarm going
    on from this block's first step (``from_s``): as the merge joins them, so its window is the merged one's."""
    joined = []
    for before in carried:
        going_on = [a.end for a in alarms if a.signal == before.signal and a.start <= from_s + 1e-6]
        joined.append(replace(before, end=max([before.end, *going_on])))
    return joined


def _cut_lead(analysis, first: int) -> None:
    """The block's results, observability verdict and input gaps from its step ``first`` on; of the
    verdict also the windows that start up to a window's length before it, which the block before
    cannot judge (they run past its end: `windows_once` takes them from here)."""
    run = analysis.prepared.run
    rows, from_s = slice(first, run.n_steps), float(run.t[first])
    span = (from_s, float(run.t[-1]) + float(run.dt))
    analysis.results = [cut_rows(result, rows, span, None) for result in analysis.results]
    analysis.input_gaps = [replace(g, start=max(g.start, from_s)) for g in analysis.input_gaps if g.end >= from_s]
    verdict = analysis.observability
    if verdict is not None and verdict.t_start.size:  # and the windows the block before could not end
        kept = verdict.t_start >= from_s - verdict.window_s - 1e-9
        analysis.observability = replace(verdict, t_start=verdict.t_start[kept], evidence=verdict.evidence[kept])


follow_dependencies(__name__)  # the disk cache filed by what the kernels compile (logscan.numba_cache)
