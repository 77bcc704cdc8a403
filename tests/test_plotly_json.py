"""Decimation for the zoom: a click on an incident or alarm row shows that window drawn densely, on a
1-hour log, without growing the report; no focus when alarms are everywhere."""

from __future__ import annotations

import numpy as np
import pytest
from test_report import GRID_N, array, figures, make_report

from logscan.report import render_html
from logscan.report.figures import Figure, Trace
from logscan.report.plotly_json import MAX_FOCUS_FRACTION, POINT_BUDGET, focus_windows


@pytest.fixture(scope="module")
def hour():
    report = make_report(GRID_N, hostile=False)
    return report, figures(render_html(report))


def zoom_window(start: float, end: float) -> tuple[float, float]:
    margin = max(2.0, 0.5 * (end - start))  # as templates/report.js
    return start - margin, end + margin


def lines(specs: list[dict]):
    """(figure id, trace name, x) of every drawn line (not the shaded spans)."""
    for spec in specs:
        for trace in spec["figure"]["data"]:
            if trace.get("yaxis") != "y2" and isinstance(trace["x"], dict):
                yield spec["id"], trace["name"], array(trace["x"])


def test_every_decimated_line_is_dense_where_an_alarm_row_zooms(hour):
    report, specs = hour
    for alarm in (a for result in report.results for a in result.alarms):
        lo, hi = zoom_window(alarm.start, alarm.end)
        for fig_id, name, x in lines(specs):
            if x.size >= 1_000:  # decimated (a short flat threshold is two points)
                inside = np.count_nonzero((x >= lo) & (x <= hi))
                # >= 40: the narrowest window is 4 s, where a 10 Hz statistic has 40 samples, all drawn
                # (the overview alone leaves about 10 points there)
                assert inside >= 40, (alarm.signal, fig_id, name, inside)


def test_the_focus_is_paid_from_the_point_budget(hour):
    _, specs = hour
    assert sum(x.size for _, _, x in lines(specs)) <= POINT_BUDGET * 1.05


def test_focus_windows_cover_the_alarms_with_the_zoom_margin():
    t = np.arange(360_000) * 0.01
    fig = Figure("f", "y", [], {"alarm": [(100.0, 100.5), (2000.0, 2030.0), (2030.5, 2031.0)]})
    windows = focus_windows([fig], t)
    assert np.allclose(windows, [[98.0, 102.5], [1984.5, 2046.5]])  # 2000-2031 is one incident


def test_no_focus_when_alarms_cover_much_of_the_log():
    t = np.arange(60_000) * 0.01  # 600 s
    spans = [(s, s + 1.0) for s in np.arange(0.0, 600.0, 600.0 * MAX_FOCUS_FRACTION / 5 / 2)]
    fig = Figure("f", "y", [Trace("y", np.zeros(t.size), np.zeros(0, int), 1.0, {})], {"alarm": spans})
    assert focus_windows([fig], t).shape == (0, 2)
