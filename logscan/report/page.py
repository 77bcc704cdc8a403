"""The analysis report page: ReportInput -> one offline HTML file (jinja2 template + plotly JSON).

The page is rendered from ``templates/report.html.j2`` with autoescaping on (topic, channel and
signal names come from untrusted logs). The figures' JSON sits in one ``application/json`` block
and is drawn by a small inline script with ``Plotly.newPlot``; plotly.js itself is embedded once,
or written once beside the reports (``plotlyjs=<directory>``) and referenced relatively
(`logscan.report.page_assets`).

The page's parts live in modules of their own: what it shows (`logscan.report.report_input`), its
tables and lines (`logscan.report.page_rows`), its figures (`logscan.report.page_sections`) and
the registration point where a new figure joins it (`logscan.report.page_parts`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from logscan.artifacts import Staged, stage, write_atomic
from logscan.report import overview, page_rows
from logscan.report.context import context_tables, group_rows, log_view, message_row, model_view, number_text
from logscan.report.context_stack import stack_rows
from logscan.report.figures import grid_step, merge_spans
from logscan.report.flight_overview import checked_view
from logscan.report.margins import result_margins
from logscan.report.page_assets import environment, install_plotly_js, plotly_js, plotly_js_src, report_js
from logscan.report.page_parts import CONTEXT_FIGURES, CONTEXT_ROWS, PageInput
from logscan.report.page_sections import detector_sections, first_screen, page_figures
from logscan.report.plotly_json import POINT_BUDGET
from logscan.report.recovery_figures import recovery_figures, recovery_rows
from logscan.report.report_input import ReportInput, flat_alarms, report_matches
from logscan.report.stacked import figures_json
from logscan.verdict.autopilot_messages import MAX_SHOWN
from logscan.verdict.coverage import WHOLE_LOG, skipped_heading

__all__ = ["ReportInput", "flat_alarms", "render_html", "render_report", "report_matches", "stage_report"]


def _figures(report: ReportInput, point_budget: int) -> dict:
    """Every figure of the page and the values the template needs about them."""
    t = np.asarray(report.t, dtype=np.float64)
    t_end = float(t[-1]) if t.size else 0.0
    events = [page_rows.event_view(e, i, t_end) for i, e in enumerate(report.truth_events)]
    page = PageInput(report, t, merge_spans([(e["start"], e["end"]) for e in events], 0.0, 0.0))
    margins = result_margins(report.results, t)
    heads, first, checked = first_screen(page)
    sections, section_figures = detector_sections(page, margins)
    figures = page_figures(section_figures, first, checked)
    rows = [row for build in CONTEXT_ROWS for row in build(page)]
    span = getattr(report.context, "t_span", None)  # the grid's, as the run's context figures had it
    context = ([stack_rows(rows, report.clock, span)] if rows else []) + [f for b in CONTEXT_FIGURES for f in b(page)]
    recovered = recovery_figures(report.recovery, report.clock)
    ids = {s["detector"]: s["id"] for s in sections}
    return {
        "t": t,
        "events": events,
        "heads": heads,
        "margins": margins,
        "sections": sections,
        "checked_figure": checked_view(checked),
        "headline_figure": first and {"id": "fig-headline", "title": first.title, "caption": first.caption},
        "context": context,
        "recovery": recovered,
        "n_figures": len(figures) + len(context) + len(recovered),
        "figure_json": figures_json(figures, t, point_budget, extra=context + recovered, clock=report.clock),
        "margin_rows": overview.margin_rows(margins, report.results, ids, report.clock),
    }


def render_html(report: ReportInput, *, plotlyjs_src: str | None = None, point_budget: int = POINT_BUDGET) -> str:
    """The report page as a string; plotly.js inline, or from ``plotlyjs_src`` (a URL) if given."""
    f = _figures(report, point_budget)
    t, events, clock = f["t"], f["events"], report.clock
    has_truth = bool(events) or bool(report.log_facts.get("has_truth"))
    alarms = flat_alarms(report.results)
    rows = page_rows.alarm_rows(report, events, has_truth)
    log = log_view(report.log_facts) | {"clock": page_rows.clock_text(clock)}
    return environment().get_template("report.html.j2").render(
        title=f"logscan report: {log['name']}",
        log=log,
        profile_text=report.profile_text,
        profile_source=report.profile_source,
        model=model_view(report.model),
        version=report.logscan_version,
        verdict=report.verdict,
        verdict_lines=page_rows.verdict_lines(report, f["heads"], f["margins"]),
        margins=overview.fold_margins(f["margins"], f["margin_rows"]),
        time_head=page_rows.time_head(clock),
        time_axis=clock.axis_title(),
        time_scale=1000 if clock.utc else 1,  # axis units per second (a date axis counts milliseconds)
        log_span=" ".join(repr(clock.axis_value(float(v))) for v in t[[0, -1]]) if t.size > 1 else "",
        groups=group_rows(report.groups),
        verdict_class=page_rows.verdict_class(report.verdict, len(alarms), report.unchecked),
        n_alarms=len(alarms),
        warnings=[str(w) for w in report.warnings],
        unchecked=[str(u) for u in report.unchecked],
        skipped=[str(u) for u in report.skipped],
        skipped_heading=skipped_heading(report.judged),
        checked_span="the whole log" if report.judged == WHOLE_LOG else report.judged,
        unjudged=str(report.unjudged),
        messages=[message_row(m, clock) for m in report.messages[:MAX_SHOWN]],
        messages_hidden=max(len(report.messages) - MAX_SHOWN, 0),
        messages_outside=report.messages_outside,
        incidents=page_rows.incident_rows(f["heads"], clock),
        checked_figure=f["checked_figure"],
        headline_figure=f["headline_figure"],
        rows=rows,
        rows_hidden=max(len(alarms) - len(rows), 0),
        has_truth=has_truth,
        events=page_rows.event_rows(events, clock),
        sections=f["sections"],
        n_figures=f["n_figures"],
        context=f["context"],
        **context_tables(report.context, clock),  # the autopilot's logged messages
        recovery=f["recovery"],
        recovery_rows=recovery_rows(report.recovery, clock),
        figure_json=f["figure_json"],
        plotlyjs_inline=None if plotlyjs_src else plotly_js(),
        plotlyjs_src=plotlyjs_src,
        report_js=report_js(),
        grid=_grid_facts(getattr(report, "grid", None), t),
    )  # fmt: skip


def _grid_facts(grid: tuple[int, float] | None, t: np.ndarray) -> dict:
    """The header's grid: its steps and step, from ``t`` unless the report gives them (``grid``)."""
    n, dt = grid if grid is not None else (int(t.size), grid_step(t))
    return {"n": n, "dt": number_text(dt)}


def render_report(report: ReportInput, path: str | os.PathLike, *, plotlyjs: str | os.PathLike = "embed") -> None:
    """Write the report for ``report`` to ``path`` atomically.

    plotlyjs: "embed" puts plotly.js inside the page (one self-contained file, ~5 MB); a
    directory path writes plotly.min.js there once and references it relatively (each report
    then stays a few hundred kilobytes).
    """
    target = Path(path)
    src = None if str(plotlyjs) == "embed" else install_plotly_js(Path(plotlyjs), target)
    write_atomic(target, render_html(report, plotlyjs_src=src))


def stage_report(
    report: ReportInput, path: str | os.PathLike, *, plotlyjs: str | os.PathLike = "embed", token: str = ""
) -> Staged:
    """The report for ``report`` written to a temporary file beside ``path`` and not yet renamed
    (`logscan.artifacts.commit` does that, together with the run's other outputs). With a
    plotly.js directory the page links to ``DIR/plotly.min.js``, which the caller stages once
    (`logscan.report.page_assets.stage_plotly_js`)."""
    target = Path(path)
    src = None if str(plotlyjs) == "embed" else plotly_js_src(Path(plotlyjs), target)
    return stage(target, render_html(report, plotlyjs_src=src), token=token)
