"""The report page's tables and lines: the alarms (numbered from 1, incidents first), the
incidents, the ground-truth events, the verdict's lines and the log's clock."""

from __future__ import annotations

from collections.abc import Sequence

from logscan.report import overview
from logscan.report.context import number_text
from logscan.report.headline import Headline
from logscan.report.margins import Margin
from logscan.report.report_input import ReportInput, flat_alarms, report_matches
from logscan.results import DetectorResult, FaultEvent
from logscan.timebase.clock import Clock
from logscan.verdict.incidents import signal_label

VERDICT_INCIDENTS = 10  # incidents the verdict names on the first screen; the Incidents table has them all

MAX_TABLE_ROWS = 200  # alarm table rows shown; the JSON summary has them all


def time_head(clock: Clock) -> str:
    """The unit of the tables' time columns: "s", "UTC" or "PX4 boot time, s"."""
    if clock.utc:
        return "UTC"
    return "s" if clock.relative else f"{clock.name}, s"


def event_view(event: FaultEvent, index: int, t_end: float) -> dict:
    """A truth event as {index, kind, target, start, end, open_ended, magnitude, label}; ``index``
    counts from 0 (the JSON's event index), the label from 1 (the report's tables)."""
    open_ended = event.t_end is None
    return {
        "index": index,
        "kind": event.kind,
        "target": event.target,
        "start": float(event.t_start),
        "end": t_end if open_ended else float(event.t_end),
        "open_ended": open_ended,
        "magnitude": event.magnitude,
        "label": f"#{index + 1} {event.kind} {event.target}".strip(),  # numbered from 1, as alarms
    }


def alarm_rows(report: ReportInput, events: list[dict], has_truth: bool) -> list[dict]:
    alarms = flat_alarms(report.results)
    incident_of = {id(alarm): i for i, incident in enumerate(report.incidents, 1) for alarm in incident.alarms}
    info_of = {id(alarm): result.info for result in report.results for alarm in result.alarms}
    matches = report.matches
    if has_truth and matches is None and alarms:
        matches = report_matches(report.results, report.truth_events)
    rows = []
    clock = report.clock
    for i, alarm in enumerate(alarms[:MAX_TABLE_ROWS]):
        start, end = float(alarm.start), float(alarm.end)
        row = {
            "index": i + 1,  # numbered from 1, as the incidents
            "detector": alarm.detector,
            "signal": alarm.signal,
            "label": signal_label(alarm.signal, alarm.detector),
            "start": clock.short(start),
            "end": clock.short(end),
            "t0": repr(clock.axis_value(start)),  # where the time axis zooms to: its own units
            "t1": repr(clock.axis_value(end)),
            "order": start,
            "duration": f"{end - start:.3f}",
            **overview.peak_cells(alarm, info_of.get(id(alarm), {})),  # peak, threshold, ratio, note
            "bound": alarm.bound,
            "rejected": overview.is_rejected(alarm.signal),  # the note replaces peak / threshold
            "event": None,
            "latency": None,
        }
        if has_truth and matches is not None and i < len(matches):
            match = matches[i] or {}
            hit = match.get("event")
            if hit is not None and 0 <= int(hit) < len(events):
                row["event"] = events[int(hit)]["label"]
                row["latency"] = number_text(match.get("latency_s"), 3)
        row["incident"] = incident_of.get(id(alarm), "")
        rows.append(row)
    if not incident_of:
        return rows
    # incidents first, in time order, then the alarms behind each (in time order)
    return sorted(rows, key=lambda r: (r["incident"] == "", r["incident"], r["order"]))


def incident_rows(heads: Sequence[Headline], clock: Clock) -> list[dict]:
    return [
        {"index": i, "headline": head.line(clock), "start": clock.short(inc.start),
         "end": clock.short(inc.end), "t0": repr(clock.axis_value(inc.start)), "t1": repr(clock.axis_value(inc.end)),
         "n_alarms": len(inc.alarms),
         "checks": [{"name": name, "label": signal_label(name, detector)}
                    for detector, name in sorted({(a.detector, a.signal) for a in inc.alarms}, key=lambda c: c[1])]}
        for i, head in enumerate(heads, 1)
        for inc in [head.incident]
    ]  # fmt: skip


def verdict_class(verdict: str, n_alarms: int, unchecked: Sequence[str] = ()) -> str:
    if n_alarms:
        return "alarm"
    return "partial" if unchecked or "partial" in verdict else "ok"


def _possible_lines(results: Sequence[DetectorResult], clock: Clock) -> list[str]:
    """The "possible fault" warnings (shaded orange in the figures): one verdict line per statistic,
    its count and span (they can be many: each is in the JSON)."""
    by_signal: dict[tuple[str, str], list] = {}
    for result in results:
        for p in result.possible:
            by_signal.setdefault((p.detector, p.signal), []).append(p)
    lines = []
    for (detector, signal), found in by_signal.items():
        first, last = min(p.start for p in found), max(p.end for p in found)
        what = f"{len(found)} possible faults" if len(found) > 1 else "possible fault"
        lines.append(f"{what} (warnings, not alarms): {detector} {signal}, {clock.span_text(first, last)}")
    return lines


def _suppressed_lines(results: Sequence[DetectorResult], clock: Clock) -> list[str]:
    """One verdict line per suppressed alarm, with the reason the suppressions file gives."""
    return [
        f"suppressed: {a.detector} {a.signal} {clock.span_text(a.start, a.end)} ({reason})"
        for result in results
        for a, reason in result.suppressed
    ][:MAX_TABLE_ROWS]


def event_rows(events: list[dict], clock: Clock) -> list[dict]:
    return [
        {**e, "start": clock.short(e["start"]), "end": clock.short(e["end"]) + (" (open)" if e["open_ended"] else ""),
         "magnitude": "—" if e["magnitude"] is None else str(e["magnitude"])}
        for e in events
    ]  # fmt: skip


def clock_text(clock: Clock) -> str:
    """The log facts' line on the clock: its name, time zero in it, and its UTC when known."""
    if clock.utc:
        return f"UTC (the log's timestamps are wall-clock time); time zero {clock.utc_text(0.0)}"
    if clock.relative:
        return "time since log start (the log's timestamps are not a known clock)"
    utc = clock.utc_text(0.0)
    dated = f"; UTC of time zero {utc} (from the GNSS receiver's time)" if utc else ""
    return f"{clock.name}; the analysis' time zero at {clock.at(0.0):.3f} s{dated}"


def verdict_lines(report: ReportInput, heads: Sequence[Headline], margins: Sequence[Margin]) -> list[str]:
    """Each incident's headline, the first `VERDICT_INCIDENTS` of them and how many more (or the
    closest margin), the possible faults, the suppressed alarms."""
    clock = report.clock
    lines = [head.line(clock) for head in heads[:VERDICT_INCIDENTS]] or overview.verdict_lines((), margins, clock)
    if len(heads) > VERDICT_INCIDENTS:  # a log alarming all day: the first screen is not the list
        lines.append(f"... and {len(heads) - VERDICT_INCIDENTS} more incidents: see the Incidents table")
    return lines + _possible_lines(report.results, clock) + _suppressed_lines(report.results, clock)
