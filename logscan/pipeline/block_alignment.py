"""Alignment's warnings of a log in blocks: a group's gate closed and a channel's gaps, said of the
log from the figures of each block's own steps (after its lead-in: `alignment_figures`) summed
(`alignment_lines`), not each block's with its own figures (docs/algorithms.md section 8.1b).

A gap is the block's where it ends: after the block before's last step on the grid it was held
on (a delayed sensor's grid lies its delay after the run's steps, a start-stamped input's a step
before), up to its own last; one running across a border ends in the next block, whose lead-in
holds the sample it started from (a gap longer than the lead-in is measured from the lead-in's
start); the stretch a block's span ends in without a sample is the next block's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from logscan.align.notes import GapReport, gap_lines, gate_line


@dataclass
class AlignmentFigures:
    """One block's: each gated group's (closed steps, steps) of its own steps, its channels' gaps
    ending in them, the step (s), and the lines its alignment said of its whole run (the log's
    replace them)."""

    closed: dict[str, tuple[int, int]]
    gaps: list[GapReport]
    step_s: float
    said: frozenset[str]
    number: int = 0  # the block's number of the log's (`BlockSpan.number`), set as it is folded in


def alignment_figures(run, specs: dict, first: int) -> AlignmentFigures:
    """`AlignmentFigures` of a block's full-rate ``run`` from its own first step ``first``."""
    closed, said = {}, set(gap_lines(run.gap_reports))
    for name, group in run.groups.items():
        spec = specs.get(name)
        if spec is None or not getattr(spec, "gate_channel", None):
            continue
        gate = getattr(group, "gate_closed", None)
        closed[name] = (0 if gate is None else int(np.count_nonzero(gate[first:])), int(run.n_steps) - first)
        said |= {line for line in run.warnings if line.startswith(f"group {name!r}: {spec.gate_channel} below ")}
    gaps = []
    for report in run.gap_reports:
        keep = report.before >= first  # ends after the block before's last step on its grid
        gaps.append(GapReport(report.name, report.limit, report.starts[keep], report.ends[keep], None, report.open_end))
    return AlignmentFigures(closed, gaps, float(run.dt), frozenset(said))


def alignment_lines(blocks: list[AlignmentFigures], specs: dict) -> list[str]:
    """The gate lines of the groups whose gate closed in some block, then the gap lines, of the
    ``blocks`` in order. The stretch a block ends its span in is the next block's; after a block
    that could not be analysed, the next one analysed has it when it ends there (from the same
    last sample), else it is counted to the border."""
    if not blocks:
        return []
    step_s = blocks[0].step_s
    closed: dict[str, list[int]] = {}
    pieces: dict[tuple[str, str], list[GapReport]] = {}
    for k, block in enumerate(blocks):
        for name, (gated, steps) in block.closed.items():
            total = closed.setdefault(name, [0, 0])
            total[0] += gated
            total[1] += steps
        for report in block.gaps:
            cut = report.open_end and report.ends.size and _ended_after(blocks, k, report)
            ends = slice(0, report.ends.size - 1) if cut else slice(None)
            pieces.setdefault((report.name, report.limit), []).append(
                GapReport(report.name, report.limit, report.starts[ends], report.ends[ends])
            )
    gates = [
        gate_line(name, specs[name].gate_channel, specs[name].gate_min, gated * step_s, steps * step_s)
        for name, (gated, steps) in closed.items()
        if gated and name in specs
    ]
    reports = [
        GapReport(name, limit, np.concatenate([p.starts for p in parts]), np.concatenate([p.ends for p in parts]))
        for (name, limit), parts in pieces.items()
    ]
    return gates + gap_lines(reports)


def _ended_after(blocks: list[AlignmentFigures], k: int, report: GapReport) -> bool:
    """Whether a later block has the stretch ``report`` (block ``k``'s) ends its span in: the next
    block does, when it is the next of the log; after one not analysed, the next analysed one
    when it has a gap from the same last sample."""
    if k == len(blocks) - 1:
        return False
    after = blocks[k + 1]
    if after.number == blocks[k].number + 1:
        return True
    start = report.starts[-1]
    return any(g.name == report.name and g.limit == report.limit and start in g.starts for g in after.gaps)
