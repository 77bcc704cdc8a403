"""Block mode (`analyze_blocked`): a long log analysed as consecutive windows of bounded length, so
memory is bounded by the block's length, not the log's (issue 29, item 2).

Each block is a window (`analyze_log`'s ``start_s``/``end_s``): of an indexed MCAP file only the
chunks it needs are decoded (`logscan.readers.mcap.window`), of a log a built-in profile read whole
the samples it needs are cut from that one read (`logscan.pipeline.held_window`), its EKF starts from a lead-in before
it (`logscan.pipeline.lead_in`), the checks of the vehicle's own reports run from before it
(`logscan.pipeline.raw_lead`). Once a block is analysed it is reduced to what the outputs read
(`logscan.pipeline.block_reduce`: its alarms, incidents, lines, counts, the envelopes of its
series and the rows its sensor figures draw), its full-rate arrays are freed and it is folded into
one analysis of the blocks so far (`logscan.pipeline.block_fold`), not kept. docs/algorithms.md
section 8.1b says when it runs and what differs from the analysis of the whole log at once (the
block borders).
"""

from __future__ import annotations

import gc
import math
import os
from dataclasses import replace

from logscan.alarms import AlarmInterval
from logscan.docs import doc_url
from logscan.errors import LogscanError
from logscan.memory import every_free_page, return_freed_pages
from logscan.pipeline.block_fold import BlockFold
from logscan.pipeline.block_merge import BlockSpan
from logscan.pipeline.block_reduce import bucket_width, first_quoted, reduce_block
from logscan.pipeline.preparation import load_profile_for
from logscan.pipeline.run import analyze_log
from logscan.readers import detect_format
from logscan.readers.mcap.span import indexed_span_s
from logscan.report.kept_views import FOCUS_ROWS
from logscan.report.sensor_figures import REDUCED_POINTS
from logscan.verdict.coverage import own_steps
from logscan.verdict.observability import WARMUP_S as OBSERVABILITY_WARMUP_S
from logscan.verdict.observability import WINDOW_S as OBSERVABILITY_WINDOW_S

# The default block: grid steps analysed at once. The analysis holds ~0.8 KiB per step (the 100 Hz
# quadcopter: ~282 MiB per log-hour, bench/README.md) beside ~0.7 KiB read per step and the index
# times of the whole file (a window's read): 30 minutes at 100 Hz keeps a 24-hour log's peak within
# the 1 GB.
BLOCK_STEPS = 180_000
# Every block after the first is analysed from this long before it, its alarms seen from its own first
# step (`logscan.alarms` rule 6): the detectors' windows, sums and persistence run in over steps the
# block before judged, so they stand at the border as in the whole log's analysis at once. Twice the
# longest bounded memory among them: the observability verdict's kernel settles over WARMUP_S (30 s)
# before a window of WINDOW_S (1 s); the NIS and e_x window sums, the frozen check's runs and the
# alarms' persistence span seconds; a CUSUM forgets a healthy stretch in its drift's time
# (docs/algorithms.md 8.1b).
DETECTOR_LEAD_S = 2 * (OBSERVABILITY_WARMUP_S + OBSERVABILITY_WINDOW_S)
# A block may be this much of its length longer than asked (a 24-hour log of 1-hour pieces spans
# 86,400.24 s: 48 blocks of 1800.005 s, not 49 shorter ones)
BLOCK_SLACK = 0.01
# A block ends this long before the next begins: alignment takes the steps from a window's start
# to its end in whole nanoseconds (`logscan.timebase.time_sanity.grid`), so a step is in the one
# block or the next, whatever its phase
BORDER_GAP_S = 1e-9
# The peak memory of a log analysed at once: issue 29's 450 MB for a log of any length.
MEMORY_BUDGET_BYTES = 450_000_000
# The peak RSS of `logscan analyze` of a log at once, as a line through the worst of three runs at 15
# and at 60 minutes of the 100 Hz quadcopter log, with and without the report (bench/README.md,
# "At-once peak by length"; it bounds the worst runs at 30, 45 and 50 minutes from above): START_BYTES
# (interpreter, numba's kernels, the reader's and the report's fixed part) plus STEP_BYTES per grid step
# (aligned run, EKF trace, detectors' series and working memory; 282 MiB per 100 Hz log-hour).
START_BYTES = 218 * 2**20
STEP_BYTES = 821
# Logs longer than this many grid steps are analysed in blocks unless --block-s 0: the longest span
# whose peak at once stays within the budget (269,683 steps: 44.9 minutes at 100 Hz). Blocks are of
# equal length, none longer than BLOCK_STEPS (`block_windows`), so no block comes near it either.
AUTO_STEPS = (MEMORY_BUDGET_BYTES - START_BYTES) // STEP_BYTES


def block_windows(
    span_s: float, block_s: float, dt: float, start_s: float | None = None, end_s: float | None = None
) -> list[tuple[float | None, float | None]]:
    """The fewest consecutive windows [start, end] of equal length, a whole number of grid steps
    (``dt``), covering ``start_s``..``end_s`` (None: that end of the log, ``span_s`` long) with
    none longer than ``block_s`` (by more than `BLOCK_SLACK` of it: a log's seams and rounding), so
    each block's memory is bounded by ``block_s``, the last included; each ends a nanosecond
    before the next begins (`BORDER_GAP_S`), so every step is analysed once, whatever the grid's
    phase (a ULog's time zero is its logger's start, not a grid step: with half a step between
    blocks, the steps falling in it were in none). One window: the span itself."""
    lo = 0.0 if start_s is None else float(start_s)
    hi = float(span_s) if end_s is None else float(end_s)
    count = max(1, math.ceil((hi - lo) / block_s - BLOCK_SLACK))
    length = math.ceil((hi - lo) / count / dt - 1e-9) * dt  # whole steps: a border on the grid
    borders = [lo + k * length for k in range(1, count)]
    starts = [start_s, *borders]
    ends = [b - BORDER_GAP_S for b in borders] + [end_s]
    return list(zip(starts, ends))


def blocks_for(path, loaded, block_s: float | None, start_s: float | None, end_s: float | None, refusal=None):
    """The windows to analyse ``path`` in, or None: the whole log at once. ``block_s`` None: in
    blocks of `BLOCK_STEPS` when the span analysed holds more than `AUTO_STEPS` grid steps; 0:
    never; else blocks of that length whenever the span is longer than one. Only a log `_refusal`
    finds nothing against is read in blocks (``refusal``: it, found already)."""
    if block_s == 0:
        return None
    refused, span = _refusal(path, loaded) if refusal is None else refusal
    if refused or span is None:
        return None
    rate = float(loaded.profile.vehicle.rate_hz)
    span_s = span[0]
    analysed_s = (span_s if end_s is None else min(end_s, span_s)) - (start_s or 0.0)
    if block_s is None:
        if analysed_s * rate <= AUTO_STEPS:
            return None
        block_s = BLOCK_STEPS / rate
    windows = block_windows(span_s, block_s, 1.0 / rate, start_s, end_s)
    return windows if len(windows) > 1 else None


def _refusal(path, loaded, header_stamp: bool = False) -> tuple[str, tuple[float, int] | None]:
    """(why ``path`` cannot be read in blocks, "" when it can; its span in seconds from time zero
    and its message count). An indexed MCAP file reads a window without the rest; a log of another
    format is read whole, and in blocks only when a built-in profile has read it already to build
    itself (`loaded.log`: each block a window of that read, `logscan.pipeline.held_window`), on
    its log times (``header_stamp``: the analysis reads it again on the header stamps). Only a
    profile without further loops or [recovery] (both re-read the whole run)."""
    fmt = detect_format(path)
    held = fmt != "mcap"  # read whole: its blocks are windows of the built-in profile's read
    if held and loaded.log is None:
        return (
            f"a {fmt} log analysed with --profile or its embedded one is read whole, so it was analysed at once "
            "(an indexed MCAP, or a log a built-in profile reads, is read in blocks)"
        ), None
    if held and header_stamp:
        return f"a {fmt} log is read whole again on its header stamps (--use-header-stamp); analysed at once", None
    if loaded.profile.loops or loaded.profile.recovery is not None:
        return "a profile with further loops or [recovery] re-reads the whole run; analysed at once", None
    span = held_span(loaded.log) if held else indexed_span_s(path)
    if span is None:
        what = "the log has no timed sample" if held else "the MCAP file has no chunk index or statistics"
        return f"{what} to read a block from; analysed at once", None
    if span[0] * float(loaded.profile.vehicle.rate_hz) > span[1]:  # an outlying time (2**63 - 1 ns)
        why = (
            f"the file's span ({span[0]:.6g} s) holds fewer messages than grid steps (an outlying "
            "time stretches it); analysed at once, where outlying times are dropped"
        )
        return why, span
    return "", span


def held_span(log) -> tuple[float, int] | None:
    """(seconds from ``log``'s time zero to its last sample, its samples: one per time array), as
    `indexed_span_s` gives an MCAP file's; None without a timed sample."""
    origin, end = log.origin_ns, log.end_ns
    if origin is None or end is None:
        return None
    counts = {id(channel.t): len(channel) for channel in log.channels.values()}
    return (end - origin) / 1e9, sum(counts.values())


def over_budget_warning(steps: int, why: str) -> str:
    """The warning of a log analysed at once although its grid holds more than `AUTO_STEPS` steps:
    its memory grew with its length past the budget a log in blocks keeps (``why``: `_refusal`)."""
    return (
        f"memory: {steps:,} grid steps were analysed at once, more than the {AUTO_STEPS:,} whose peak stays "
        f"within {MEMORY_BUDGET_BYTES / 1e6:.0f} MB, so the peak grew with the log's length: {why}; "
        f"--start/--end analyse a part with less memory ({doc_url('troubleshooting.md')}, a log does not fit in memory)"
    )


def analyze_blocked(path: str | os.PathLike, profile_path=None, *, block_s: float | None = None, **options):
    """`analyze_log`, of a long log in blocks (`blocks_for`) merged into one analysis;
    ``block_s``: None (auto), 0 (never) or the block's length in seconds; ``options``: those of
    `analyze_log` (``start_s``/``end_s``: the span the blocks cover). A log longer than the
    --block-s asked for that could not be read in blocks says so in its warnings."""
    loaded = load_profile_for(path, profile_path)
    start_s, end_s = options.pop("start_s", None), options.pop("end_s", None)
    # found before the analysis takes loaded.log
    refusal = ("", None) if block_s == 0 else _refusal(path, loaded, bool(options.get("use_header_stamp")))
    windows = blocks_for(path, loaded, block_s, start_s, end_s, refusal)
    if windows is None:
        analysis = analyze_log(path, profile_path, loaded=loaded, start_s=start_s, end_s=end_s, **options)
        steps = analysis.run.n_steps
        # longer than the --block-s asked for (shorter than one block: as it should be), or by default
        # past the budget at once: why it was not read in blocks
        too_long = (analysis.duration_s > block_s) if block_s else (block_s is None and steps > AUTO_STEPS)
        refused = refusal[0] if too_long else ""
        if refused:
            analysis.warnings.append(f"--block-s: {refused}" if block_s else over_budget_warning(steps, refused))
        return analysis
    return _in_blocks(path, profile_path, loaded, windows, (start_s, end_s), options, block_s)


def _in_blocks(path, profile_path, loaded, windows: list, window: tuple, options: dict, asked_s=None):
    """Each window analysed, reduced, its full-rate arrays freed and folded into the merged state;
    ``asked_s``: the --block-s given (None: the default), which the equal blocks may undercut."""
    progress = options.pop("progress", None)
    options.pop("fraction", None)  # the bytes of each block's read would run back and forth
    options["free_series"] = True  # sensor_views as asked: the incidents' sizes read the innovations
    options["read_plans"] = {}  # the file's plan, read by the first block's read and kept for the others
    rate = float(loaded.profile.vehicle.rate_hz)
    block_s = windows[1][0] - (windows[0][0] or 0.0)
    width = bucket_width(int(len(windows) * block_s * rate))
    points = -(-REDUCED_POINTS // len(windows))  # the sensor figures' rows: each block its share of the log's
    # a built-in profile's log, read whole to build it: of an MCAP each block reads its own window;
    # of another format the first block's read holds it for the others (`held_window`), and only it
    first_log, loaded.log = (None if detect_format(path) == "mcap" else loaded.log), None
    fold, refused = BlockFold(), []
    carried: list[AlarmInterval] = []  # the alarm the block before's first incident quotes
    with every_free_page():  # the peak must not depend on where the heap stands (logscan.memory)
        for k, (start_s, end_s) in enumerate(windows):
            step = None if progress is None else _prefixed(progress, f"block {k + 1}/{len(windows)}: ")
            # `analyze_log` sets the tables' calibration on it; the first block's read holds the log
            own, first_log = replace(loaded, log=first_log), None
            # after the first block, the detectors' windows and sums run in from DETECTOR_LEAD_S before it
            led = None if k == 0 else max(float(start_s) - DETECTOR_LEAD_S, float(windows[0][0] or 0.0))
            try:
                analysis = analyze_log(
                    path,
                    profile_path,
                    loaded=own,
                    start_s=start_s if led is None else led,
                    end_s=end_s,
                    progress=step,
                    judged_from_s=None if led is None else start_s,
                    **options,
                )
            except LogscanError as exc:  # a block the log holds too little of (a long gap): the others stand
                refused.append((k, exc))
                continue
            from_s = None if led is None else start_s
            if from_s is not None and own_steps(analysis.run.t, from_s) == analysis.run.n_steps:  # its lead-in only
                refused.append((k, _no_own_steps(analysis)))
                continue
            focus = _focus_share(fold, len(windows) - k)
            first_s = float(analysis.run.t[0]) if from_s is None else from_s
            quoted = first_quoted(analysis, first_s)
            reduce_block(analysis, width, from_s, points, focus, quoted, carried)
            carried = quoted  # the next block keeps the rest of its window
            fold.add(analysis, BlockSpan(k + 1, len(windows), first_s, float(analysis.run.t[-1])))
            del analysis
            gc.collect()
            return_freed_pages()
    if fold.prepared is None:
        raise refused[0][1]
    merged = fold.merged(None if window == (None, None) else window)
    merged.unchecked += [_refused_line(windows, k, len(windows), exc) for k, exc in refused]
    merged.warnings += _blocks_said(len(windows), block_s, asked_s, rate)
    return merged


def _blocks_said(count: int, block_s: float, asked_s: float | None, rate: float) -> list[str]:
    """The warnings of a log analysed in ``count`` blocks of ``block_s``: that it was, and what
    blocks shorter than the detectors' lead cost."""
    said = [
        f"analysed in {count} blocks of {block_s:g} s (--block-s), each after the first from "
        f"{DETECTOR_LEAD_S:g} s before it, so the detectors' windows and sums run on across the borders; the "
        f"thresholds a detector estimates from its samples are each block's ({doc_url('algorithms.md')}, "
        "section 8.1b)"
    ]
    if block_s < DETECTOR_LEAD_S:
        said.append(
            f"{_asked(asked_s, block_s)}: each block is analysed with the {DETECTOR_LEAD_S:g} s before it, so blocks "
            f"shorter than that cost more than twice the analysis at once (default: {BLOCK_STEPS / rate:g} s)"
        )
    return said


def _asked(asked_s: float | None, block_s: float) -> str:
    """The --block-s given, and the equal blocks' length where it differs (a 60-s ask of 395 s: 56.5 s)."""
    if asked_s is None:
        return f"blocks of {block_s:g} s"
    return f"--block-s {asked_s:g}" + ("" if f"{asked_s:g}" == f"{block_s:g}" else f" (blocks of {block_s:g} s)")


def _no_own_steps(analysis) -> LogscanError:
    """Why a block whose grid is its lead-in alone (the profile's sensors end before it) is not analysed."""
    end = float(analysis.run.t[-1])
    return LogscanError(
        f"no grid step of its own: the profile's sensors have no sample there (the grid ends at {end:.1f} s)"
    )


def _refused_line(windows: list, k: int, n: int, exc: LogscanError) -> str:
    """What was not checked of a block that could not be analysed, and why."""
    start, end = windows[k]
    span = f"{start or 0.0:.1f}-{'the end' if end is None else f'{end:.1f} s'}"
    return f"block {k + 1} of {n} ({span}) not analysed: {exc.message}"


def _prefixed(progress, prefix: str):
    return lambda message: progress(prefix + message)


def _focus_share(fold: BlockFold, blocks_left: int):
    """How many rows inside zoom windows a group's figures keep of this block: an equal share of
    what the blocks before left of the log's `FOCUS_ROWS`, so the log keeps at most that many."""
    return lambda group: max(FOCUS_ROWS - fold.kept.focus.get(group, 0), 0) // blocks_left
