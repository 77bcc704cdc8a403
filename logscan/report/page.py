"""The analysis report page: ReportInput -> one offline HTML file (jinja2 template + plotly JSON).

The page is rendered from ``templates/report.html.j2`` with autoescaping on (topic, channel and
signal names come from untrusted logs). The figures' JSON sits in one ``application/json`` block
and is drawn by a small inline script with ``Plotly.newPlot``; plotly.js itself is embedded once,
or written once beside the reports (``plotlyjs=<directory>``) and referenced relatively.
"""

from __future__ import annotations

import functools
import os
import urllib.parse
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import logscan.templates
from logscan.alarms import AlarmInterval
from logscan.artifacts import Staged, commit, stage, write_atomic
from logscan.errors import InputError
from logscan.report import overview
from logscan.report.context import (
    context_tables,
    group_rows,
    info_rows,
    log_view,
    message_row,
    model_view,
    number_text,
)
from logscan.report.context_figures import context_figures
from logscan.report.figures import detector_figures, merge_spans
from logscan.report.flight_overview import FIGURE_ID, checked_rows, checked_view
from logscan.report.headline import Headline, headline_figure, headlines
from logscan.report.margins import Margin, result_margins
from logscan.report.observability_figures import observability_figures
from logscan.report.plotly_json import POINT_BUDGET
from logscan.report.recovery_figures import recovery_figures, recovery_rows
from logscan.report.run_context import RunContext
from logscan.report.sensor_figures import named_group_figures
from logscan.report.sensor_views import Innovations
from logscan.report.stacked import figures_json, fold_flat, row_captions
from logscan.results import DetectorResult, FaultEvent, Incident
from logscan.timebase.clock import Clock
from logscan.verdict import scoring
from logscan.verdict.autopilot_messages import MAX_SHOWN
from logscan.verdict.incidents import signal_label

PLOTLY_JS_NAME = "plotly.min.js"
MAX_TABLE_ROWS = 200  # alarm table rows shown; the JSON summary has them all


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
    unjudged:         what the profile's [alarms] suspension left unjudged of the model-based
                      statistics, when at most half of the flight ("": nothing; more is an
                      ``unchecked`` line): said where "every check ran" would be.
    messages:         the autopilot's messages during flight with their incidents
                      (`logscan.verdict.autopilot_messages.AutopilotMessage`), a table under the incidents.
    groups:           the profile's measurement groups as used, with the filter's counts
                      (`logscan.report.context.measurement_groups`). Empty: not shown.
    context:          the run's path and mode (`logscan.report.run_context.RunContext`), drawn in the
                      "Context" section (`logscan.report.context_figures`). None: not shown.
    innovations:      the EKF's packed innovations (`logscan.report.sensor_views.Innovations`): a group
                      an alarm names is drawn (measured vs predicted, per channel) in the first
                      section whose alarms name it. None: not drawn.
    clock:            the log's own clock (`logscan.timebase.clock`): the time axis, the tables and the
                      headlines show times in it. Default: seconds since the log's start.
    recovery:         the recovered estimates per loop and state and one record per anomaly
                      (`logscan.report.recovery_view`). None: no recovery section.
    observability:    when a fault of a kind could not be seen (`logscan.verdict.observability`), drawn as
                      bands in the "Context" section. None: not drawn.
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
    unjudged: str = ""
    messages: list = field(default_factory=list)
    groups: list[dict] = field(default_factory=list)
    context: RunContext | None = None
    innovations: Innovations | None = None
    clock: Clock = field(default_factory=Clock)
    recovery: Any = None  # logscan.report.recovery_view.RecoveryView: the recovery section, when [recovery] ran
    observability: Any = None  # logscan.verdict.observability.Observability: shaded where a fault could not be seen


# --- alarms and ground truth ------------------------------------------------------------------


def flat_alarms(results: Sequence[DetectorResult]) -> list[AlarmInterval]:
    """All alarms of all results, results in order, each result's alarms in order."""
    return [alarm for result in results for alarm in result.alarms]


def _time_head(clock: Clock) -> str:
    """The unit of the tables' time columns: "s", "UTC" or "PX4 boot time, s"."""
    if clock.utc:
        return "UTC"
    return "s" if clock.relative else f"{clock.name}, s"


def _event_view(event: FaultEvent, index: int, t_end: float) -> dict:
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


def _alarm_rows(report: ReportInput, events: list[dict], has_truth: bool) -> list[dict]:
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


def _incident_rows(heads: Sequence[Headline], clock: Clock) -> list[dict]:
    return [
        {"index": i, "headline": head.line(clock), "start": clock.short(inc.start),
         "end": clock.short(inc.end), "t0": repr(clock.axis_value(inc.start)), "t1": repr(clock.axis_value(inc.end)),
         "n_alarms": len(inc.alarms),
         "checks": [{"name": name, "label": signal_label(name, detector)}
                    for detector, name in sorted({(a.detector, a.signal) for a in inc.alarms}, key=lambda c: c[1])]}
        for i, head in enumerate(heads, 1)
        for inc in [head.incident]
    ]  # fmt: skip


def _verdict_class(verdict: str, n_alarms: int, unchecked: Sequence[str] = ()) -> str:
    if n_alarms:
        return "alarm"
    return "partial" if unchecked or "partial" in verdict else "ok"


# --- plotly.js and the template -----------------------------------------------------------------


def _plotly_js() -> str:
    from plotly.offline import get_plotlyjs

    js = get_plotlyjs()
    # "</script" inside the inline script would end it early; "<\/" is the same string in JS
    return js.replace("</script", "<\\/script").replace("</SCRIPT", "<\\/SCRIPT")


def plotly_js_target(directory: str | os.PathLike) -> Path:
    """Where ``--plotlyjs DIR`` puts plotly.js (the directory is created; InputError when it cannot be)."""
    directory = Path(directory)
    if directory.exists() and not directory.is_dir():
        raise InputError("--plotlyjs must be a directory", path=str(directory), hint="give a directory path or 'embed'")
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the plotly.js directory: {exc.strerror}", path=str(directory)) from None
    return directory / PLOTLY_JS_NAME


def stage_plotly_js(directory: str | os.PathLike, token: str = "") -> Staged | None:
    """plotly.min.js staged into ``directory`` (`logscan.artifacts.stage`); None when the file
    there already holds it."""
    from plotly.offline import get_plotlyjs

    payload = get_plotlyjs().encode("utf-8")
    target = plotly_js_target(directory)
    if target.is_file() and target.read_bytes() == payload:
        return None
    return stage(target, payload, token=token)


def _plotly_js_src(directory: Path, report_path: Path) -> str:
    """The URL of plotly.min.js in ``directory``, relative to the report."""
    relative = os.path.relpath((directory / PLOTLY_JS_NAME).resolve(), report_path.resolve().parent)
    return urllib.parse.quote(Path(relative).as_posix())


def _install_plotly_js(directory: Path, report_path: Path) -> str:
    """Write plotly.min.js into ``directory`` (if absent or different); URL relative to the report."""
    staged = stage_plotly_js(directory)
    if staged is not None:
        commit([staged])
    return _plotly_js_src(directory, report_path)


@functools.lru_cache(maxsize=1)
def _environment():
    import jinja2

    return jinja2.Environment(
        loader=jinja2.FileSystemLoader(Path(logscan.templates.__file__).parent),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
    )


def _report_js() -> str:
    """templates/report.js (the page's interactions), "" when absent; safe inside a <script>."""
    path = Path(logscan.templates.__file__).parent / "report.js"
    js = path.read_text(encoding="utf-8") if path.is_file() else ""
    return js.replace("</script", "<\\/script").replace("</SCRIPT", "<\\/SCRIPT")


# --- the page -----------------------------------------------------------------------------------


def _sections(
    report: ReportInput, t: np.ndarray, truth_spans: list, margins: Sequence[Margin]
) -> tuple[list[dict], list[tuple[str, Any]]]:
    """One section per detector result, alarmed ones first, and its one figure (its rows, a list of
    `Figure`, `logscan.report.stacked`) with its element id ("fig-<n>", numbered in page order)."""
    sections = []
    drawn: set[str] = set()  # groups whose sensor figures are placed
    for result in report.results:
        problems: list[str] = []
        labels = {name: signal_label(name, result.detector) for name in result.series}
        figs = detector_figures(result, t, truth_spans, report.model, problems, labels)
        # the sensor beside the statistic: right after the statistics' rows, before the extras
        after = 1 + max((i for i, f in enumerate(figs) if f.y_title in result.series), default=0)
        figs[after:after] = named_group_figures(result, report.innovations, t, truth_spans, drawn)
        own = [m for m in margins if m.detector == result.detector]
        sections.append({
            "detector": result.detector,
            "n_alarms": len(result.alarms),
            "line": overview.section_line(len(result.alarms), own, report.clock),
            "warnings": [str(w) for w in result.warnings] + problems,
            "coverage": str(result.info.get("coverage", "")),
            "info": info_rows(result.info),
            "statistics": [{"name": name, "label": label} for name, label in labels.items()],
            "figures": figs,
        })  # fmt: skip
    sections, figures = overview.order_sections(sections), []
    for section in sections:  # one figure per section: its rows on one time axis
        rows, flat = fold_flat(section["figures"])
        section["figures"] = []
        if not rows:  # nothing drawable (its problems are the section's warnings)
            continue
        fig_id = f"fig-{len(figures)}"
        title = "; ".join(fig.title for fig in rows)
        section["figures"] = [{"id": fig_id, "title": title, "captions": row_captions(rows, flat), "rows": len(rows)}]
        figures.append((fig_id, rows))
    return sections, figures


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


def _event_rows(events: list[dict], clock: Clock) -> list[dict]:
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


def _headlines(
    report: ReportInput, t: np.ndarray, truth_spans: list, figures: list
) -> tuple[list[Headline], Any, list]:
    """Each incident's `Headline` and the first one's sensor figure (inserted first in ``figures``
    as "fig-headline"; None when it names no sensor channel); without incidents, every group
    against its prediction (`logscan.report.flight_overview`, appended to ``figures``; [] else)."""
    heads = headlines(report.incidents, report.innovations, t, report.model)
    first = headline_figure(heads[0], report.innovations, t, truth_spans) if heads else None
    if first is not None:  # the first screen: the headline's sensor, zoomed to it
        figures.insert(0, ("fig-headline", first))
    checked = [] if report.incidents else checked_rows(report.innovations, t, truth_spans)
    figures += [(FIGURE_ID, checked)] if checked else []  # the flight when nothing alarmed
    return heads, first, checked


def _verdict_lines(report: ReportInput, heads: Sequence[Headline], margins: Sequence[Margin]) -> list[str]:
    """Each incident's headline (or the closest margin), the possible faults, the suppressed alarms."""
    clock = report.clock
    lines = [head.line(clock) for head in heads] or overview.verdict_lines((), margins, clock)
    return lines + _possible_lines(report.results, clock) + _suppressed_lines(report.results, clock)


def _ids(sections: Sequence[dict]) -> dict[str, str]:
    return {s["detector"]: s["id"] for s in sections}


def render_html(report: ReportInput, *, plotlyjs_src: str | None = None, point_budget: int = POINT_BUDGET) -> str:
    """The report page as a string; plotly.js inline, or from ``plotlyjs_src`` (a URL) if given."""
    t = np.asarray(report.t, dtype=np.float64)
    t_end = float(t[-1]) if t.size else 0.0
    events = [_event_view(e, i, t_end) for i, e in enumerate(report.truth_events)]
    has_truth = bool(events) or bool(report.log_facts.get("has_truth"))
    truth_spans = merge_spans([(e["start"], e["end"]) for e in events], 0.0, 0.0)
    margins = result_margins(report.results, t)
    sections, figures = _sections(report, t, truth_spans, margins)
    clock = report.clock
    heads, first, checked = _headlines(report, t, truth_spans, figures)
    context = context_figures(report.context, report.incidents, clock, report.innovations, t)
    context += observability_figures(report.observability, clock)
    recovered = recovery_figures(report.recovery, clock)
    figure_json = figures_json(figures, t, point_budget, extra=context + recovered, clock=clock)
    alarms = flat_alarms(report.results)
    rows = _alarm_rows(report, events, has_truth)
    log = log_view(report.log_facts) | {"clock": clock_text(clock)}
    return _environment().get_template("report.html.j2").render(
        title=f"logscan report: {log['name']}",
        log=log,
        profile_text=report.profile_text,
        profile_source=report.profile_source,
        model=model_view(report.model),
        version=report.logscan_version,
        verdict=report.verdict,
        verdict_lines=_verdict_lines(report, heads, margins),
        margins=overview.fold_margins(margins, overview.margin_rows(margins, report.results, _ids(sections), clock)),
        time_head=_time_head(clock),
        time_axis=clock.axis_title(),
        time_scale=1000 if clock.utc else 1,  # axis units per second (a date axis counts milliseconds)
        log_span=" ".join(repr(clock.axis_value(float(v))) for v in t[[0, -1]]) if t.size > 1 else "",
        groups=group_rows(report.groups),
        verdict_class=_verdict_class(report.verdict, len(alarms), report.unchecked),
        n_alarms=len(alarms),
        warnings=[str(w) for w in report.warnings],
        unchecked=[str(u) for u in report.unchecked],
        skipped=[str(u) for u in report.skipped],
        unjudged=str(report.unjudged),
        messages=[message_row(m, clock) for m in report.messages[:MAX_SHOWN]],
        messages_hidden=max(len(report.messages) - MAX_SHOWN, 0),
        incidents=_incident_rows(heads, clock),
        checked_figure=checked_view(checked),
        headline_figure=first and {"id": "fig-headline", "title": first.title, "caption": first.caption},
        rows=rows,
        rows_hidden=max(len(alarms) - len(rows), 0),
        has_truth=has_truth,
        events=_event_rows(events, clock),
        sections=sections,
        n_figures=len(figures) + len(context) + len(recovered),
        context=context,
        **context_tables(report.context, clock),  # the autopilot's logged messages
        recovery=recovered,
        recovery_rows=recovery_rows(report.recovery, clock),
        figure_json=figure_json,
        plotlyjs_inline=None if plotlyjs_src else _plotly_js(),
        plotlyjs_src=plotlyjs_src,
        report_js=_report_js(),
        grid={"n": int(t.size), "dt": number_text(float(np.median(np.diff(t))) if t.size > 1 else None)},
    )  # fmt: skip


def render_report(report: ReportInput, path: str | os.PathLike, *, plotlyjs: str | os.PathLike = "embed") -> None:
    """Write the report for ``report`` to ``path`` atomically.

    plotlyjs: "embed" puts plotly.js inside the page (one self-contained file, ~5 MB); a
    directory path writes plotly.min.js there once and references it relatively (each report
    then stays a few hundred kilobytes).
    """
    target = Path(path)
    src = None if str(plotlyjs) == "embed" else _install_plotly_js(Path(plotlyjs), target)
    write_atomic(target, render_html(report, plotlyjs_src=src))


def stage_report(
    report: ReportInput, path: str | os.PathLike, *, plotlyjs: str | os.PathLike = "embed", token: str = ""
) -> Staged:
    """The report for ``report`` written to a temporary file beside ``path`` and not yet renamed
    (`logscan.artifacts.commit` does that, together with the run's other outputs). With a
    plotly.js directory the page links to ``DIR/plotly.min.js``, which the caller stages once
    (`stage_plotly_js`)."""
    target = Path(path)
    src = None if str(plotlyjs) == "embed" else _plotly_js_src(Path(plotlyjs), target)
    return stage(target, render_html(report, plotlyjs_src=src), token=token)
