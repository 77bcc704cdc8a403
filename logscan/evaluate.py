"""Evaluation of detectors against ground truth over many logs: per detector, per check, per fault kind.

ALGORITHMS.md section 7 scores one detector on one log (`logscan.scoring`); this module runs the
analysis on every log that has ground truth and pools the scores, at three levels:

 - per detector: every alarm the detector raised;
 - per check (signal family) of a detector: ``encoded_ekf:e_x`` (the state check e_x together with
   the rejected-sample checks ``rejected.<group>``: both flag a corrupted estimate update),
   ``encoded_ekf:e_v`` (variance check), ``nis:<group>`` and ``nis:all``; another detector's signal
   ``<detector>.<name>`` becomes the check ``<detector>:<name>``;
 - per fault kind (``<model>/<kind>``): detection rate and latency of each detector and check,
   the layout of the encoded-EKF paper's Table III.

Alarms of one group (a detector, or the several signals of one check) that overlap in time are
merged into one span before scoring, so a fault that trips e_x and a rejected-sample check at once
counts once, and a false alarm is a span when the group is on with no fault. A check is scored only
on the logs where it ran (its statistic exists there), so e.g. ``nis:position`` is not charged with
misses on steer-by-wire logs. Logs without ground truth are skipped and listed; a log that cannot be
analysed is recorded as one line and counted, never raised.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from logscan.scoring import DEFAULT_GRACE_S, Score, aggregate, score_log

CHECK_SEPARATOR = ":"
# encoded_ekf signals whose check family is not the signal's own name
_FAMILY_PREFIXES = {"encoded_ekf": (("rejected.", "e_x"),)}


def check_family(detector: str, signal: str) -> str:
    """The check a signal belongs to: ``rejected.<group>`` of the encoded detector -> ``e_x``;
    ``<detector>.<name>`` -> ``<name>`` (``nis.accel`` -> ``accel``); otherwise the signal."""
    for prefix, family in _FAMILY_PREFIXES.get(detector, ()):
        if signal.startswith(prefix):
            return family
    own = f"{detector}."
    return signal[len(own):] if signal.startswith(own) else signal


def check_key(detector: str, signal: str) -> str:
    """Score key of a check: ``<detector>:<family>``."""
    return f"{detector}{CHECK_SEPARATOR}{check_family(detector, signal)}"


def merge_intervals(alarms: Iterable) -> list[tuple[float, float]]:
    """Union of alarm intervals (objects with start/end, or pairs) as sorted disjoint (start, end)."""
    spans = sorted((float(a.start), float(a.end)) if hasattr(a, "start") else (float(a[0]), float(a[1]))
                   for a in alarms)
    merged: list[tuple[float, float]] = []
    for start, end in spans:
        if merged and start <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], end))
        else:
            merged.append((start, end))
    return merged


def alarm_groups(results: Sequence) -> dict[str, list]:
    """Alarms per score key (detector, then each of its checks) from DetectorResults.

    Every check whose statistic exists on the run gets a key, with an empty list when it raised
    nothing (so its misses are counted)."""
    groups: dict[str, list] = {}
    for result in results:
        groups[result.detector] = list(result.alarms)
        for signal in result.series:
            groups.setdefault(check_key(result.detector, signal), [])
        for alarm in result.alarms:
            groups.setdefault(check_key(result.detector, alarm.signal), []).append(alarm)
    return groups


def score_groups(
    events: Sequence,
    groups: Mapping[str, Sequence],
    *,
    duration_s: float,
    grace_s: float = DEFAULT_GRACE_S,
    log: str = "",
) -> dict[str, Score]:
    """One Score per group of alarms (merged to disjoint spans first) on one log."""
    return {
        key: score_log(events, merge_intervals(alarms), duration_s=duration_s, grace_s=grace_s,
                       detector=key, log=log)
        for key, alarms in groups.items()
    }


@dataclass
class LogEvaluation:
    """The scores of one log: one Score per key (detector or check)."""

    path: str
    model: str
    duration_s: float
    events: list  # logscan.scoring.FaultEvent
    scores: dict[str, Score]
    aggressive: bool = False

    @property
    def healthy(self) -> bool:
        return not self.events


@dataclass
class LogFailure:
    """A log that could not be evaluated: one line, and the exit code its error maps to."""

    path: str
    message: str
    exit_code: int = 2


def kind_summary(score: Score) -> dict:
    """JSON view of one key's detection of one fault kind (a Score whose tp/fn count its events)."""
    return {"events": score.n_events, "detected": score.tp, "detection_rate": score.recall,
            "mean_latency_s": score.mean_latency_s, "max_latency_s": score.max_latency_s}


def kind_label(model: str, kind: str) -> str:
    return f"{model}/{kind or 'unnamed'}"


@dataclass
class Evaluation:
    """Scores of many logs, with the skipped and failed ones, and their pooled views."""

    logs: list[LogEvaluation] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)  # logs without ground truth
    failures: list[LogFailure] = field(default_factory=list)
    grace_s: float = DEFAULT_GRACE_S

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
        """Per ``<model>/<kind>``: a Score of one key whose tp/fn count that kind's events
        (detection rate = recall) with their latencies; its fp is not kind-specific and stays 0."""
        stats: dict[str, Score] = {}
        for log in self.logs if logs is None else logs:
            score = log.scores.get(key)
            if score is None:
                continue
            for match in score.matches:
                label = kind_label(log.model, match.event.kind)
                entry = stats.setdefault(label, Score(detector=key, log=label, n_logs=0))
                entry.n_logs += 1
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
            "n_logs": len(self.logs),
            "n_healthy_logs": sum(log.healthy for log in self.logs),
            "scores": {key: _score_summary(self.aggregate(key)) for key in keys},
            "by_kind": {key: {kind: kind_summary(s) for kind, s in sorted(self.by_kind(key).items())}
                        for key in keys},
            "logs": [
                {"file": log.path, "model": log.model, "duration_s": log.duration_s,
                 "events": [e.to_dict() for e in log.events],
                 "scores": {key: s.to_dict() for key, s in log.scores.items()}}
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


def evaluate_analysis(analysis, *, grace_s: float = DEFAULT_GRACE_S) -> LogEvaluation:
    """Score one analysed log (`logscan.analysis.Analysis` with ground truth) per detector and check."""
    duration = float(analysis.run.t[-1] - analysis.run.t[0])
    scores = score_groups(analysis.events, alarm_groups(analysis.results), duration_s=duration,
                          grace_s=grace_s, log=analysis.path)
    truth = analysis.log.truth or {}
    return LogEvaluation(analysis.path, analysis.model.name, duration, list(analysis.events), scores,
                         aggressive=bool(truth.get("aggressive", False)))


def has_truth(path: str) -> bool:
    """Whether the log carries ground truth (reads only its metadata, not its messages)."""
    from logscan.readers import read_embedded

    return read_embedded(path)[1] is not None


def evaluate_logs(
    paths: Sequence[str],
    *,
    profile_path: str | None = None,
    detector_names: list[str] | None = None,
    grace_s: float = DEFAULT_GRACE_S,
    use_header_stamp: bool = False,
    progress=None,
) -> Evaluation:
    """Analyse and score every log with ground truth; skip the others; record failures as lines."""
    from logscan.analysis import analyze_log
    from logscan.errors import LogscanError

    evaluation = Evaluation(grace_s=grace_s)
    for path in paths:
        if progress:
            progress(path)
        try:
            if not has_truth(path):
                evaluation.skipped.append(path)
                continue
            analysis = analyze_log(path, profile_path, use_header_stamp=use_header_stamp,
                                   detector_names=detector_names, grace_s=grace_s)
            evaluation.logs.append(evaluate_analysis(analysis, grace_s=grace_s))
        except LogscanError as exc:
            line = exc.one_line() if exc.path else f"{path}: {exc.one_line()}"
            evaluation.failures.append(LogFailure(path, line, exc.exit_code))
        except Exception as exc:  # noqa: BLE001 - one bad log must not stop a fleet evaluation
            evaluation.failures.append(
                LogFailure(path, f"{path}: internal error: {type(exc).__name__}: {exc} "
                           "(a bug in logscan; `logscan --debug analyze` shows the traceback)", 3)
            )
    return evaluation


# --- text rendering ---------------------------------------------------------------------------

def _num(value: float | None, fmt: str = "{:.2f}") -> str:
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) else fmt.format(value)


def render_scores(evaluation: Evaluation) -> str:
    """Per detector and per check: counts, precision/recall/F1, latency, false alarms per hour."""
    header = (f"{'detector / check':<26} {'logs':>4} {'events':>6} {'TP':>4} {'FN':>4} {'FP':>4} "
              f"{'prec':>5} {'recall':>6} {'F1':>5} {'lat mean':>8} {'lat max':>8} {'FA/h healthy':>12}")
    lines = [header, "-" * len(header)]
    for key in evaluation.keys():
        s = evaluation.aggregate(key)
        label = key if CHECK_SEPARATOR not in key else "  " + key
        lines.append(
            f"{label:<26} {s.n_logs:>4} {s.n_events:>6} {s.tp:>4} {s.fn:>4} {s.fp:>4} "
            f"{_num(s.precision):>5} {_num(s.recall):>6} {_num(s.f1):>5} "
            f"{_num(s.mean_latency_s, '{:.2f} s'):>8} {_num(s.max_latency_s, '{:.2f} s'):>8} "
            f"{_num(s.false_alarms_per_hour_healthy, '{:.1f}'):>12}"
        )
    return "\n".join(lines)


def render_kinds(evaluation: Evaluation) -> str:
    """Per fault kind (Table III view): detected/events and latency of each detector and check."""
    kinds = evaluation.kinds()
    if not kinds:
        return "per fault kind: no fault events in the evaluated logs"
    header = f"{'fault kind':<30} {'detector / check':<26} {'detected':>8} {'lat mean':>8} {'lat max':>8}"
    lines = [header, "-" * len(header)]
    keys = evaluation.keys()
    per_key = {key: evaluation.by_kind(key) for key in keys}
    for kind in kinds:
        first = True
        for key in keys:
            stats = per_key[key].get(kind)
            if stats is None:
                continue
            label = key if CHECK_SEPARATOR not in key else "  " + key
            lines.append(
                f"{kind if first else '':<30} {label:<26} {f'{stats.tp}/{stats.n_events}':>8} "
                f"{_num(stats.mean_latency_s, '{:.2f} s'):>8} {_num(stats.max_latency_s, '{:.2f} s'):>8}"
            )
            first = False
    return "\n".join(lines)


def render_evaluation(evaluation: Evaluation) -> str:
    """The one-screen text report of `logscan evaluate`."""
    n_healthy = sum(log.healthy for log in evaluation.logs)
    n_events = sum(len(log.events) for log in evaluation.logs)
    hours = sum(log.duration_s for log in evaluation.logs if log.healthy) / 3600.0
    parts = [
        f"evaluated {len(evaluation.logs)} log(s) with ground truth: {n_events} fault event(s), "
        f"{n_healthy} healthy log(s) ({hours * 60:.1f} min); grace {evaluation.grace_s:g} s",
    ]
    if evaluation.logs:
        parts += ["", render_scores(evaluation), "", render_kinds(evaluation)]
    if evaluation.skipped:
        parts.append("")
        parts.append(f"skipped {len(evaluation.skipped)} log(s) without ground truth: "
                     + ", ".join(Path(p).name for p in evaluation.skipped))
    if evaluation.failures:
        parts.append("")
        parts.append(f"{len(evaluation.failures)} log(s) could not be evaluated (errors on stderr)")
    return "\n".join(parts)
