"""Scoring alarm intervals against ground-truth fault events (docs/algorithms.md section 7.1).

Rules (closed intervals throughout, times in seconds on the analysis grid):

- A fault event is [t_start, t_end] from the ground truth (t_end None: the fault lasts to the end
  of the log). Events are considered in order of t_start (ties: ground-truth order).
- An alarm [start, end] matches the FIRST event whose window [t_start, t_end + grace_s] it
  overlaps: ``start <= t_end + grace_s and end >= t_start`` (touching counts). It then counts for
  that event only, even if it also spans later events. An alarm that overlaps no window is a false
  alarm (FP). Several alarms on one event count once.
- Latency of a detected event = (start of its earliest matched alarm) - t_start, clipped at 0: an
  alarm raised before the fault began but still on when it began detects it "at once" (latency
  0); the unclipped value is kept as ``raw_latency_s`` on the match so such cases stay visible.
- TP = detected events, FN = missed events, FP = false alarm intervals.
  precision = TP / (TP + FP), recall = TP / (TP + FN), F1 = 2 P R / (P + R).
  0/0 is undefined and reported as None (JSON null), never as 1.0: precision with no alarms at
  all, recall on a log without events, F1 when either is None; F1 = 0.0 when P + R = 0.
- False alarms per hour = FP / hours of log (None without a duration). The "healthy" variant
  counts only logs without fault events, the false-alarm rate the evaluation reports.
- Aggregation over logs sums the counts and durations and pools the latencies (mean and max over
  every detected event of every log), so metrics of an aggregate are micro-averages.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

from logscan.results import AlarmInterval, FaultEvent

DEFAULT_GRACE_S = 1.0


@dataclass
class EventMatch:
    """How one event was scored: detected or not, its latency, and which alarms matched it."""

    event: FaultEvent
    alarm_indices: list[int] = field(default_factory=list)  # indices into the scored alarm list
    latency_s: float | None = None  # clipped at 0
    raw_latency_s: float | None = None  # first matched alarm start - t_start, may be negative

    @property
    def detected(self) -> bool:
        return bool(self.alarm_indices)

    def to_dict(self) -> dict:
        return {
            **self.event.to_dict(),
            "detected": self.detected,
            "latency_s": self.latency_s,
            "raw_latency_s": self.raw_latency_s,
            "alarms": list(self.alarm_indices),
        }


def _interval(alarm: AlarmInterval | tuple[float, float]) -> tuple[float, float]:
    if isinstance(alarm, AlarmInterval):
        return float(alarm.start), float(alarm.end)
    start, end = alarm
    return float(start), float(end)


def match_alarms(
    events: Sequence[FaultEvent], alarms: Sequence, grace_s: float = DEFAULT_GRACE_S
) -> tuple[list[EventMatch], list[int | None]]:
    """Match alarms (AlarmInterval-like objects with start/end, or (start, end) pairs) to events.

    Returns one EventMatch per event (in the given order) and, per alarm, the index of the event
    it detected or None for a false alarm. Cost O(alarms x events); both are short lists.
    """
    order = sorted(range(len(events)), key=lambda i: events[i].t_start)
    matches = [EventMatch(event) for event in events]
    alarm_event: list[int | None] = []
    for a, alarm in enumerate(alarms):
        start, end = _interval(alarm)
        hit = next(
            (i for i in order if start <= events[i].end_or_inf + grace_s and end >= events[i].t_start),
            None,
        )
        alarm_event.append(hit)
        if hit is not None:
            match = matches[hit]
            match.alarm_indices.append(a)
            raw = start - events[hit].t_start
            if match.raw_latency_s is None or raw < match.raw_latency_s:
                match.raw_latency_s = raw
                match.latency_s = max(raw, 0.0)
    return matches, alarm_event


def _ratio(num: float, den: float) -> float | None:
    return None if den == 0 else num / den


@dataclass
class Score:
    """Counts of one detector on one log (or summed over logs), with the derived metrics.

    duration_s / healthy_duration_s: seconds of log scored (healthy: logs without events);
    healthy_fp: false alarms on those healthy logs. latencies_s: one per detected event.
    """

    detector: str = ""
    log: str = ""
    tp: int = 0
    fn: int = 0
    fp: int = 0
    n_alarms: int = 0
    duration_s: float | None = None
    healthy_fp: int = 0
    healthy_duration_s: float = 0.0
    n_logs: int = 1
    latencies_s: list[float] = field(default_factory=list)
    matches: list[EventMatch] = field(default_factory=list)

    @property
    def n_events(self) -> int:
        return self.tp + self.fn

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
            "n_alarms": self.n_alarms,
            "precision": self.precision,
            "recall": self.recall,
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
    detector: str = "",
    log: str = "",
) -> Score:
    """Score one detector's alarms on one log against that log's events."""
    matches, alarm_event = match_alarms(events, alarms, grace_s)
    fp = sum(1 for e in alarm_event if e is None)
    healthy = len(events) == 0 and duration_s is not None
    return Score(
        detector=detector,
        log=log,
        tp=sum(m.detected for m in matches),
        fn=sum(not m.detected for m in matches),
        fp=fp,
        n_alarms=len(alarm_event),
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
    detectors: Iterable[str] = (),
    log: str = "",
) -> dict[str, Score]:
    """Score each detector's alarms separately (grouped by ``alarm.detector``). Names in
    ``detectors`` are scored even without any alarm (all their events missed)."""
    grouped: dict[str, list] = {name: [] for name in detectors}
    for alarm in alarms:
        grouped.setdefault(alarm.detector, []).append(alarm)
    return {
        name: score_log(events, items, duration_s=duration_s, grace_s=grace_s, detector=name, log=log)
        for name, items in grouped.items()
    }


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
        n_alarms=sum(s.n_alarms for s in scores),
        duration_s=None if any(d is None for d in durations) else float(sum(durations)),
        healthy_fp=sum(s.healthy_fp for s in scores),
        healthy_duration_s=float(sum(s.healthy_duration_s for s in scores)),
        n_logs=sum(s.n_logs for s in scores),
        latencies_s=[x for s in scores for x in s.latencies_s],
        matches=[],
    )
