"""Anomalies to recover from: a detector's alarm intervals, or the ground truth (oracle, evaluation only).

An alarm whose statistic names a measurement group of its loop (``nis.gps`` -> gps,
`logscan.verdict.incidents.group_of`) flags that group; an alarm that names none (an overall or state
check), or any alarm of a detector used as generic, flags nothing: the anomaly is generic. Alarms
that overlap (or lie within ``merge_gap_s``) form one anomaly, their groups joined; one generic
alarm makes the whole anomaly generic.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from logscan.alarms import AlarmInterval
from logscan.recovery.records import Anomaly, LoopRun
from logscan.results import FaultEvent
from logscan.verdict.incidents import group_of

# one alarm or fault, before merging: (start, end, {loop: groups} or None, {loop: seen until} or None)
_Piece = tuple[float, float, dict[str, tuple[str, ...]] | None, dict[str, float] | None]


def merge_pieces(pieces: Sequence[_Piece], gap_s: float) -> list[Anomaly]:
    """Overlapping pieces (closer than ``gap_s``) joined into anomalies, in time order."""
    out: list[Anomaly] = []
    for start, end, targets, seen in sorted(pieces, key=lambda p: (p[0], p[1])):
        piece = Anomaly(start, max(start, end), targets, seen)
        if out and start <= out[-1].t_end + gap_s:
            out[-1] = join(out[-1], piece)
        else:
            out.append(piece)
    return out


def join(a: Anomaly, b: Anomaly) -> Anomaly:
    """One anomaly of two: the earlier detection, the later end, the groups joined, and per loop the
    latest time an alarm still showed it."""
    return Anomaly(
        min(a.t_detect, b.t_detect), max(a.t_end, b.t_end), join_targets(a.targets, b.targets), join_seen(a, b)
    )


def join_seen(a: Anomaly, b: Anomaly) -> dict[str, float] | None:
    """Per loop, the later of the two times an alarm on that loop last showed the anomaly (an
    anomaly without ``seen_until`` showed it on every loop until its end)."""
    if not a.seen_until and not b.seen_until:
        return None
    seen: dict[str, float] = {}
    for one in (a, b):
        mine = one.seen_until or {loop: one.t_end for loop in set(a.seen_until or {}) | set(b.seen_until or {})}
        for loop, t in mine.items():
            seen[loop] = max(seen.get(loop, -np.inf), t)
    return seen


def join_targets(a, b):
    if a is None or b is None:
        return None
    joined = {loop: tuple(groups) for loop, groups in a.items()}
    for loop, groups in b.items():
        joined[loop] = tuple(dict.fromkeys(joined.get(loop, ()) + tuple(groups)))
    return joined


def anomalies_from_alarms(
    alarms: Mapping[str, Sequence[AlarmInterval]],
    loops: Sequence[LoopRun],
    *,
    specific: bool = True,
    merge_gap_s: float = 0.0,
    end_delays: Mapping[str, Mapping[tuple[str, str], float]] | None = None,
) -> list[Anomaly]:
    """One chosen detector's alarms, per loop name (loops may share group names, so each loop's
    alarms come apart), as anomalies. ``specific=False`` uses the detector as generic.
    ``end_delays``: loop -> (detector, statistic) -> its declared end delay in seconds
    (`Detector.end_delays`; missing: 0): an alarm shows its anomaly lasting until its end minus it."""
    by_name = {lp.name: lp for lp in loops}
    unknown = sorted(set(alarms) - set(by_name))
    if unknown:
        raise ValueError(f"alarms given for unknown loop(s) {', '.join(unknown)} (loops: {', '.join(by_name)})")
    pieces: list[_Piece] = []
    for loop, intervals in alarms.items():
        groups = list(by_name[loop].run.groups)
        delays = (end_delays or {}).get(loop, {})
        for alarm in intervals:
            group = group_of(alarm.signal, groups) if specific else None
            start, end = float(alarm.start), float(alarm.end)
            delay = float(delays.get((alarm.detector, alarm.signal), 0.0))
            if not delay >= 0:  # NaN or negative: no delay known
                delay = 0.0
            seen = {loop: max(start, end - delay)}
            pieces.append((start, end, None if group is None else {loop: (group,)}, seen))
    return merge_pieces(pieces, merge_gap_s)


def resolve_target(target: str, channels: Sequence[str], loops: Sequence[LoopRun]) -> dict[str, tuple[str, ...]]:
    """The loop groups a fault's target names: ``loop.group[.output]`` first, else the groups
    holding one of the fault's log ``channels``, else ``group[.output]`` in every loop that has the
    group (the simulator's targets are ``group.output``, e.g. ``gps.x``). Empty: no sensor (an
    actuator or estimator fault)."""
    rules = (
        lambda lp, g, grp: target == f"{lp.name}.{g}" or target.startswith(f"{lp.name}.{g}."),
        lambda lp, g, grp: bool(set(channels) & set(grp.channels)),
        lambda lp, g, grp: target == g or target.startswith(f"{g}."),
    )
    for rule in rules:
        found: dict[str, tuple[str, ...]] = {}
        for lp in loops:
            hits = tuple(g for g, grp in lp.run.groups.items() if rule(lp, g, grp))
            if hits:
                found[lp.name] = hits
        if found:
            return found
    return {}


def anomalies_from_truth(
    events: Sequence[FaultEvent],
    detection_time_s: float,
    loops: Sequence[LoopRun],
    *,
    merge_gap_s: float = 0.0,
) -> list[Anomaly]:
    """ORACLE mode, for evaluation only: each ground-truth fault as if a perfect specific detector
    flagged its sensor ``detection_time_s`` after it began, until it ended (None: the end of the
    log). A fault whose target is no sensor of any loop (actuator, estimator) is generic."""
    if not (math.isfinite(detection_time_s) and detection_time_s >= 0):
        raise ValueError(f"detection_time_s must be a finite number >= 0, got {detection_time_s!r}")
    t_last = max(
        (float(lp.run.t[-1]) + (lp.run.start_ns - loops[0].run.start_ns) * 1e-9 for lp in loops if lp.run.n_steps),
        default=0.0,
    )
    pieces: list[_Piece] = []
    for ev in events:
        t_detect = float(ev.t_start) + detection_time_s
        end = t_last if ev.t_end is None else float(ev.t_end)
        targets = resolve_target(ev.target, ev.channels, loops)
        pieces.append((t_detect, max(end, t_detect), targets or None, None))
    return merge_pieces(pieces, merge_gap_s)
