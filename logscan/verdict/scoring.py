"""Scoring alarm intervals against ground-truth fault events and healthy transients (docs/algorithms.md section 7.1).

Rules (closed intervals throughout, times in seconds on the analysis grid):

- A fault event is [t_start, t_end] from the ground truth (t_end None: the fault lasts to the end
  of the log). Events are considered in order of t_start (ties: ground-truth order).
- Each alarm [start, end] gets exactly one outcome, the first that applies:

  1. detection: it starts within an event's window [t_start, t_end + grace_s] (both ends
     included); it counts for every such event whose target its statistics name (`names_target`:
     simultaneous faults on several sensors, e.g. a hierarchical robot's mocap and both encoders,
     each detected by the alarm that names it), else for the first such event only.
     Several alarms on one event count once; latency = start of the earliest one - t_start
     (never negative).
  2. at onset: it started before an event's onset and is still on at it (start < t_start <= end).
     Not a detection and not a false alarm. Every event with such an alarm is flagged
     ``active_at_onset`` (whatever that alarm's own outcome), and is detected only by a later
     alarm that starts within its window.
  3. recovery: it starts within the recovery window (t_end + grace_s, t_end + grace_s +
     recovery_s] of a detected event (the filter settling after the fault was removed).
  4. transient: it overlaps a healthy transient's [t_start, t_end + grace_s] (a glitch listed in
     the truth's ``transients``, not a fault).
  5. false alarm (FP): anything else.

- TP = detected events, FN = missed events, FP = false alarms; ``at_onset`` counts events flagged
  active at onset, ``recovery_alarms`` and ``transient_alarms`` count alarms.
  precision = TP / (TP + FP), recall = TP / (TP + FN), F1 = 2 P R / (P + R).
  0/0 is undefined and reported as None (JSON null), never as 1.0: precision with neither a
  detection nor a false alarm, recall on a log without events, F1 when either is None; F1 = 0.0
  when P + R = 0.
- False alarms per hour = FP / hours of log (None without a duration). The "healthy" variant
  counts only logs without fault events, the false-alarm rate the evaluation reports.
- Aggregation over logs sums the counts and durations and pools the latencies (mean and max over
  every detected event of every log), so metrics of an aggregate are micro-averages.
- Observability (`label_observability`, docs/algorithms.md section 10): an event whose whole span
  lies where a fault of its kind and size could not be seen is labelled unobservable; it stays a TP
  or an FN (recall is unchanged), and ``fn_unobservable`` counts the misses among them, so
  ``recall_observable`` = detected / events that could be seen at some time of their span.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

from logscan.alarms import AlarmInterval
from logscan.results import FaultEvent

DEFAULT_GRACE_S = 1.0
DEFAULT_RECOVERY_S = 5.0

DETECTION = "detection"
AT_ONSET = "at_onset"
RECOVERY = "recovery"
TRANSIENT = "transient"
FALSE_ALARM = "false_alarm"


class AlarmOutcome(NamedTuple):
    """What one alarm was scored as, and the index of the fault event concerned (detection,
    at onset, recovery) or of the transient it overlapped (transient); None for a false alarm."""

    kind: str
    index: int | None = None


@dataclass
class EventMatch:
    """How one event was scored: detected or not, its latency, and the alarms around it."""

    event: FaultEvent
    alarm_indices: list[int] = field(default_factory=list)  # alarms that started in its window
    latency_s: float | None = None  # earliest of those starts - t_start, >= 0
    onset_alarm_indices: list[int] = field(default_factory=list)  # alarms already on at t_start
    recovery_indices: list[int] = field(default_factory=list)  # alarms in its recovery window
    # whether the fault could be seen at all (`logscan.verdict.observability`): True, False (its whole span
    # lies where it could not be seen: a miss there is labelled so), None (no verdict)
    observable: bool | None = None

    @property
    def detected(self) -> bool:
        return bool(self.alarm_indices)

    @property
    def active_at_onset(self) -> bool:
        return bool(self.onset_alarm_indices)

    def to_dict(self) -> dict:
        return {
            **self.event.to_dict(),
            "detected": self.detected,
            "latency_s": self.latency_s,
            "active_at_onset": self.active_at_onset,
            "alarms": list(self.alarm_indices),
            "onset_alarms": list(self.onset_alarm_indices),
            "recovery_alarms": list(self.recovery_indices),
            "observable": self.observable,
        }


def _interval(alarm) -> tuple[float, float]:
    """(start, end) of an AlarmInterval, a merged span (`logscan.verdict.evaluation.Span`) or a pair."""
    if hasattr(alarm, "start"):
        return float(alarm.start), float(alarm.end)
    start, end = alarm
    return float(start), float(end)


def classify_alarms(
    events: Sequence[FaultEvent],
    alarms: Sequence,
    *,
    grace_s: float = DEFAULT_GRACE_S,
    recovery_s: float = DEFAULT_RECOVERY_S,
    transients: Sequence[FaultEvent] = (),
) -> tuple[list[EventMatch], list[AlarmOutcome]]:
    """Score alarms (AlarmInterval-like objects with start/end, or (start, end) pairs) against
    events and transients by the rules of this module's docstring.

    Returns one EventMatch per event (in the given order) and one AlarmOutcome per alarm.
    Cost O(alarms x (events + transients)); all are short lists.
    """
    spans = [_interval(a) for a in alarms]
    order = sorted(range(len(events)), key=lambda i: events[i].t_start)
    starts = [event.t_start for event in events]
    ends = [event.end_or_inf + grace_s for event in events]
    matches = [EventMatch(event) for event in events]
    outcomes: list[AlarmOutcome | None] = [None] * len(spans)
    for a, (start, _end) in enumerate(spans):
        within = [i for i in order if starts[i] <= start <= ends[i]]
        if not within:
            continue
        names = signal_names(alarms[a])
        named = [i for i in within if names_target(names, events[i].target)]
        outcomes[a] = AlarmOutcome(DETECTION, (named or within)[0])
        for hit in named or within[:1]:
            match = matches[hit]
            match.alarm_indices.append(a)
            if match.latency_s is None or start - starts[hit] < match.latency_s:
                match.latency_s = start - starts[hit]
    for i in order:
        for a, (start, end) in enumerate(spans):
            if start < starts[i] <= end:
                matches[i].onset_alarm_indices.append(a)
                outcomes[a] = outcomes[a] or AlarmOutcome(AT_ONSET, i)
    for a, (start, end) in enumerate(spans):
        if outcomes[a] is not None:
            continue
        hit = next((i for i in order if matches[i].detected and ends[i] < start <= ends[i] + recovery_s), None)
        if hit is not None:
            outcomes[a] = AlarmOutcome(RECOVERY, hit)
            matches[hit].recovery_indices.append(a)
            continue
        near = next((j for j, t in enumerate(transients) if start <= t.end_or_inf + grace_s and end >= t.t_start), None)
        outcomes[a] = AlarmOutcome(FALSE_ALARM) if near is None else AlarmOutcome(TRANSIENT, near)
    return matches, outcomes


def signal_names(alarm) -> frozenset[str]:
    """The names an alarm's statistics are made of (``left_motor/nis.encoder`` -> left_motor, nis,
    encoder): an AlarmInterval's signal, a merged span's ``signals``; none for a bare pair."""
    signals = getattr(alarm, "signals", None)
    if signals is None:
        signals = (getattr(alarm, "signal", ""),)
    return frozenset(part for signal in signals for part in signal.replace("/", ".").split(".") if part)


def names_target(names: frozenset[str], target: str) -> bool:
    """Whether statistics made of ``names`` are about a fault's ``target`` (``loop.group``,
    ``group`` or ``group.output``): every part of it, or every part but a trailing output."""
    parts = [part for part in target.split(".") if part]
    return bool(parts) and (set(parts) <= names or (len(parts) > 1 and set(parts[:-1]) <= names))


def match_alarms(
    events: Sequence[FaultEvent], alarms: Sequence, grace_s: float = DEFAULT_GRACE_S
) -> tuple[list[EventMatch], list[int | None]]:
    """Detections only: one EventMatch per event and, per alarm, the index of the event it
    detected or None (at onset, recovery, transient or false: see `classify_alarms`)."""
    matches, outcomes = classify_alarms(events, alarms, grace_s=grace_s)
    return matches, [o.index if o.kind == DETECTION else None for o in outcomes]


def _ratio(num: float, den: float) -> float | None:
    return None if den == 0 else num / den


@dataclass
class Score:
    """Counts of one detector on one log (or summed over logs), with the derived metrics.

    at_onset: events with an alarm already on at their onset; recovery_alarms / transient_alarms:
    alarms after a detected fault / on a healthy transient (neither detections nor false alarms).
    duration_s / healthy_duration_s: seconds of log scored (healthy: logs without events);
    healthy_fp: false alarms on those healthy logs. latencies_s: one per detected event.
    """

    detector: str = ""
    log: str = ""
    tp: int = 0
    fn: int = 0
    fp: int = 0
    at_onset: int = 0
    recovery_alarms: int = 0
    transient_alarms: int = 0
    n_alarms: int = 0
    duration_s: float | None = None
    healthy_fp: int = 0
    healthy_duration_s: float = 0.0
    n_logs: int = 1
    unobservable: int = 0  # events whose whole span lies where they could not be seen
    fn_unobservable: int = 0  # of them, missed (the rest of FN were missed where they could be seen)
    latencies_s: list[float] = field(default_factory=list)
    matches: list[EventMatch] = field(default_factory=list)

    @property
    def n_events(self) -> int:
        return self.tp + self.fn

    @property
    def fn_observable(self) -> int:
        return self.fn - self.fn_unobservable

    @property
    def recall_observable(self) -> float | None:
        """Recall over the events that could be seen at some time of their span (or have no verdict)."""
        return _ratio(self.tp - (self.unobservable - self.fn_unobservable), self.n_events - self.unobservable)

    @property
    def precision(self) -> float | None:
        return _ratio(self.tp, self.tp + self.fp)

    @property
    def recall(self) -> float | None:
        return _ratio(self.tp, self.tp + self.fn)

    @property
    def f1(self) -> float | None:
        p, r = self.precision, self.recall
        if p is None or r is None:
            return None
        return 0.0 if p + r == 0 else 2 * p * r / (p + r)

    @property
    def mean_latency_s(self) -> float | None:
        return sum(self.latencies_s) / len(self.latencies_s) if self.latencies_s else None

    @property
    def max_latency_s(self) -> float | None:
        return max(self.latencies_s) if self.latencies_s else None

    @property
    def false_alarms_per_hour(self) -> float | None:
        if not self.duration_s:
            return None
        return self.fp / (self.duration_s / 3600.0)

    @property
    def false_alarms_per_hour_healthy(self) -> float | None:
        if not self.healthy_duration_s:
            return None
        return self.healthy_fp / (self.healthy_duration_s / 3600.0)

    def to_dict(self) -> dict:
        return {
            "detector": self.detector,
            "log": self.log,
            "n_logs": self.n_logs,
            "n_events": self.n_events,
            "tp": self.tp,
            "fn": self.fn,
            "fp": self.fp,
            "at_onset": self.at_onset,
            "recovery_alarms": self.recovery_alarms,
            "transient_alarms": self.transient_alarms,
            "n_alarms": self.n_alarms,
            "precision": self.precision,
            "recall": self.recall,
            "unobservable": self.unobservable,
            "fn_unobservable": self.fn_unobservable,
            "recall_observable": self.recall_observable,
            "f1": self.f1,
            "mean_latency_s": self.mean_latency_s,
            "max_latency_s": self.max_latency_s,
            "duration_s": self.duration_s,
            "false_alarms_per_hour": self.false_alarms_per_hour,
            "healthy_duration_s": self.healthy_duration_s,
            "false_alarms_per_hour_healthy": self.false_alarms_per_hour_healthy,
            "events": [m.to_dict() for m in self.matches],
        }


def score_log(
    events: Sequence[FaultEvent],
    alarms: Sequence,
    *,
    duration_s: float | None = None,
    grace_s: float = DEFAULT_GRACE_S,
    recovery_s: float = DEFAULT_RECOVERY_S,
    transients: Sequence[FaultEvent] = (),
    detector: str = "",
    log: str = "",
) -> Score:
    """Score one detector's alarms on one log against that log's events and transients."""
    matches, outcomes = classify_alarms(events, alarms, grace_s=grace_s, recovery_s=recovery_s, transients=transients)
    kinds = [o.kind for o in outcomes]
    fp = kinds.count(FALSE_ALARM)
    healthy = len(events) == 0 and duration_s is not None
    return Score(
        detector=detector,
        log=log,
        tp=sum(m.detected for m in matches),
        fn=sum(not m.detected for m in matches),
        fp=fp,
        at_onset=sum(m.active_at_onset for m in matches),
        recovery_alarms=kinds.count(RECOVERY),
        transient_alarms=kinds.count(TRANSIENT),
        n_alarms=len(outcomes),
        duration_s=duration_s,
        healthy_fp=fp if healthy else 0,
        healthy_duration_s=float(duration_s) if healthy else 0.0,
        latencies_s=[m.latency_s for m in matches if m.latency_s is not None],
        matches=matches,
    )


def score_by_detector(
    events: Sequence[FaultEvent],
    alarms: Sequence[AlarmInterval],
    *,
    duration_s: float | None = None,
    grace_s: float = DEFAULT_GRACE_S,
    recovery_s: float = DEFAULT_RECOVERY_S,
    transients: Sequence[FaultEvent] = (),
    detectors: Iterable[str] = (),
    log: str = "",
) -> dict[str, Score]:
    """Score each detector's alarms separately (grouped by ``alarm.detector``). Names in
    ``detectors`` are scored even without any alarm (all their events missed)."""
    grouped: dict[str, list] = {name: [] for name in detectors}
    for alarm in alarms:
        grouped.setdefault(alarm.detector, []).append(alarm)
    options = {"duration_s": duration_s, "grace_s": grace_s, "recovery_s": recovery_s, "transients": transients}
    return {name: score_log(events, items, detector=name, log=log, **options) for name, items in grouped.items()}


def aggregate(scores: Iterable[Score], *, detector: str | None = None) -> Score:
    """Sum counts and durations over logs and pool the latencies (micro-averaged metrics).

    duration_s is None when any log's duration is unknown."""
    scores = list(scores)
    durations = [s.duration_s for s in scores]
    names = sorted({s.detector for s in scores})
    return Score(
        detector=detector if detector is not None else ",".join(names),
        log="",
        tp=sum(s.tp for s in scores),
        fn=sum(s.fn for s in scores),
        fp=sum(s.fp for s in scores),
        at_onset=sum(s.at_onset for s in scores),
        recovery_alarms=sum(s.recovery_alarms for s in scores),
        transient_alarms=sum(s.transient_alarms for s in scores),
        n_alarms=sum(s.n_alarms for s in scores),
        duration_s=None if any(d is None for d in durations) else float(sum(durations)),
        healthy_fp=sum(s.healthy_fp for s in scores),
        healthy_duration_s=float(sum(s.healthy_duration_s for s in scores)),
        n_logs=sum(s.n_logs for s in scores),
        unobservable=sum(s.unobservable for s in scores),
        fn_unobservable=sum(s.fn_unobservable for s in scores),
        latencies_s=[x for s in scores for x in s.latencies_s],
        matches=[],
    )


def label_observability(score: Score, verdicts: Sequence[bool | None]) -> Score:
    """Label each event of ``score`` with its verdict (one per event, in the events' order: True
    observable, False unobservable, None no verdict) and count the unobservable ones and the misses
    among them; returns the score."""
    for match, verdict in zip(score.matches, verdicts, strict=True):
        match.observable = verdict
    blind = [m for m in score.matches if m.observable is False]
    score.unobservable = len(blind)
    score.fn_unobservable = sum(not m.detected for m in blind)
    return score
