"""Analysis: the typed results of one analysed log, its verdict, JSON summary and report input.

Built by `logscan.pipeline.detection`; read by the CLI, the report, evaluation and the artifacts. Pure:
no output files and no printing here.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from logscan import __version__
from logscan.detectors.registry import default_registry
from logscan.errors import ExitCode
from logscan.report import ReportInput, report_matches
from logscan.report.context import measurement_groups
from logscan.report.run_context import analysed_span
from logscan.results import DetectorResult, FaultEvent, Incident
from logscan.timebase.clock import clock_of
from logscan.verdict.autopilot_messages import FlightMessages, flight_messages
from logscan.verdict.coverage import Coverage, judged_span, skipped_checks, skipped_heading
from logscan.verdict.incidents import InputGap, signal_label
from logscan.verdict.input_fault import KinematicEvidence

if TYPE_CHECKING:  # what an analysis carries from the layers that built it (no runtime edge)
    from logscan.pipeline.block_alignment import AlignmentFigures
    from logscan.pipeline.stages import Prepared
    from logscan.recovery.records import Recovery
    from logscan.report.recovery_view import RecoveryView
    from logscan.verdict.nis_consistency import NisConsistency
    from logscan.verdict.observability import Observability


@dataclass
class DetectorFailure:
    """A detector that raised while running: its name, one line, and the exit code it maps to."""

    detector: str
    message: str
    exit_code: int = int(ExitCode.INTERNAL)


@dataclass
class Analysis:
    """Everything one analysed log produced."""

    prepared: Prepared
    results: list[DetectorResult] = field(default_factory=list)
    incidents: list[Incident] = field(default_factory=list)  # alarms grouped, in time order
    unchecked: list[str] = field(default_factory=list)  # what could not be checked (logscan.verdict.coverage)
    # what the [alarms] suspension left unjudged of the model-based statistics, when at most half of
    # the flight (`logscan.verdict.coverage.unjudged_flight`; more is an ``unchecked`` line); "": nothing
    unjudged: str = ""
    # the coverage in figures (block mode judges the blocks' sum; None: not found, a failed analysis)
    coverage: Coverage | None = field(default=None, repr=False)
    # the groups' NIS the consistency warnings judge (block mode judges the blocks' sum; None: no filter)
    consistency: NisConsistency | None = field(default=None, repr=False)
    # a block's gate and gap figures of its own steps (`logscan.pipeline.block_alignment`; None: at once)
    alignment: AlignmentFigures | None = field(default=None, repr=False)
    # (N,) the grid steps the [alarms] suspension held back (None: none): where judging resumed
    # after it, an incident's source is not the alarm that happened to update first
    suspended: np.ndarray | None = field(default=None, repr=False)
    input_gaps: list[InputGap] = field(default_factory=list)  # where the filter held a missing input
    # the innovations of the sensors that measure the motion twice over (incidents' rule 6), kept
    # from the EKF's before the detectors free them
    kinematic: KinematicEvidence | None = field(default=None, repr=False)
    failures: list[DetectorFailure] = field(default_factory=list)  # detectors that raised
    events: list[FaultEvent] = field(default_factory=list)  # ground truth, when the log has it
    scores: dict = field(default_factory=dict)  # detector -> logscan.verdict.scoring.Score (with truth)
    warnings: list[str] = field(default_factory=list)
    loops: dict[str, Analysis] = field(default_factory=dict)  # a hierarchical profile's further loops
    recovery: Recovery | None = None  # when the profile asks for [recovery]
    recovery_view: RecoveryView | None = None  # what the report draws of it
    observability: Observability | None = None  # when a fault could be seen at all

    # --- the prepared log, read through ------------------------------------------------------------
    @property
    def path(self) -> str:
        return self.prepared.path

    @property
    def log(self):
        return self.prepared.log

    @property
    def profile(self):
        return self.prepared.profile

    @property
    def profile_text(self) -> str:
        return self.prepared.loaded.text

    @property
    def profile_source(self) -> str:
        return self.prepared.loaded.source

    @property
    def model(self):
        return self.prepared.model

    @property
    def run(self):
        return self.prepared.run

    @property
    def trace(self):
        return self.prepared.trace

    @property
    def clock(self):
        """The log's own clock (`logscan.timebase.clock`): the one the pipeline kept, when it dated the log
        before releasing its samples (a ULog's GNSS time), else derived from the log and run now."""
        kept = getattr(self.prepared, "clock", None)
        return kept if kept is not None else clock_of(self.log, self.run.start_ns)

    # --- verdict and summary -----------------------------------------------------------------------
    @property
    def alarms(self) -> list:
        """Every detector's alarms, the further loops' too (their signals naming their loop:
        ``left_motor/nis.encoder``)."""
        own = [alarm for result in self.results for alarm in result.alarms]
        return own + [
            replace(alarm, signal=f"{name}/{alarm.signal}")
            for name, loop in self.loops.items()
            for alarm in loop.alarms
        ]

    @property
    def possible(self) -> list:
        """ "Possible fault" warnings of every detector (a level below alarms), the loops' too."""
        return [p for result in self.results for p in result.possible] + [
            p for loop in self.loops.values() for p in loop.possible
        ]

    @property
    def all_incidents(self) -> list:
        return self.incidents + [i for loop in self.loops.values() for i in loop.all_incidents]

    @property
    def partial(self) -> bool:
        return bool(self.log.source.partial)

    @property
    def skipped_checks(self) -> list[str]:
        """The checks the detectors could not run because the log holds nothing for them to judge
        (`logscan.verdict.coverage.skipped_checks`): listed; unlike ``unchecked``, the verdict stands."""
        return skipped_checks(self.results)

    @property
    def skipped_heading(self) -> str:
        """What the skipped checks are listed under: nothing to judge in this log, or in the window."""
        return skipped_heading(judged_span(self.run))

    def autopilot_messages(self) -> FlightMessages:
        """The autopilot's distinct messages of WARNING and above during flight and within the
        window, each with its incident; the numbers logged while disarmed and outside the window
        (`logscan.verdict.autopilot_messages`)."""
        context = getattr(self.prepared, "context", None)
        states = getattr(context, "states", None) or {}
        metadata = self.log.source.metadata or {}
        window = analysed_span(self.run)  # as the raw-topic checks judge it, and the report's context
        return flight_messages(metadata, self.run.start_ns, self.incidents, states.get("armed"), window)

    @property
    def duration_s(self) -> float:
        return float(self.run.t[-1] - self.run.t[0])

    def verdict(self) -> str:
        """'no alarms' only when everything was checked and every detector ran."""
        n, k = len(self.alarms), len(self.all_incidents)
        if n:
            parts = [f"{n} alarm{'s' if n != 1 else ''} in {k} incident{'s' if k != 1 else ''}"]
        else:
            parts = ["no alarms" if not (self.unchecked or self.failures) else "no alarms in what was checked"]
        if self.possible:
            parts.append(f"{len(self.possible)} possible fault{'s' if len(self.possible) != 1 else ''}")
        suppressed = sum(len(r.suppressed) for r in self.results)
        if suppressed:
            parts.append(f"{suppressed} suppressed")
        if self.unchecked:
            parts.append("not fully checked")
        if self.failures:
            parts.append(", ".join(f.message.split(":")[0] for f in self.failures))
        return "; ".join(parts)

    def exit_code(self, allow_partial: bool = False, fail_on_warning: bool = False) -> ExitCode:
        """3 (or the error's code) when a detector failed, 2 when part of the log could not be
        checked (unless ``allow_partial``), 1 with alarms (or, ``fail_on_warning``, with possible
        faults), 0 otherwise."""
        if self.failures:
            return ExitCode(max(f.exit_code for f in self.failures))
        if self.unchecked and not allow_partial:
            return ExitCode.BAD_INPUT
        if self.alarms or (fail_on_warning and self.possible):
            return ExitCode.ALARMS
        return ExitCode.OK

    def against_baseline(self) -> dict[str, int] | None:
        """logscan's model-based alarms against the autopilot's own verdict (a detector with
        `is_baseline`: PX4's estimator tests), when it ran and read something: how many of them it
        also flagged (overlapping in time, 1 s of slack), how many it did not, and its alarms no
        model-based detector matched. Detectors that read the autopilot's topics (`raw_topics`)
        are neither side."""
        registry = default_registry()

        def kind(result) -> str:
            try:
                cls = registry.get(result.detector)
            except Exception:  # noqa: BLE001 - a detector the registry lost counts as model-based
                return "model"
            if getattr(cls, "is_baseline", False):
                return "baseline"
            return "autopilot" if getattr(cls, "raw_topics", ()) else "model"

        baseline = [r for r in self.results if kind(r) == "baseline" and r.info.get("sources")]
        if not baseline:
            return None
        theirs = [a for r in baseline for a in r.alarms]
        ours = [a for r in self.results if kind(r) == "model" for a in r.alarms]

        def overlaps(a, b) -> bool:
            return a.start <= b.end + 1.0 and b.start <= a.end + 1.0

        both = sum(1 for a in ours if any(overlaps(a, b) for b in theirs))
        alone = sum(1 for b in theirs if not any(overlaps(a, b) for a in ours))
        return {"logscan_alarms": len(ours), "also_flagged_by_px4": both, "px4_alarms": len(theirs), "px4_alone": alone}

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary of this log (the `--json` artifact's per-log entry). Times stay seconds
        since the log's time zero (``start``, ``end``); alarms and incidents add them in the log's
        own clock (``start_clock``, ``start_utc``...: `logscan.timebase.clock.Clock.stamp`)."""
        clock = self.clock
        return {
            "file": self.path,
            "clock": clock.to_dict(),
            "verdict": self.verdict(),
            "n_alarms": len(self.alarms),
            "n_incidents": len(self.incidents),
            "n_possible": len(self.possible),
            "possible_faults": [clock.stamp(p.to_dict()) for p in self.possible],
            "suppressed": [
                clock.stamp({**a.to_dict(), "reason": reason}) for r in self.results for a, reason in r.suppressed
            ],
            "incidents": [incident.to_dict(clock) for incident in self.incidents],
            "unchecked": list(self.unchecked),
            "skipped_checks": self.skipped_checks,
            **_messages_summary(self.autopilot_messages(), clock),
            "failed_detectors": [{"detector": f.detector, "error": f.message} for f in self.failures],
            "logscan_version": __version__,
            "profile_source": self.profile_source,
            "model": self.model.name,
            "log": self.log.summary() | {"channels": len(self.log.channels)},
            "filter": self.prepared.filter_summary(),
            "detectors": [_stamped(result.to_dict(), clock) for result in self.results],
            "truth_events": [
                clock.stamp({"kind": e.kind, "target": e.target, "start": e.t_start, "end": e.t_end})
                for e in self.events
            ],
            "scores": {name: score.to_dict() for name, score in self.scores.items()},
            "against_px4": self.against_baseline(),
            "warnings": list(self.warnings),
            **({"loops": {name: loop.loop_summary(clock) for name, loop in self.loops.items()}} if self.loops else {}),
            **({"recovery": self.recovery_summary(clock)} if self.recovery is not None else {}),
            **({"observability": self.observability.to_dict()} if self.observability is not None else {}),
        }

    def loop_summary(self, clock) -> dict[str, Any]:
        """A further loop's own part of the summary: its model, rate, verdict and detectors."""
        return {
            "model": self.model.name,
            "rate_hz": self.profile.vehicle.rate_hz,
            "verdict": self.verdict(),
            "n_alarms": len(self.alarms),
            "incidents": [incident.to_dict(clock) for incident in self.incidents],
            "filter": self.prepared.filter_summary(),
            "detectors": [_stamped(result.to_dict(), clock) for result in self.results],
        }

    def recovery_summary(self, clock) -> dict[str, Any]:
        """One record per recovered anomaly (`logscan.recovery.AnomalyRecord`), times also in the
        log's clock."""
        keys = ("t_detect", "t_end", "t_checkpoint", "t_recovered_end", "t_agreed")
        recovery = self.recovery
        assert recovery is not None  # `summary` asks only when there is one
        return {
            "method": recovery.settings.method,
            "k_sigma": recovery.settings.k_sigma,
            "anomalies": [clock.stamp(record.to_dict(), keys) for record in recovery.anomalies],
        }

    def report_input(self, grace_s: float | None = None):
        """What the HTML report shows of this log."""
        messages = self.autopilot_messages()
        return ReportInput(
            log_facts=self.log.summary(),
            profile_text=self.profile_text,
            profile_source=self.profile_source,
            model=self.model.describe(),
            logscan_version=__version__,
            t=self.run.t,
            results=self.results,
            truth_events=list(self.events),
            matches=report_matches(self.results, self.events, grace_s) if self.events else None,
            verdict=self.verdict(),
            warnings=self.warnings,
            incidents=self.incidents,
            unchecked=self.unchecked + [f.message for f in self.failures],
            skipped=self.skipped_checks,
            judged=judged_span(self.run),
            unjudged=self.unjudged,
            messages=messages.listed,
            messages_outside=messages.outside,
            groups=measurement_groups(self.profile, self.prepared.filter_summary()),
            context=getattr(self.prepared, "context", None),
            innovations=getattr(self.prepared, "innovations", None),
            clock=self.clock,
            recovery=self.recovery_view,
            observability=self.observability,
            grid=getattr(self.prepared, "grid", None),
        )


def _messages_summary(messages: FlightMessages, clock) -> dict[str, Any]:
    """The JSON of the autopilot's messages during flight and the counts of those while disarmed
    and outside the window."""
    return {
        "autopilot_messages": [m.to_dict(clock) for m in messages.listed],
        "autopilot_messages_disarmed": messages.disarmed,
        "autopilot_messages_outside_window": messages.outside,
    }


def _stamped(result: dict, clock) -> dict:
    """A detector result's JSON with its alarms' times also in the log's clock, and its statistics'
    plain words (``labels``; each alarm's ``label``)."""
    detector = result["detector"]
    result["labels"] = {name: signal_label(name, detector) for name in result.get("series", {})}
    for key in ("alarms", "possible_faults", "suppressed"):
        result[key] = [
            clock.stamp(item) | {"label": signal_label(item.get("signal", ""), detector)}
            for item in result.get(key, [])
        ]
    return result
