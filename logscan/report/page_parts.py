"""Where a figure joins the report page: one line in one of the lists below.

``DETECTOR_ROWS``: rows of a detector section's one figure (`logscan.report.stacked`), placed after
    the rows of the detector's own statistics and before its extras. A builder takes the section's
    `DetectorResult` and the `PageInput` and returns `logscan.report.figures.Figure` rows ([] when the
    result is not its kind); the rows share the section's time axis, crosshair and zoom.
``CONTEXT_ROWS``: rows of the "Context" section's one figure on the page's time axis (one hover,
    one spike line and one zoom across them: `logscan.report.context_stack`). A builder takes the
    `PageInput` and returns `logscan.report.context_figures.time_row`s (``{"spec", "data",
    "layout"}``: a figure's traces, on ``y`` and the hidden overlay ``y2``, and its layout).
``CONTEXT_FIGURES``: figures of the "Context" section not on the time axis (the path), each
    already serialised (``{"id", "title", "caption", "timeseries", "height", "json", "points"}``,
    as `logscan.report.context_figures._spec` makes them; their points come out of the page's
    budget). A builder takes the `PageInput` and returns a list of them.

A new figure is a function in a module of its own (`report/` may import only what
docs/extending.md "Who imports whom" lists) and its name added to one list here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from logscan.report.context_figures import context_rows, path_figures
from logscan.report.figures import Figure
from logscan.report.kgn_view import kgn_rows
from logscan.report.observability_figures import observability_rows
from logscan.report.report_input import ReportInput
from logscan.report.sensor_figures import named_group_figures
from logscan.report.sensor_views import PageViews
from logscan.report.ubikf_truth_view import ubikf_truth_rows
from logscan.report.ubikf_view import ubikf_rows
from logscan.results import DetectorResult


@dataclass
class PageInput:
    """What a figure builder may read: the report, its analysis grid ``t`` (seconds since the log's
    start, float64), the ground-truth spans to shade, the measurement groups whose sensor
    figures are already placed (a group is drawn once per page), and the groups' views of the
    filter's innovations, each made once for the page (None when no filter ran)."""

    report: ReportInput
    t: np.ndarray
    truth_spans: list[tuple[float, float]]
    drawn: set[str] = field(default_factory=set)
    views: PageViews | None = field(init=False)

    def __post_init__(self) -> None:
        innovations = self.report.innovations
        self.views = None if innovations is None else PageViews(innovations)


def sensor_rows(result: DetectorResult, page: PageInput) -> list[Figure]:
    """The sensors the result's alarms name, measured vs predicted (`logscan.report.sensor_figures`)."""
    return named_group_figures(result, page.views, page.t, page.truth_spans, page.drawn)


def run_context_rows(page: PageInput) -> list[dict]:
    """The mode, the autopilot's state and messages (`logscan.report.context_figures`)."""
    return context_rows(page.report.context)


def blind_rows(page: PageInput) -> list[dict]:
    """Where a fault could not have been seen (`logscan.report.observability_figures`)."""
    return observability_rows(page.report.observability)


def path_figure(page: PageInput) -> list[dict]:
    """The path, the filter's estimate of it and the incidents on it (`logscan.report.context_figures`)."""
    report = page.report
    return path_figures(report.context, report.incidents, report.clock, report.innovations, page.t)


DETECTOR_ROWS: list[Callable[[DetectorResult, PageInput], list[Figure]]] = [
    sensor_rows,
    kgn_rows,
    ubikf_rows,
    ubikf_truth_rows,
]
CONTEXT_ROWS: list[Callable[[PageInput], list[dict]]] = [
    run_context_rows,
    blind_rows,
]
CONTEXT_FIGURES: list[Callable[[PageInput], list[dict]]] = [
    path_figure,
]
