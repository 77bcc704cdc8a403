"""Evaluation of detectors against ground truth over many logs: per detector, per check, per fault kind.

`logscan.verdict.scoring` scores one detector on one log (docs/algorithms.md section 7); this module scores
an analysed log per detector and check (`evaluate_analysis`) and pools the scores of many logs
(`Evaluation`; `logscan.tasks.evaluate_logs` analyses them), at three levels:

 - per detector: every alarm the detector raised;
 - per check of a detector, ``<detector>:<check>``: each statistic is scored with the check its
   detector declared for it (`DetectorResult.check_of`: e.g. the encoded detector scores its
   rejected-sample statistics with its state check e_x, since both flag a corrupted update), else
   with its own name without the ``<detector>.`` prefix (``nis.accel`` -> ``nis:accel``);
 - per fault kind (``<model>/<kind>``): detection rate and latency of each detector and check,
   the layout of the encoded-EKF paper's Table III.

Alarms of one group (a detector, or the several signals of one check) that overlap in time are
merged into one span before scoring, so a fault that trips e_x and a rejected-sample check at once
counts once, and a false alarm is a span when the group is on with no fault (nor a fault just
ended, nor a healthy transient listed in the truth: see `logscan.verdict.scoring`). A check is scored only
on the logs where it ran (its statistic exists there), so e.g. ``nis:position`` is not charged with
misses on steer-by-wire logs. Logs without ground truth are skipped and listed; a log that cannot be
analysed is recorded as one line and counted, never raised.

Scoring only: this module runs no pipeline and no fleet (it sits below both).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import NamedTuple

from logscan.alarms import AlarmInterval
from logscan.results import events_from_truth
from logscan.verdict.scoring import (
    DEFAULT_GRACE_S,
    DEFAULT_RECOVERY_S,
    Score,
    aggregate,
    label_observability,
    score_log,
)

CHECK_SEPARATOR = ":"


def check_key(result, signal: str, prefix: str = "") -> str:
    """Score key of a check: ``<detector>:<check>``, the check as the detector declared it
    (``<detector>:<loop>/<check>`` with a further loop's ``prefix``)."""
    return f"{result.detector}{CHECK_SEPARATOR}{prefix}{result.check_of(signal)}"


class Span(NamedTuple):
    """Merged alarms: [start, end] and the statistics they came from (which faults they name)."""

    start: float
    end: float
    signals: frozenset[str] = frozenset()


def merge_intervals(alarms: Iterable) -> list[Span]:
    """Union of alarm intervals (objects with start/end, or pairs) as sorted disjoint spans, each
    with the signals of the alarms merged into it."""
    spans = sorted(
        (float(a.start), float(a.end), a.signal) if isinstance(a, AlarmInterval) else (float(a[0]), float(a[1]), "")
        for a in alarms
    )
    merged: list[Span] = []
    for start, end, signal in spans:
        mine = frozenset((signal,) if signal else ())
        if merged and start <= merged[-1].end:
            last = merged[-1]
            merged[-1] = Span(last.start, max(last.end, end), last.signals | mine)
        else:
            merged.append(Span(start, end, mine))
    return merged


def alarm_groups(results: Sequence, loops: Mapping[str, Sequence] | None = None) -> dict[str, list]:
    """Alarms per score key (detector, then each of its checks) from DetectorResults; ``loops``:
    a hierarchical log's further loops, loop name -> their DetectorResults, whose alarms join their
    detector's key and name their loop (``left_motor/nis.encoder``, check ``nis:left_motor/encoder``).

    Every check whose statistic exists on the run gets a key, with an empty list when it raised
    nothing (so its misses are counted)."""
    groups: dict[str, list] = {}
    for loop, loop_results in [("", results), *(loops or {}).items()]:
        prefix = f"{loop}/" if loop else ""
        for result in loop_results:
            groups.setdefault(result.detector, [])
            for signal in result.series:
                groups.setdefault(check_key(result, signal, prefix), [])
            for alarm in result.alarms:
                named = replace(alarm, signal=prefix + alarm.signal) if prefix else alarm
                groups[result.detector].append(named)
                groups.setdefault(check_key(result, alarm.signal, prefix), []).append(named)
    return groups


def score_groups(
    events: Sequence,
    groups: Mapping[str, Sequence],
    *,
    duration_s: float,
    grace_s: float = DEFAULT_GRACE_S,
    recovery_s: float = DEFAULT_RECOVERY_S,
    transients: Sequence = (),
    log: str = "",
) -> dict[str, Score]:
    """One Score per group of alarms (merged to disjoint spans first) on one log."""
    options = {"duration_s": duration_s, "grace_s": grace_s, "recovery_s": recovery_s, "transients": transients}
    return {
        key: score_log(events, merge_intervals(alarms), detector=key, log=log, **options)
        for key, alarms in groups.items()
    }


@dataclass
class LogEvaluation:
    """The scores of one log: one Score per key (detector or check)."""

    path: str
    model: str
    duration_s: float
    events: list  # logscan.verdict.scoring.FaultEvent
    scores: dict[str, Score]
    aggressive: bool = False
    transients: list = field(default_factory=list)  # healthy transients of the truth (FaultEvent)

    @property
    def healthy(self) -> bool:
        return not self.events


def kind_summary(score: Score) -> dict:
    """JSON view of one key's detection of one fault kind (a Score whose tp/fn count its events):
    with the events that could not be seen at all (``unobservable``), the misses among them, and
    the detection rate over the others (``detection_rate_observable``)."""
    return {
        "events": score.n_events,
        "detected": score.tp,
        "at_onset": score.at_onset,
        "detection_rate": score.recall,
        "unobservable": score.unobservable,
        "missed_unobservable": score.fn_unobservable,
        "detection_rate_observable": score.recall_observable,
        "mean_latency_s": score.mean_latency_s,
        "max_latency_s": score.max_latency_s,
    }


def kind_label(model: str, kind: str) -> str:
    return f"{model}/{kind or 'unnamed'}"


@dataclass
class Evaluation:
    """Scores of many logs, with the skipped and failed ones, and their pooled views."""

    logs: list[LogEvaluation] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)  # logs without ground truth
    failures: list = field(default_factory=list)  # logscan.fleet.LogFailure
    grace_s: float = DEFAULT_GRACE_S
    recovery_s: float = DEFAULT_RECOVERY_S

    def keys(self) -> list[str]:
        """Score keys in a stable order: detectors by name, each followed by its checks in the
        order they first appear (e_x before e_v, sensor groups before nis:all)."""
        seen: dict[str, None] = {}
        for log in self.logs:
            seen.update(dict.fromkeys(log.scores))
        detectors = sorted(k for k in seen if CHECK_SEPARATOR not in k)
        ordered = []
        for name in detectors:
            ordered.append(name)
            ordered.extend(k for k in seen if k.split(CHECK_SEPARATOR, 1)[0] == name and k != name)
        ordered.extend(k for k in seen if k not in ordered)
        return ordered

    def aggregate(self, key: str, logs: Iterable[LogEvaluation] | None = None) -> Score:
        """Micro-averaged Score of one key over the logs where it ran."""
        chosen = self.logs if logs is None else logs
        return aggregate([log.scores[key] for log in chosen if key in log.scores], detector=key)

    def by_kind(self, key: str, logs: Iterable[LogEvaluation] | None = None) -> dict[str, Score]:
        """Per ``<model>/<kind>``: a Score of one key whose tp/fn/at_onset count that kind's events
        (detection rate = recall) with their latencies; its alarm counts are not kind-specific and
        stay 0."""
        stats: dict[str, Score] = {}
        for log in self.logs if logs is None else logs:
            score = log.scores.get(key)
            if score is None:
                continue
            for match in score.matches:
                label = kind_label(log.model, match.event.kind)
                entry = stats.setdefault(label, Score(detector=key, log=label, n_logs=0))
                entry.n_logs += 1
                entry.at_onset += match.active_at_onset
                entry.unobservable += match.observable is False
                entry.fn_unobservable += match.observable is False and not match.detected
                if match.detected:
                    entry.tp += 1
                    entry.latencies_s.append(match.latency_s)
                else:
                    entry.fn += 1
        return stats

    def kinds(self) -> list[str]:
        return sorted({kind_label(log.model, e.kind) for log in self.logs for e in log.events})

    def to_dict(self) -> dict:
        keys = self.keys()
        return {
            "grace_s": self.grace_s,
            "recovery_s": self.recovery_s,
            "n_logs": len(self.logs),
            "n_healthy_logs": sum(log.healthy for log in self.logs),
            "scores": {key: _score_summary(self.aggregate(key)) for key in keys},
            "by_kind": {key: {kind: kind_summary(s) for kind, s in sorted(self.by_kind(key).items())} for key in keys},
            "logs": [
                {
                    "file": log.path,
                    "model": log.model,
                    "duration_s": log.duration_s,
                    "events": [e.to_dict() for e in log.events],
                    "transients": [e.to_dict() for e in log.transients],
                    "scores": {key: s.to_dict() for key, s in log.scores.items()},
                }
                for log in self.logs
            ],
            "skipped_no_truth": list(self.skipped),
            "errors": [{"file": f.path, "error": f.message, "exit_code": f.exit_code} for f in self.failures],
        }


def _score_summary(score: Score) -> dict:
    out = score.to_dict()
    out.pop("events", None)
    out.pop("log", None)
    return out


def evaluate_analysis(
    analysis, *, grace_s: float = DEFAULT_GRACE_S, recovery_s: float = DEFAULT_RECOVERY_S
) -> LogEvaluation:
    """Score one analysed log (`logscan.pipeline.analysis.Analysis` with ground truth) per detector and
    check, with the healthy transients its truth lists scored apart."""
    duration = analysis.duration_s
    truth = analysis.log.truth or {}
    transients = events_from_truth(truth.get("transients") or [], path=analysis.path)
    scores = score_groups(
        analysis.events,
        alarm_groups(analysis.results, {name: loop.results for name, loop in getattr(analysis, "loops", {}).items()}),
        duration_s=duration,
        grace_s=grace_s,
        recovery_s=recovery_s,
        transients=transients,
        log=analysis.path,
    )
    # the events that could not be seen at all (logscan.verdict.observability), labelled in every key's score
    observability = getattr(analysis, "observability", None)
    verdicts = [observability.event_verdict(e) if observability is not None else None for e in analysis.events]
    for score in scores.values():
        label_observability(score, verdicts)
    return LogEvaluation(
        analysis.path,
        analysis.model.name,
        duration,
        list(analysis.events),
        scores,
        aggressive=bool(truth.get("aggressive", False)),
        transients=transients,
    )
