"""How the blocks' reduced analyses (`logscan.pipeline.block_reduce`) merge into one analysis of the
log (`logscan.pipeline.block_fold` folds each in as it is reduced): one verdict, one summary, one
report. An alarm or an incident that runs across a block's border is one: alarms of one statistic
at most the profile's merge gap apart are merged (as within a block), incidents likewise; lines,
facts, the filter's counts and the observability windows once each. docs/algorithms.md section
8.1b says what differs from the analysis of the whole log at once.
"""

from __future__ import annotations

import operator
import re
from dataclasses import replace
from functools import reduce
from typing import NamedTuple

import numpy as np

from logscan.results import DetectorResult, Incident
from logscan.verdict.coverage import Coverage, Stop
from logscan.verdict.incidents import DEFAULT_GAP_S, quoted_peak
from logscan.verdict.observability_folded import folded

# the filter summary's counts summed over the blocks; its mean NIS weighted by each block's updates
_COUNTS = ("updates", "rejected", "seeded")
_SUMS = ("steps", "inputs_held", "divergence_episodes", "diverged_steps")


def merge_gap_s(profile) -> float:
    """The gap below which alarms of one statistic and incidents merge (`logscan.pipeline.detection`)."""
    policy = getattr(profile, "alarm_policy", None)
    return policy.merge_gap_s if policy is not None else DEFAULT_GAP_S


class BlockSpan(NamedTuple):
    """A block as its lines name it: its number (from 1) of the log's blocks, its first and last
    step judged (s)."""

    number: int
    of: int
    start_s: float
    end_s: float


def said_once(lines: list[list[str]], spans: list[BlockSpan] | None = None) -> list[str]:
    """Each block's lines (``lines[k]``: block k's) said once: a line every block that says it says
    alike as it is; one said with other figures by other blocks (a group's NIS over each block) as
    the first block's, saying in how many blocks it came and whose figures it gives. With the
    blocks' ``spans`` (``spans[k]``: block k's), a line not every block says names the blocks and
    spans it holds for (a block's line of what it could not check is not the log's)."""
    first: dict[str, tuple[str, int]] = {}
    blocks: dict[str, set[int]] = {}
    texts: dict[str, set[str]] = {}
    for k, block in enumerate(lines):
        for line in block:
            key = figures_masked(line)
            first.setdefault(key, (line, k))
            blocks.setdefault(key, set()).add(k)
            texts.setdefault(key, set()).add(line)
    return [
        line + block_note(sorted(blocks[key]), len(lines), len(texts[key]) > 1, spans)
        for key, (line, _) in first.items()
    ]


def block_note(said: list[int], of: int, differ: bool, spans: list[BlockSpan] | None) -> str:
    """What follows a line the blocks ``said`` (their places, in order) gave of the ``of`` that
    could: with ``spans``, the blocks it holds for when not all; whose figures it gives when they
    ``differ`` (the first's); "" when neither."""
    figures = f"these figures are block {spans[said[0]].number if spans else said[0] + 1}'s" if differ else ""
    if spans and len(said) < of:
        return f" ({blocks_where([spans[k] for k in said])}{'; ' + figures if figures else ''})"
    return f" (said in {len(said)} of {of} blocks; {figures})" if figures else ""


def blocks_where(said: list[BlockSpan]) -> str:
    """ "in blocks 1-2, 4 of 5: 0.0-15.6 s, 31.2-39.0 s": the blocks ``said`` (in order) as runs of
    consecutive ones, each with the span it covers."""
    runs: list[list[BlockSpan]] = []
    for span in said:
        if runs and span.number == runs[-1][1].number + 1:
            runs[-1][1] = span
        else:
            runs.append([span, span])
    names = ", ".join(f"{a.number}" if a is b else f"{a.number}-{b.number}" for a, b in runs)
    times = ", ".join(f"{round(a.start_s, 1) + 0.0:.1f}-{b.end_s:.1f} s" for a, b in runs)  # + 0.0: no "-0.0"
    return f"in {'block' if len(said) == 1 else 'blocks'} {names} of {said[0].of}: {times}"


# a figure, its sign with it ("t=-0.028 s" and "t=0.000 s" alike), not the digits of a name (battery_status_0)
_FIGURES = re.compile(r"(?<![\w.])-?\d+(?:[.,]\d+)*(?:e[-+]?\d+)?")


def figures_masked(line: str) -> str:
    """``line`` with its figures masked: the key of lines that differ only in them."""
    return _FIGURES.sub("#", line)


def merged_coverage(coverages: list[Coverage | None]) -> Coverage | None:
    """The blocks' coverage figures as the log's: group uses, divergence, the unjudged share and the
    judged time summed; a sensor stopped in a block and used in no later one stopped for the log,
    the judged time of the blocks after it added to its own."""
    known = [c for c in coverages if c is not None]
    if not known:
        return None
    shares = [c.share for c in known if c.share is not None]
    share = reduce(operator.add, shares) if shares else None
    stops = {}
    for k, coverage in enumerate(known):
        for name, stop in coverage.stopped.items():
            later = known[k + 1 :]
            if not any(name in c.heard for c in later):
                stops[name] = Stop(stop.t, stop.unjudged_s + sum(c.judged_s for c in later))
    return Coverage(
        filter=reduce(operator.add, (c.filter for c in known)),
        share=share if share is not None and share.suspended_s > 0.0 else None,  # as at once: nothing held back
        stopped=stops,
        judged_s=sum(c.judged_s for c in known),
        heard=frozenset().union(*(c.heard for c in known)),
        log_end=known[-1].log_end,
    )


def _union(items) -> list:
    """The distinct items, in the order they first appear."""
    return list(dict.fromkeys(items))


def merged_info(infos: list[dict]) -> dict:
    """A detector's facts over the blocks: a value every block gives alike once; dicts merged key
    by key; lists end to end (e.g. each alarm's uncapped peak); whole numbers summed (counts);
    any other value that differs (a scale estimated from each block's samples): the first block's."""
    out: dict = {}
    for key in _union(k for info in infos for k in info):
        values = [info[key] for info in infos if key in info]
        out[key] = _merged_value(values)
    return out


def _merged_value(values: list):
    if all(v == values[0] for v in values[1:]):
        return values[0]
    if all(isinstance(v, dict) for v in values):
        return merged_info(values)
    if all(isinstance(v, list) for v in values):
        return [item for v in values for item in v]
    if all(isinstance(v, int) and not isinstance(v, bool) for v in values):
        return sum(values)
    return values[0]


def merged_incidents(incidents: list[Incident], results: list[DetectorResult], gap_s: float) -> list[Incident]:
    """The blocks' incidents, those at most ``gap_s`` apart (one each side of a border) as one:
    headed as the earlier (its source alarmed first), its span to the later's end; every
    incident's alarms the merged ones within it, the check its headline quotes the merged alarm
    with its peak (the part before a border peaked lower, or as high)."""
    alarms = sorted((a for r in results for a in r.alarms), key=lambda a: (a.start, a.end))
    out: list[Incident] = []
    for incident in sorted(incidents, key=lambda i: (i.start, i.end)):
        if out and incident.start - out[-1].end <= gap_s + 1e-9:
            out[-1] = replace(out[-1], end=max(out[-1].end, incident.end))
        else:
            out.append(incident)
    for i, incident in enumerate(out):
        members = [a for a in alarms if a.start <= incident.end + 1e-9 and a.end >= incident.start - 1e-9]
        quoted, detail = incident.quoted, incident.detail
        if quoted is not None:  # the merged alarm the quoted part now belongs to, and its peak
            part, quoted = quoted, next((a for a in members if _holds(a, quoted)), quoted)
            if detail.startswith(quoted_peak(part)):  # a part's peak: the merged alarm's is the higher
                detail = quoted_peak(quoted) + detail[len(quoted_peak(part)) :]
        merged = replace(incident, alarms=members or incident.alarms, quoted=quoted, detail=detail)
        merged.headline = merged.headline_in()
        out[i] = merged
    return out


def _holds(alarm, part) -> bool:
    """Whether ``alarm`` (merged) is of the statistic ``part`` is and holds its start."""
    return (alarm.detector, alarm.signal) == (part.detector, part.signal) and alarm.start <= part.start <= alarm.end


def merged_filter_summary(summaries: list[dict | None]) -> dict | None:
    """The EKF's counts over the blocks: steps, updates, rejections... summed; the mean NIS per
    group weighted by its updates; the first block's other facts."""
    known = [s for s in summaries if s]
    if not known:
        return None
    out = dict(known[0])  # its lead-in too: the first block's is the analysed span's (--start)
    for key in _SUMS:
        if key in out:
            out[key] = sum(s.get(key, 0) for s in known)
    for key in _COUNTS:
        if key in out:
            out[key] = {g: sum(s.get(key, {}).get(g, 0) for s in known) for g in out[key]}
    if "mean_nis" in out and "updates" in out:
        out["mean_nis"] = {g: _weighted_nis(known, g) for g in out["mean_nis"]}
    return out


def _weighted_nis(summaries: list[dict], group: str):
    pairs = [(s["mean_nis"].get(group), s["updates"].get(group, 0)) for s in summaries]
    pairs = [(m, n) for m, n in pairs if m is not None and n and np.isfinite(m)]
    total = sum(n for _, n in pairs)
    return sum(m * n for m, n in pairs) / total if total else summaries[0]["mean_nis"].get(group)


def windows_once(merged, part):
    """The verdict ``merged`` (of the blocks before; None: none judged one) with the block's ``part``
    after it: a window both give (the last of one, led in by the next) once, the one judged where
    it is (the later of two alike), in the order of their starts. Only ``merged``'s windows from
    ``part``'s first on are sorted again; its arrays grow in place (``merged`` is not kept)."""
    if part is None or not part.t_start.size:
        return merged
    stride = part.stride_s if merged is None else merged.stride_s
    first = 0
    if merged is not None:
        slots = np.round(merged.t_start / stride).astype(np.int64)
        first = int(np.searchsorted(slots, np.round(part.t_start / stride).astype(np.int64).min()))
        t_start = np.concatenate([merged.t_start[first:], part.t_start])
        evidence = np.concatenate([merged.evidence[first:], part.evidence])
    else:
        t_start, evidence = part.t_start, part.evidence
    slot = np.round(t_start / stride).astype(np.int64)
    judged = np.isfinite(evidence).reshape(evidence.shape[0], -1).any(axis=1)
    order = np.lexsort((judged, slot))  # by window start, a judged row last among its doubles
    kept = order[np.append(slot[order][1:] != slot[order][:-1], True)]
    if merged is None:  # copies (fancy indexing): the arrays below own their data
        return replace(part, t_start=t_start[kept], evidence=evidence[kept])
    rows = first + kept.size
    merged.t_start.resize(rows, refcheck=False)
    merged.evidence.resize((rows, *merged.evidence.shape[1:]), refcheck=False)
    merged.t_start[first:], merged.evidence[first:] = t_start[kept], evidence[kept]
    return replace(merged, t_end=part.t_end)


def windows_folded(merged, part, events):
    """`windows_once`, then the windows no later block can give or replace reduced to what the
    verdict reads of them (`logscan.verdict.observability_folded`; ``events``: the log's truth
    events, whose verdicts it keeps). A block's windows start a window before its first step
    (`logscan.pipeline.block_reduce`), which is at most a grid step after the last one of the block
    before; so the windows starting more than a window and a stride before the merged verdict's end
    are final."""
    if part is not None and part.t_start.size and merged is not None and part.t_start.min() <= merged.last_reduced:
        raise RuntimeError("a block's observability windows reach back into those already reduced")
    merged = windows_once(merged, part)
    if merged is None:
        return None
    merged = folded(merged, events)
    open_from = merged.t_end - merged.window_s - merged.stride_s
    return merged.reduced(int(np.searchsorted(merged.t_start, open_from, side="left")))
