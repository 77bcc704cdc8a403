"""The report page's figures: one per detector section (its rows on one time axis), the headline
incident's sensor on the first screen, and the flight when nothing alarmed."""

from __future__ import annotations

from collections.abc import Sequence

from logscan.report import overview
from logscan.report.context import info_rows
from logscan.report.figures import Figure, detector_figures
from logscan.report.flight_overview import FIGURE_ID, checked_rows
from logscan.report.headline import Headline, headline_figure, headlines
from logscan.report.margins import Margin
from logscan.report.page_parts import DETECTOR_ROWS, PageInput
from logscan.report.stacked import fold_flat, row_captions
from logscan.verdict.incidents import signal_label


def _section(result, page: PageInput, margins: Sequence[Margin]) -> dict:
    """A detector's section: its line, warnings, facts and rows (`Figure`s, not yet stacked)."""
    report = page.report
    problems: list[str] = []
    labels = {name: signal_label(name, result.detector) for name in result.series}
    figs = detector_figures(result, page.t, page.truth_spans, report.model, problems, labels)
    # the hooked rows (the sensor beside the statistic): after the statistics' rows, before the extras
    after = 1 + max((i for i, f in enumerate(figs) if f.y_title in result.series), default=0)
    figs[after:after] = [row for build in DETECTOR_ROWS for row in build(result, page)]
    own = [m for m in margins if m.detector == result.detector]
    return {
        "detector": result.detector,
        "n_alarms": len(result.alarms),
        "line": overview.section_line(len(result.alarms), own, report.clock),
        "warnings": [str(w) for w in result.warnings] + problems,
        "coverage": str(result.info.get("coverage", "")),
        "info": info_rows(result.info),
        "statistics": [{"name": name, "label": label} for name, label in labels.items()],
        "figures": figs,
    }


def detector_sections(page: PageInput, margins: Sequence[Margin]) -> tuple[list[dict], list[tuple[str, list]]]:
    """One section per detector result, alarmed ones first, and its one figure (its rows, a list of
    `Figure`, `logscan.report.stacked`) with its element id ("fig-<n>", numbered in page order)."""
    sections = overview.order_sections([_section(result, page, margins) for result in page.report.results])
    figures: list[tuple[str, list]] = []
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


def first_screen(page: PageInput) -> tuple[list[Headline], Figure | None, list[Figure]]:
    """Each incident's `Headline`, the first one's sensor figure (None when it names no sensor
    channel) and, without incidents, every group against its prediction
    (`logscan.report.flight_overview`; [] else). Made before the detector sections: the views
    the headlines make are kept for the sections' sensor figures (`PageInput.views`)."""
    report, t = page.report, page.t
    heads = headlines(report.incidents, page.views, t, report.model)
    first = headline_figure(heads[0], page.views, t, page.truth_spans) if heads else None
    checked = [] if report.incidents else checked_rows(report.innovations, t, page.truth_spans)
    return heads, first, checked


def page_figures(sections: list, first: Figure | None, checked: list[Figure]) -> list[tuple[str, Figure | list]]:
    """The page's figures in page order: the headline's sensor zoomed to it (the first screen),
    each detector section's figure (`detector_sections`), the flight when nothing alarmed."""
    headline = [("fig-headline", first)] if first is not None else []
    return headline + sections + ([(FIGURE_ID, checked)] if checked else [])
