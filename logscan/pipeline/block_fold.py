"""The blocks' reduced analyses (`logscan.pipeline.block_reduce`) folded into one analysis of the log
as each is reduced (`BlockFold.add`, then `BlockFold.merged`): the envelopes of every series
appended end to end to one array per series, the observability windows to one verdict, and of the
rest only what the merge reads (alarms, lines, counts, facts), so no block is kept once it is
folded in. The running state holds the log's envelopes (about `MERGED_POINTS` points per series
whatever the number of blocks), the observability verdict (its final windows reduced to what it
reads: `block_merge.windows_folded`) and those lists. docs/algorithms.md
section 8.1b says what the merge does and what differs from the analysis of the whole log at once.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from logscan.alarms import merge_close
from logscan.pipeline.analysis import Analysis, DetectorFailure
from logscan.pipeline.block_alignment import alignment_lines
from logscan.pipeline.block_merge import (
    BlockSpan,
    block_note,
    figures_masked,
    merge_gap_s,
    merged_coverage,
    merged_filter_summary,
    merged_incidents,
    merged_info,
    said_once,
    windows_folded,
)
from logscan.pipeline.detection import consistency_lines, rescore
from logscan.pipeline.kept_nis import KeptNis
from logscan.report.context_join import joined
from logscan.report.kept_views import KeptRows
from logscan.results import Band, DetectorResult, NotChecked, events_from_truth
from logscan.verdict.coverage import judged_span

if TYPE_CHECKING:
    from logscan.pipeline.stages import Prepared
    from logscan.report.run_context import RunContext


class Columns:
    """Named arrays end to end along their first axis, each block's piece appended in place
    (`ndarray.resize`: the array grows, it is not copied per block), ``fill`` where a block has
    none; a name first given by a later block is ``fill`` over the blocks before it."""

    def __init__(self, fill=np.nan) -> None:
        self.fill = fill
        self.arrays: dict[str, np.ndarray] = {}

    def append(self, piece: dict | None, before: int, size: int) -> None:
        """Block's ``piece`` (name -> (size, ...)) after the ``before`` points of the blocks before."""
        piece = piece or {}
        for name, values in piece.items():
            if name not in self.arrays:
                known = np.asarray(values)
                self.arrays[name] = np.full((before, *known.shape[1:]), self.fill, dtype=known.dtype)
        for name, array in self.arrays.items():
            values = None if name not in piece else np.asarray(piece[name])
            dtype = array.dtype if values is None else np.result_type(array, values)
            if dtype != array.dtype:  # as np.concatenate would promote
                array = self.arrays[name] = array.astype(dtype)
            array.resize((before + size, *array.shape[1:]), refcheck=False)  # only this state holds it
            array[before:] = self.fill if values is None else values

    def nbytes(self) -> int:
        return sum(a.nbytes for a in self.arrays.values())


class _Detector:
    """One detector's results over the blocks folded so far."""

    def __init__(self, first: DetectorResult) -> None:
        self.template = replace(first, series={}, extras={}, judged={}, thresholds={})
        self.series, self.extras, self.judged = Columns(), Columns(), Columns(fill=False)
        self.uppers, self.lowers = Columns(), Columns()
        self.bands: dict[str, None] = {}  # every statistic with thresholds, in the order they came
        self.alarms: list = []
        self.possible: list = []
        self.warnings: list[list[str]] = []
        # a reason (its figures masked) -> its first NotChecked, the blocks giving it, their texts
        self.not_checked: dict[str, tuple[NotChecked, list[int], set[str]]] = {}
        self.blocks: list[int] = []  # the blocks it ran in
        self.infos: list[dict] = []
        self.checks: dict = {}
        self.fractions: dict[str, list[int]] = {}  # statistic -> [judged, valid] samples over the blocks
        self.finite: dict[str, int] = {}  # statistic -> its finite samples in the blocks so far
        self.per_step: dict[str, int] = {}  # statistic -> its values per grid step (a column: 1)

    def append(self, result: DetectorResult | None, before: int, size: int, steps: int, block: int) -> None:
        """Block ``block``'s ``result`` (None: the block has none) of ``size`` envelope points, ``steps`` grid steps."""
        pieces = (None, None, None, None, None) if result is None else _pieces(result)
        for columns, piece in zip((self.series, self.extras, self.judged, self.uppers, self.lowers), pieces):
            columns.append(piece, before, size)
        if result is None:
            return
        for name, (samples, finite) in result.series_counts.items():
            self.finite[name] = self.finite.get(name, 0) + finite
            if steps:
                self.per_step.setdefault(name, samples // steps)
        self.bands.update(dict.fromkeys(result.thresholds))
        self.alarms += result.alarms
        self.possible += result.possible
        self.warnings.append(result.warnings)
        self.blocks.append(block)
        for key, reason in {figures_masked(n.reason): n for n in result.not_checked}.items():
            _, blocks, texts = self.not_checked.setdefault(key, (reason, [], set()))
            blocks.append(block)
            texts.add(reason.reason)
        self.infos.append(result.info)
        self.checks.update(result.checks)
        for name, (alarmable, judged) in result.judged_counts.items():  # the log's share: the counts summed
            total = self.fractions.setdefault(name, [0, 0])
            total[0] += alarmable
            total[1] += judged

    def merged(self, gap_s: float, steps: int, spans: list[BlockSpan]) -> DetectorResult:
        """The detector's result over the ``steps`` grid steps folded in (a series a block lacks: NaN
        there); ``spans``: the blocks folded in (`BlockSpan`)."""
        uppers, lowers = self.uppers.arrays, self.lowers.arrays
        return replace(
            self.template,
            series=self.series.arrays,
            extras=self.extras.arrays,
            judged=self.judged.arrays,
            thresholds={name: Band(upper=uppers.get(name), lower=lowers.get(name)) for name in self.bands},
            alarms=merge_close(self.alarms, gap_s),
            possible=merge_close(self.possible, gap_s),
            warnings=said_once(self.warnings),
            not_checked=self.log_not_checked(spans),
            info=merged_info(self.infos),
            checks=self.checks,
            judged_fraction={name: float(a / max(j, 1)) for name, (a, j) in self.fractions.items()},
            judged_counts={name: (a, j) for name, (a, j) in self.fractions.items()},
            series_counts={name: self.counts(name, steps) for name in self.series.arrays},
        )

    def log_not_checked(self, spans: list[BlockSpan]) -> list[NotChecked]:
        """The checks the log could not run: one every block it ran in could not run, as it is; a
        check without a valid sample (``partial``) in some blocks only had one in others (as at
        once, not the log's); one with nothing to judge in some blocks, named with them."""
        return [
            replace(reason, reason=reason.reason + block_note(said, len(self.blocks), len(texts) > 1, spans))
            for reason, said, texts in self.not_checked.values()
            if len(said) == len(self.blocks) or not reason.partial
        ]

    def counts(self, name: str, steps: int) -> tuple[int, int]:
        """(samples, finite ones) of a statistic over ``steps`` grid steps, as its series at once has."""
        return steps * self.per_step.get(name, 1), self.finite.get(name, 0)

    def nbytes(self) -> int:
        return sum(c.nbytes() for c in (self.series, self.extras, self.judged, self.uppers, self.lowers))


def _after_alignment(block: Analysis) -> int:
    """The index in ``block.warnings`` just after its run's alignment warnings (their last: its gap
    lines); without any, after the profile's notes and the reader's warnings, where they would stand."""
    prepared = block.prepared
    for said in (set(prepared.run.warnings), {*prepared.loaded.notes, *prepared.log.source.warnings}):
        marks = [k for k, line in enumerate(block.warnings) if line in said]
        if marks:
            return marks[-1] + 1
    return 0


def _pieces(result: DetectorResult) -> tuple:
    """The result's series, extras, judged masks, upper and lower thresholds (name -> array)."""
    bands = result.thresholds
    uppers = {name: b.upper for name, b in bands.items() if b is not None and b.upper is not None}
    lowers = {name: b.lower for name, b in bands.items() if b is not None and b.lower is not None}
    return result.series, result.extras, result.judged, uppers, lowers


class BlockFold:
    """The merged analysis of the blocks folded in so far (`add`, in time order); `merged` gives it."""

    def __init__(self) -> None:
        self.prepared: Prepared | None = None  # the first block's: its log, profile and model
        self.points = 0  # the envelopes' points so far (the merged times')
        self.times = Columns()
        self.detectors: dict[str, _Detector] = {}
        self.steps = 0  # grid steps
        self.summaries: list[dict | None] = []
        self.warnings: list[list[str]] = []
        self.unchecked: list[list[str]] = []
        self.coverages: list = []  # each block's coverage in figures: the log's is their sum
        self.consistency = KeptNis()  # the blocks' groups' NIS, on disk: the log's consistency warnings judge it
        self.alignment: list = []  # each block's gate and gap figures: the log's lines sum them
        self.alignment_before: list[str] = []  # the first block's lines kept before its alignment lines
        self.spans: list[BlockSpan] = []  # the blocks folded in, in order
        self.incidents: list = []
        self.input_gaps: list = []
        self.failures: dict = {}
        self.observability = None
        self.events: list = []  # the log's truth events (`rescore` scores the merged alarms against them)
        self.kept = KeptRows()  # the rows of the sensor figures (`logscan.report.kept_views`)
        self.context: RunContext | None = None  # the blocks' context so far (`logscan.report.context_join`)

    def add(self, block: Analysis, span: BlockSpan) -> None:
        """Fold a reduced block in (``span``: which it is); nothing of it is kept but what the merge reads."""
        prepared = block.prepared
        size = prepared.run.t.size
        if self.prepared is None:
            self.prepared = prepared
            truth = prepared.log.truth
            self.events = events_from_truth(truth.get("events", []), path=prepared.path) if truth else []
        self.times.append({"t": prepared.run.t}, self.points, size)
        for result in block.results:
            if result.detector not in self.detectors:
                self.detectors[result.detector] = _Detector(result)
        steps = prepared.grid[0] if prepared.grid else 0
        for name, detector in self.detectors.items():
            detector.append(
                next((r for r in block.results if r.detector == name), None), self.points, size, steps, len(self.spans)
            )
        self.points += size
        self.steps += steps
        self.summaries.append(prepared.filter_summary())
        own = block.coverage.said if block.coverage is not None else frozenset()  # said of the log's sum instead
        own |= block.consistency.said if block.consistency is not None else frozenset()
        own |= block.alignment.said if block.alignment is not None else frozenset()
        self.warnings.append([line for line in block.warnings if line not in own])
        if not self.spans:  # the log's alignment lines go where the first block's run said its own
            self.alignment_before = [line for line in block.warnings[: _after_alignment(block)] if line not in own]
        self.unchecked.append([line for line in block.unchecked if line not in own])
        self.coverages.append(block.coverage)
        self.consistency.add(block.consistency)
        if block.alignment is not None:
            self.alignment.append(replace(block.alignment, number=span.number))
        self.spans.append(span)
        self.incidents += block.incidents
        self.input_gaps += block.input_gaps
        self.failures.update({(f.detector, f.message): f for f in block.failures})
        self.observability = windows_folded(self.observability, block.observability, self.events)
        if isinstance(prepared.innovations, KeptRows):
            self.kept.extend(prepared.innovations)
        prepared.innovations = None
        self.context, prepared.context = joined(self.context, prepared.context), None
        block.results, block.observability = [], None  # the first block's prepared stays: the merged one's

    def nbytes(self) -> int:
        """The bytes of the envelopes folded so far (the merged times' and every detector's) and of the
        sensor figures' kept rows."""
        return self.times.nbytes() + self.kept.nbytes() + sum(d.nbytes() for d in self.detectors.values())

    def merged(self, window: tuple[float | None, float | None] | None) -> Analysis:
        """One analysis of the log (``window``: the --start/--end the blocks cover, None: the whole
        log): the first block's log, profile and model; the envelopes end to end; the alarms,
        incidents, lines, counts and facts merged; the ground truth scored again on the merged
        alarms (`rescore`)."""
        prepared = self.prepared
        if prepared is None:
            raise ValueError("no block was folded in")
        gap_s = merge_gap_s(prepared.profile)
        t = self.times.arrays["t"]
        prepared.run = replace(prepared.run, t=t, u=np.empty((t.size, 0)), window=window, first_step=0)
        prepared._filter_summary = merged_filter_summary(self.summaries)
        prepared.grid = (self.steps, float(prepared.run.dt))
        prepared.innovations = self.kept if self.kept.group_names else None
        prepared.context = self.context
        merged = Analysis(prepared=prepared, warnings=said_once(self.warnings))
        merged.results = [detector.merged(gap_s, self.steps, self.spans) for detector in self.detectors.values()]
        merged.incidents = merged_incidents(self.incidents, merged.results, gap_s)
        merged.unchecked = said_once(self.unchecked, self.spans)
        merged.coverage = merged_coverage(self.coverages)
        if merged.coverage is not None:
            lines, merged.unjudged = merged.coverage.lines(merged.results, judged_span(prepared.run))
            merged.unchecked += lines
            merged.warnings += [merged.unjudged] if merged.unjudged else []
        specs = getattr(prepared.profile, "measurements", {})
        at = len(said_once([self.alignment_before]))  # where the first block's run said its own, as at once
        merged.warnings[at:at] = alignment_lines(self.alignment, specs)
        # first, as at once: they question every verdict
        merged.warnings[:0] = consistency_lines(self.consistency.summed(), prepared, merged.results)
        merged.input_gaps = self.input_gaps
        merged.failures = [DetectorFailure(f.detector, f.message, f.exit_code) for f in self.failures.values()]
        merged.observability = self.observability
        if prepared.log.truth is not None:
            rescore(merged)
        return merged
