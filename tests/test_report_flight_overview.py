"""The flight at a glance: a report without incidents draws every measurement group against its
prediction (one row per group, on the page's time axis); a report with incidents does not."""

from __future__ import annotations

import re

from test_report import figures, make_report
from test_sensor_views import hour_innovations

from logscan.report import render_html
from logscan.results import Incident


def _report(incidents: bool):
    report = make_report(6_000, truth=False, hostile=False)
    report.innovations = hour_innovations(report.t.size)
    report.incidents = [Incident(10.0, 11.0, "accel", "accel x", [])] if incidents else []
    return report


def test_a_log_without_incidents_shows_every_group_against_its_prediction():
    page = render_html(_report(incidents=False))
    assert re.search(r'<h2 id="checked">What was checked', page)
    assert '<div class="figure ls-timeseries ls-section" id="fig-checked" data-rows="3"' in page
    spec = next(s["figure"] for s in figures(page) if s["id"] == "fig-checked")
    titles = [note["text"] for note in spec["layout"]["annotations"] if "normalised innovation" in note["text"]]
    assert [title.removeprefix("<b>").split(":")[0] for title in titles] == ["accel", "gyro", "gps"]
    channels = {trace["name"] for trace in spec["data"]}
    assert {"/accel/x", "/gyro/y", "/gps/z"} <= channels
    assert page.index('id="fig-checked"') < page.index("<h2>Alarms</h2>")  # under the verdict


def test_a_log_with_incidents_keeps_its_points_for_the_evidence():
    page = render_html(_report(incidents=True))
    assert 'id="fig-checked"' not in page and 'id="checked"' not in page


def test_a_geodetic_position_is_drawn_as_a_map_east_against_north_about_the_first_fix():
    from types import SimpleNamespace

    import numpy as np

    from logscan.models import get_model
    from logscan.report.run_context import path_of

    n = 500
    t = np.arange(n) * 0.1
    ned = np.column_stack([10 * np.sin(t / 10), 30 * np.cos(t / 10) - 30, np.full(n, -5.0)])  # north, east, down
    group = SimpleNamespace(z=ned, fresh=np.ones(n, bool), origin=(47.0, 8.0, 400.0),
                            channels=["/vehicle_gps_position_0/lat", "/vehicle_gps_position_0/lon",
                                      "/vehicle_gps_position_0/alt"])  # fmt: skip
    run = SimpleNamespace(t=t, groups={"gnss_position": group})
    path = path_of(run, get_model("ins", {}))
    assert path is not None and path.group == "gnss_position"
    assert path.channels == ("east (m from the first fix)", "north (m from the first fix)")
    assert np.allclose(path.x, ned[:, 1]) and np.allclose(path.y, ned[:, 0])  # east across, north up


def test_the_path_is_the_filters_estimate_over_the_measured_fixes():
    import json

    import numpy as np
    from test_report import array

    from logscan.report.context_figures import path_figure
    from logscan.report.run_context import Path2D, estimated_path

    n = 3_000
    t = np.arange(n) * 0.01
    innovations = hour_innovations(n)
    fixes = Path2D(t[::10], np.zeros(n // 10), np.ones(n // 10), ("/gps/x", "/gps/y"), "gps", (0, 1))
    estimate = estimated_path(fixes, innovations, t)
    view = innovations.view("gps")
    steps = np.flatnonzero(np.isfinite(view.predicted[:, 0]))  # the 10 Hz updates
    assert np.array_equal(estimate.t, t[steps]) and np.allclose(estimate.x, view.predicted[steps, 0])
    assert np.allclose(estimate.y, view.predicted[steps, 1])
    figure = json.loads(path_figure(fixes, [], None, estimate)["json"])
    by_name = {trace["name"]: trace for trace in figure["data"]}
    assert np.allclose(array(by_name["the filter's estimate"]["x"]), estimate.x, atol=1e-5)
    assert array(by_name["fixes (measured)"]["y"]).tolist() == [1.0] * (n // 10)
    assert estimated_path(fixes, None, t) is None and estimated_path(None, innovations, t) is None


def test_what_was_not_checked_stays_above_the_overview():
    report = _report(incidents=False)
    report.unchecked = ["the model-based statistics were not judged on the ground"]
    page = render_html(report)
    assert page.index('id="unchecked"') < page.index('id="fig-checked"')
