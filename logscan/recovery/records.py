"""The data of recovery: its inputs (one loop's run, one anomaly), its settings and its results.

Times are seconds since the first loop's ``run.start_ns`` (loops cut from one log share it, so these
are the log's analysis-grid seconds, the times of alarm intervals and fault events).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from logscan.align import AlignedRun
from logscan.detectors.budget import design_rate
from logscan.docs import doc_url
from logscan.errors import ProfileError
from logscan.models.base import Model
from logscan.traces import EkfTrace

METHODS = ("refilter", "rollforward", "replace")
UNTRUSTWORTHY = "recovery no longer trustworthy"


@dataclass
class LoopRun:
    """One control loop: its model, aligned run and the shared EKF's trace of that run (with the
    full ``P_post``: ``run_ekf(..., full_P=True)``)."""

    name: str
    model: Model
    run: AlignedRun
    trace: EkfTrace


@dataclass(frozen=True)
class Anomaly:
    """One detected anomaly: its first alarmed time, the time the detector's alarm ended and what
    it flagged: loop name -> flagged measurement groups (a specific detector), or None (a generic
    detector: every loop is affected, nothing is known about which sensors).

    seen_until: loop name -> the latest time the detector's alarms on that loop show the anomaly
    still lasting: each alarm's end minus its statistic's end delay (a windowed statistic's alarm
    outlasts the anomaly by up to its window, `Detector.end_delays`), the latest over the loop's
    alarms (a loop without alarms: its detection); None: the alarm's end on every loop (a
    per-sample test, or the ground truth)."""

    t_detect: float
    t_end: float
    targets: Mapping[str, tuple[str, ...]] | None = None
    seen_until: Mapping[str, float] | None = None

    @property
    def specific(self) -> bool:
        return self.targets is not None

    def last_seen(self, loop: str) -> float:
        """When the alarms last showed the anomaly on ``loop``; on a loop with no alarm of its own (a
        generic anomaly's other loops) only at its detection."""
        if not self.seen_until:
            return self.t_end
        return min(self.t_end, self.seen_until.get(loop, self.t_detect))

    def last_seen_anywhere(self) -> float:
        """When the alarms last showed the anomaly on any loop."""
        return min(self.t_end, max(self.seen_until.values())) if self.seen_until else self.t_end


@dataclass(frozen=True)
class RecoverySettings:
    """How to recover (docs/algorithms.md section 5).

    method: "refilter" (default: the shared filter re-run from the checkpoint without the flagged
        groups), "rollforward" (the paper's pure prediction), "replace" (the paper's element
        replacement, for reproduction).
    checkpoint_period_s: 0 takes a checkpoint at every sample of the slowest loop.
    detection_time_s: the detector's detection time: the checkpoint lies more than this plus the
        slowest loop's period before the first alarmed time.
    k_sigma: the reported bound is k_sigma * sqrt(diag P) of the recovery.
    allowed_error: "loop.state" -> allowed error E; T_max is computed for these states only.
    hold_s: flagged sensors must agree with the recovered prediction this long to end an anomaly
        (the span ends where that agreement began; a generic anomaly ends this long after the
        detector's alarm at the latest).
    max_duration_s: an anomaly is cut this long after its first alarmed time.
    agreement_quantile: a flagged group's sample agrees when its NIS against the recovered
        prediction is below this chi-square quantile.
    budget_per_hour, proof_hours: the false-alarm budget (as `nis`'s) that sizes the bound beyond
        which a flagged sample still shows the anomaly after the detector's alarm; a sample that
        disagrees within it ends the recovery (the recovered estimate did not re-agree).
    consistency_tol_s: loops' steps closer than this are the same instant (None: half the fastest
        loop's period).
    """

    method: str = "refilter"
    checkpoint_period_s: float = 0.0
    detection_time_s: float = 0.0
    k_sigma: float = 3.0
    allowed_error: Mapping[str, float] = field(default_factory=dict)
    hold_s: float = 1.0
    max_duration_s: float = 60.0
    agreement_quantile: float = 0.99
    consistency_tol_s: float | None = None
    budget_per_hour: float = 0.1
    proof_hours: float = 100.0

    def __post_init__(self) -> None:
        problems = []
        if self.method not in METHODS:
            problems.append(f"recovery method {self.method!r} is unknown (choose {', '.join(METHODS)})")
        for name in ("checkpoint_period_s", "detection_time_s", "hold_s"):
            if not _finite_at_least(getattr(self, name), 0.0):
                problems.append(f"recovery {name} must be a finite number >= 0, got {getattr(self, name)!r}")
        for name in ("k_sigma", "max_duration_s", "budget_per_hour", "proof_hours"):
            if not _finite_at_least(getattr(self, name), 0.0) or getattr(self, name) == 0:
                problems.append(f"recovery {name} must be a finite number > 0, got {getattr(self, name)!r}")
        q = self.agreement_quantile
        if not (_finite_at_least(q, 0.0) and 0.0 < q < 1.0):
            problems.append(f"recovery agreement_quantile must lie strictly between 0 and 1, got {q!r}")
        problems += _budget_problems(self.budget_per_hour, self.proof_hours)
        tol = self.consistency_tol_s
        if tol is not None and not (_finite_at_least(tol, 0.0) and tol > 0):
            problems.append(f"recovery consistency_tol_s must be > 0 (or None), got {tol!r}")
        for key, value in dict(self.allowed_error).items():
            if not isinstance(key, str) or key.count(".") < 1:
                problems.append(f"recovery allowed_error key {key!r} must be 'loop.state'")
            elif not (_finite_at_least(value, 0.0) and value > 0):
                problems.append(f"recovery allowed_error[{key}] must be a finite number > 0, got {value!r}")
        if problems:
            more = f" ({len(problems) - 1} more)" if len(problems) > 1 else ""
            err = ProfileError(problems[0] + more, hint=f"see {doc_url('algorithms.md')} section 5")
            err.problems = problems
            raise err


def _budget_problems(budget_per_hour, proof_hours) -> list[str]:
    """A demonstration too short to ever show the budget (as `nis` refuses it)."""
    if not all(_finite_at_least(v, 0.0) and v > 0 for v in (budget_per_hour, proof_hours)):
        return []  # reported as non-positive numbers
    try:
        design_rate(float(budget_per_hour), float(proof_hours))
    except ValueError as exc:
        return [f"recovery proof_hours: {exc}"]
    return []


def _finite_at_least(value, low: float) -> bool:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        return False
    return math.isfinite(value) and value >= low


@dataclass
class LoopRecovery:
    """One loop's recovered series on its own grid (N steps, n states); NaN outside recovered spans.

    x_recovered: the recovered estimate.
    bound:       k_sigma * sqrt(diag P) propagated through the recovery (the reported bound).
    worst_case:  the paper's Proposition 5.1 bound (worst case: vacuous in practice).
    """

    name: str
    state_names: list[str]
    t: np.ndarray  # (N,) seconds (the common time frame)
    x_recovered: np.ndarray  # (N, n)
    bound: np.ndarray  # (N, n)
    worst_case: np.ndarray  # (N, n)

    @property
    def recovered(self) -> np.ndarray:
        """(N,) bool: steps inside a recovered span."""
        return np.all(np.isfinite(self.x_recovered), axis=1)


@dataclass
class AnomalyRecord:
    """What recovery did for one anomaly (several input anomalies merge when one's recovery runs
    into the next one's detection).

    t_checkpoint: the consistent checkpoint used (k1), None when no checkpoint qualifies (then
    nothing is recovered and ``note`` says why); checkpoint_steps: loop -> k1 on its grid.
    rollforward_s: t_recovered_end - t_checkpoint. t_agreed: when the flagged sensors of every loop
    (a generic anomaly's: every sensor, after the detector's alarm) agreed again with the recovered
    prediction (held for hold_s), None if a loop's span ended otherwise.
    loop_ends: each affected loop's own recovered span end (a specific anomaly ends per loop, when
    that loop's flagged sensors agree again or do not re-agree); t_recovered_end is the latest.
    alarm_kept: the recovery went on past the detector's alarm end. capped: cut at max_duration_s
    (or at the end of the log). t_max: "loop.state" -> the first duration after t_detect where the
    bound exceeds the allowed error (negative: already at detection; None: not within the
    max_duration_s horizon). outlasted: the states whose T_max the anomaly outlasted.
    end_reasons: loop -> why its recovered span ended there (the flagged sensors agreed again; the
    recovered estimate did not re-agree with a sensor that no longer shows the anomaly; the
    detector's alarm; the cap; the end of the log); end_reason: that of the loop that ended last.
    """

    t_detect: float
    t_end: float
    targets: dict[str, tuple[str, ...]] | None
    method: str
    loops: tuple[str, ...]
    t_checkpoint: float | None = None
    checkpoint_steps: dict[str, int] = field(default_factory=dict)
    rollforward_s: float | None = None
    t_recovered_end: float | None = None
    t_agreed: float | None = None
    loop_ends: dict[str, float] = field(default_factory=dict)
    alarm_kept: bool = False
    capped: bool = False
    t_max: dict[str, float | None] = field(default_factory=dict)
    outlasted: tuple[str, ...] = ()
    merged: int = 1
    note: str = ""
    end_reasons: dict[str, str] = field(default_factory=dict)

    @property
    def specific(self) -> bool:
        return self.targets is not None

    @property
    def end_reason(self) -> str:
        """Why the recovery ended: the reason of the loop whose span ended last ('' if none)."""
        if not self.loop_ends:
            return ""
        last = max(self.loop_ends, key=lambda name: self.loop_ends[name])
        return self.end_reasons.get(last, "")

    @property
    def verdict(self) -> str:
        """UNTRUSTWORTHY when the anomaly outlasted a state's T_max, else ''."""
        return UNTRUSTWORTHY if self.outlasted else ""

    def to_dict(self) -> dict:
        return {
            "t_detect": self.t_detect,
            "t_end": self.t_end,
            "targets": None if self.targets is None else {k: list(v) for k, v in self.targets.items()},
            "method": self.method,
            "loops": list(self.loops),
            "t_checkpoint": self.t_checkpoint,
            "checkpoint_steps": dict(self.checkpoint_steps),
            "rollforward_s": self.rollforward_s,
            "t_recovered_end": self.t_recovered_end,
            "t_agreed": self.t_agreed,
            "loop_ends": dict(self.loop_ends),
            "alarm_kept": self.alarm_kept,
            "capped": self.capped,
            "t_max": dict(self.t_max),
            "outlasted": list(self.outlasted),
            "verdict": self.verdict,
            "merged": self.merged,
            "note": self.note,
            "end_reason": self.end_reason,
            "end_reasons": dict(self.end_reasons),
        }


@dataclass
class Recovery:
    """The result of `recover`: per loop the recovered series, per anomaly its record."""

    loops: dict[str, LoopRecovery]
    anomalies: list[AnomalyRecord]
    settings: RecoverySettings
