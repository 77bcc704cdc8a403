"""What one analysis report shows (`ReportInput`) and its alarms matched to the ground truth."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from logscan.alarms import AlarmInterval
from logscan.report.run_context import RunContext
from logscan.report.sensor_views import GroupRows
from logscan.results import DetectorResult, FaultEvent, Incident
from logscan.timebase.clock import Clock
from logscan.verdict import scoring
from logscan.verdict.coverage import WHOLE_LOG


@dataclass
class ReportInput:
    """Everything one report shows.

    log_facts:        ``Log.summary()`` of the analysed log.
    profile_text:     the profile as TOML text.
    profile_source:   where the profile came from (a path, or "embedded").
    model:            ``Model.describe()`` (empty dict when no model is used).
    logscan_version:  version string of logscan.
    t:                (N,) analysis grid, seconds since the log's start.
    results:          one DetectorResult per detector that ran.
    truth_events:     ground-truth fault events. Empty: the log has no truth.
    matches:          per alarm, in the order of :func:`flat_alarms` (results in order, each
                      result's alarms in order): ``{"event": index into truth_events or None,
                      "latency_s": float or None}``. None: computed with
                      :func:`report_matches` when the log has truth.
    verdict:          the analysis' verdict ("no alarms", "N alarms in K incidents; not fully checked"...).
    warnings:         run-level warnings shown under the verdict.
    incidents:        alarms grouped in time (logscan.verdict.incidents), listed before the alarms.
    unchecked:        what could not be checked (and detectors that failed), shown under the verdict.
    skipped:          the checks with nothing to judge in this log (`logscan.verdict.coverage.skipped_checks`),
                      listed beside ``unchecked`` in the margins section.
    judged:           what was judged, as the coverage lines say it (`logscan.verdict.coverage.judged_span`):
                      "the log", or "the --start/--end window".
    unjudged:         what the profile's [alarms] suspension left unjudged of the model-based
                      statistics, when at most half of the flight ("": nothing; more is an
                      ``unchecked`` line): said where "every check ran" would be.
    messages:         the autopilot's messages during flight with their incidents
                      (`logscan.verdict.autopilot_messages.AutopilotMessage`), a table under the incidents;
                      of a --start/--end window, those in it (``messages_outside`` counts the others).
    groups:           the profile's measurement groups as used, with the filter's counts
                      (`logscan.report.context.measurement_groups`). Empty: not shown.
    context:          the run's path and mode (`logscan.report.run_context.RunContext`), drawn in the
                      "Context" section (`logscan.report.context_figures`). None: not shown.
    innovations:      the EKF's packed innovations (`logscan.report.sensor_views.Innovations`): a group
                      an alarm names is drawn (measured vs predicted, per channel) in the first
                      section whose alarms name it; block mode: the rows its figures draw, with their
                      times (`logscan.report.kept_views.KeptRows`). None: not drawn.
    clock:            the log's own clock (`logscan.timebase.clock`): the time axis, the tables and the
                      headlines show times in it. Default: seconds since the log's start.
    recovery:         the recovered estimates per loop and state and one record per anomaly
                      (`logscan.report.recovery_view`). None: no recovery section.
    observability:    when a fault of a kind could not be seen (`logscan.verdict.observability`), drawn as
                      bands in the "Context" section. None: not drawn.
    grid:             (steps, step in s) of the analysis grid when ``t`` is not it: the envelope times
                      of a log analysed in blocks (`logscan.pipeline.block_reduce`). None: ``t`` is the grid.
    """

    log_facts: dict
    profile_text: str
    profile_source: str
    model: dict
    logscan_version: str
    t: np.ndarray
    results: list[DetectorResult]
    truth_events: list[FaultEvent] = field(default_factory=list)
    matches: list[dict] | None = None
    verdict: str = "no alarms"
    warnings: list[str] = field(default_factory=list)
    incidents: list[Incident] = field(default_factory=list)
    unchecked: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    judged: str = WHOLE_LOG
    unjudged: str = ""
    messages: list = field(default_factory=list)
    messages_outside: int = 0  # of WARNING and above logged outside a --start/--end window: counted, not listed
    groups: list[dict] = field(default_factory=list)
    context: RunContext | None = None
    innovations: GroupRows | None = None
    clock: Clock = field(default_factory=Clock)
    recovery: Any = None  # logscan.report.recovery_view.RecoveryView: the recovery section, when [recovery] ran
    observability: Any = None  # logscan.verdict.observability.Observability: shaded where a fault could not be seen
    grid: tuple[int, float] | None = None


def flat_alarms(results: Sequence[DetectorResult]) -> list[AlarmInterval]:
    """All alarms of all results, results in order, each result's alarms in order."""
    return [alarm for result in results for alarm in result.alarms]


def report_matches(
    results: Sequence[DetectorResult], truth_events: list[FaultEvent], grace_s: float | None = None
) -> list[dict]:
    """Per alarm of :func:`flat_alarms`: the ground-truth event it detected and its latency.

    Uses ``logscan.verdict.scoring.match_alarms`` (an alarm detects the earliest event it overlaps,
    within the grace period after the event's end); latency = alarm start - event start, clipped
    at 0 as in scoring.
    """
    alarms = flat_alarms(results)
    grace = scoring.DEFAULT_GRACE_S if grace_s is None else grace_s
    _, alarm_event = scoring.match_alarms(truth_events, alarms, grace)
    out = []
    for alarm, hit in zip(alarms, alarm_event):
        latency = None if hit is None else max(float(alarm.start) - truth_events[hit].t_start, 0.0)
        out.append({"event": hit, "latency_s": latency})
    return out
