"""The blocks' reduced analyses (`logscan.pipeline.block_reduce`) merged into one analysis of the log
(`merge_blocks`): one verdict, one summary, one report. An alarm or an incident that runs across a
block's border is one: alarms of one statistic at most the profile's merge gap apart are merged
(as within a block), incidents likewise. docs/algorithms.md section 8.1b says what differs from
the analysis of the whole log at once.
"""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np

from logscan.alarms import merge_close
from logscan.pipeline.analysis import Analysis, DetectorFailure
from logscan.pipeline.detection import rescore
from logscan.results import Band, DetectorResult, Incident
from logscan.verdict.incidents import DEFAULT_GAP_S

# the filter summary's counts summed over the blocks; its mean NIS weighted by each block's updates
_COUNTS = ("updates", "rejected", "seeded")
_SUMS = ("steps", "inputs_held", "divergence_episodes", "diverged_steps")


def merge_blocks(blocks: list[Analysis], window: tuple[float | None, float | None] | None) -> Analysis:
    """One analysis of the log from its blocks' (in time order, each reduced): the first block's
    log, profile and model; the blocks' envelopes of every series end to end; their alarms,
    incidents, lines of what was not checked, warnings and filter counts merged; the ground truth
    scored again on the merged alarms (`rescore`). ``window``: the --start/--end the blocks cover
    (None: the whole log)."""
    first = blocks[0]
    prepared = first.prepared
    gap_s = _merge_gap_s(prepared.profile)
    results = merged_results(blocks, gap_s)  # before the first block's run holds the merged times
    t = np.concatenate([b.prepared.run.t for b in blocks])
    prepared.run = replace(prepared.run, t=t, u=np.empty((t.size, 0)), window=window, first_step=0)
    prepared._filter_summary = merged_filter_summary([b.prepared.filter_summary() for b in blocks])
    prepared.grid = (sum(b.prepared.grid[0] for b in blocks if b.prepared.grid), float(prepared.run.dt))
    merged = Analysis(prepared=prepared, warnings=said_once([b.warnings for b in blocks]))
    merged.results = results
    merged.incidents = merged_incidents([i for b in blocks for i in b.incidents], merged.results, gap_s)
    merged.unchecked = said_once([b.unchecked for b in blocks])
    merged.unjudged = "; ".join(_union(b.unjudged for b in blocks if b.unjudged))
    merged.input_gaps = [gap for b in blocks for gap in b.input_gaps]
    failures = {(f.detector, f.message): f for b in blocks for f in b.failures}
    merged.failures = [DetectorFailure(f.detector, f.message, f.exit_code) for f in failures.values()]
    merged.observability = merged_observability([b.observability for b in blocks])
    if prepared.log.truth is not None:
        rescore(merged)
    return merged


def _merge_gap_s(profile) -> float:
    """The gap below which alarms of one statistic and incidents merge (`logscan.pipeline.detection`)."""
    policy = getattr(profile, "alarm_policy", None)
    return policy.merge_gap_s if policy is not None else DEFAULT_GAP_S


def said_once(lines: list[list[str]]) -> list[str]:
    """Each block's lines (``lines[k]``: block k's) said once: a line every block that says it says
    alike as it is; one said with other figures by other blocks (a group's NIS over each block) as
    the first block's, saying in how many blocks it came and whose figures it gives."""
    first: dict[str, tuple[str, int]] = {}
    blocks: dict[str, set[int]] = {}
    texts: dict[str, set[str]] = {}
    for k, block in enumerate(lines):
        for line in block:
            key = _FIGURES.sub("#", line)
            first.setdefault(key, (line, k))
            blocks.setdefault(key, set()).add(k)
            texts.setdefault(key, set()).add(line)
    out = []
    for key, (line, k) in first.items():
        if len(texts[key]) > 1:
            line += f" (said in {len(blocks[key])} of {len(lines)} blocks; these figures are block {k + 1}'s)"
        out.append(line)
    return out


_FIGURES = re.compile(r"\d+(?:[.,]\d+)*(?:e[-+]?\d+)?")


def _union(items) -> list:
    """The distinct items, in the order they first appear."""
    return list(dict.fromkeys(items))


def merged_results(blocks: list[Analysis], gap_s: float) -> list[DetectorResult]:
    """One result per detector (in the order they first ran): its blocks' series end to end (NaN,
    or not judged, in a block where a series is missing), alarms and possible faults merged across
    the borders, warnings and not-checked reasons once each, its facts (`merged_info`)."""
    names = _union(r.detector for b in blocks for r in b.results)
    sizes = [b.prepared.run.t.size for b in blocks]
    merged = []
    for name in names:
        parts = [next((r for r in b.results if r.detector == name), None) for b in blocks]
        present = [r for r in parts if r is not None]
        result = replace(
            present[0],
            series=_joined([None if r is None else r.series for r in parts], sizes),
            extras=_joined([None if r is None else r.extras for r in parts], sizes),
            judged=_joined([None if r is None else r.judged for r in parts], sizes, fill=False),
            thresholds=_joined_bands([None if r is None else r.thresholds for r in parts], sizes),
            alarms=merge_close([a for r in present for a in r.alarms], gap_s),
            possible=merge_close([p for r in present for p in r.possible], gap_s),
            warnings=said_once([r.warnings for r in present]),
            not_checked=list({n.reason: n for r in present for n in r.not_checked}.values()),
            info=merged_info([r.info for r in present]),
            checks={k: v for r in present for k, v in r.checks.items()},
            judged_fraction=_mean_fraction(parts, sizes),
        )
        merged.append(result)
    return merged


def _joined(pieces: list[dict | None], sizes: list[int], fill=np.nan) -> dict:
    """name -> the blocks' arrays end to end; ``fill`` for a block without it."""
    names = _union(k for piece in pieces if piece for k in piece)
    out = {}
    for name in names:
        known = next(piece[name] for piece in pieces if piece and name in piece)
        dtype = np.asarray(known).dtype
        shape = np.shape(known)[1:]
        arrays = [
            np.asarray(piece[name]) if piece and name in piece else np.full((size, *shape), fill, dtype=dtype)
            for piece, size in zip(pieces, sizes)
        ]
        out[name] = np.concatenate(arrays)
    return out


def _joined_bands(pieces: list[dict | None], sizes: list[int]) -> dict:
    """statistic -> its blocks' thresholds end to end (NaN where a block has none)."""
    names = _union(k for piece in pieces if piece for k in piece)
    out = {}
    for name in names:
        bands = [piece.get(name) if piece else None for piece in pieces]
        upper = _joined([{"b": b.upper} if b is not None and b.upper is not None else None for b in bands], sizes)
        lower = _joined([{"b": b.lower} if b is not None and b.lower is not None else None for b in bands], sizes)
        out[name] = Band(upper=upper.get("b"), lower=lower.get("b"))
    return out


def _mean_fraction(parts: list[DetectorResult | None], sizes: list[int]) -> dict[str, float]:
    """statistic -> its judged fraction over the blocks, each weighted by its length."""
    totals: dict[str, list[float]] = {}
    for result, size in zip(parts, sizes):
        for name, fraction in (result.judged_fraction if result is not None else {}).items():
            total = totals.setdefault(name, [0.0, 0.0])
            total[0] += fraction * size
            total[1] += size
    return {name: weighted / max(weight, 1.0) for name, (weighted, weight) in totals.items()}


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
    incident's alarms the merged ones within it."""
    alarms = sorted((a for r in results for a in r.alarms), key=lambda a: (a.start, a.end))
    out: list[Incident] = []
    for incident in sorted(incidents, key=lambda i: (i.start, i.end)):
        if out and incident.start - out[-1].end <= gap_s + 1e-9:
            out[-1] = replace(out[-1], end=max(out[-1].end, incident.end))
        else:
            out.append(incident)
    for i, incident in enumerate(out):
        members = [a for a in alarms if a.start <= incident.end + 1e-9 and a.end >= incident.start - 1e-9]
        quoted = incident.quoted
        if quoted is not None:  # the merged alarm the quoted part now belongs to
            quoted = next((a for a in members if _holds(a, quoted)), quoted)
        merged = replace(incident, alarms=members or incident.alarms, quoted=quoted)
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


def merged_observability(parts: list):
    """The blocks' observability verdicts end to end (None: no block judged one); a window two
    blocks give (the last of one, led in by the next) once, judged where it is."""
    known = [p for p in parts if p is not None and p.t_start.size]
    if not known:
        return None
    t_start = np.concatenate([p.t_start for p in known])
    evidence = np.concatenate([p.evidence for p in known])
    slot = np.round(t_start / known[0].stride_s).astype(np.int64)
    judged = np.isfinite(evidence).reshape(evidence.shape[0], -1).any(axis=1)
    order = np.lexsort((judged, slot))  # by window start, a judged row last among its doubles
    last = np.append(slot[order][1:] != slot[order][:-1], True)
    kept = order[last]
    return replace(known[0], t_start=t_start[kept], evidence=evidence[kept], t_end=known[-1].t_end)
