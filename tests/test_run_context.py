"""The run's context for the report: the 2-D path of the position group and the mode channel, small,
kept after the aligned series are released, and drawn as the report's "Context" figures."""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pytest
from test_report import HOSTILE, HOSTILE_SHOWN, array, figures, make_report

from logscan.align import AlignedGroup
from logscan.models import get_model
from logscan.report import render_html
from logscan.report.plotly_json import POINT_BUDGET
from logscan.report.run_context import (
    MAX_MODE_INTERVALS,
    MAX_PATH_POINTS,
    ModeTrack,
    Path2D,
    RunContext,
    mode_of,
    path_of,
    true_states,
)
from logscan.results import Incident

N = 360_000  # 1 hour at 100 Hz


def quad_run(n: int = N, mode: np.ndarray | None = None, channel: str = "/flight_mode/mode"):
    """A quadcopter-shaped run: a 10 Hz position group circling, one sample far out at 1800 s."""
    t = np.arange(n) * 0.01
    fresh = np.arange(n) % 10 == 0
    z = np.column_stack([50 * np.cos(t / 100), 50 * np.sin(t / 100), np.full(n, 10.0)])
    if n > 180_000:
        z[180_000] = [500.0, 0.0, 10.0]  # a one-sample glitch the path must keep
    z[1000:2000] = np.nan  # a gap
    groups = {
        "accel": AlignedGroup("accel", ["/imu/a.x", "/imu/a.y", "/imu/a.z"], np.zeros((n, 3)), np.ones(n, bool)),
        "position": AlignedGroup("position", [f"/gps/{HOSTILE}.x", "/gps/p.y", "/gps/p.z"], z, fresh),
    }
    return SimpleNamespace(t=t, dt=0.01, n_steps=n, groups=groups, mode=mode, mode_channel=channel)


def test_the_path_is_the_position_group_decimated_keeping_a_one_sample_glitch():
    path = path_of(quad_run(), get_model("quadcopter", {}))
    assert path is not None and path.group == "position"
    assert path.channels == (f"/gps/{HOSTILE}.x", "/gps/p.y")
    assert MAX_PATH_POINTS * 0.6 <= path.t.size <= MAX_PATH_POINTS
    assert np.all(np.diff(path.t) > 0) and np.isfinite(path.x).all() and np.isfinite(path.y).all()
    assert path.x.max() == 500.0 and path.t[np.argmax(path.x)] == pytest.approx(1800.0)
    assert not np.any((path.t >= 10.0) & (path.t < 20.0))  # the gap holds no made-up point


def test_no_path_without_a_group_measuring_the_states_x_and_y():
    run = quad_run(1_000)
    del run.groups["position"]
    assert path_of(run, get_model("quadcopter", {})) is None
    sbw = get_model("steer_by_wire", {})  # no states named x and y
    assert path_of(quad_run(1_000), sbw) is None


def test_a_gnss_the_model_does_not_take_as_its_position_is_drawn_east_and_north():
    # the wheeled model measures position as x + a GNSS error state, so no group maps onto x, y
    # directly; a geodetic group's east/north columns about its first fix are the path
    n = 200
    fresh = np.arange(n) % 4 == 0
    z = np.column_stack([np.linspace(0.0, 30.0, n), np.linspace(0.0, -12.0, n)])  # north first (frame "ne")
    channels = ["/fix/{latitude,longitude} north", "/fix/{latitude,longitude} east"]
    gnss = AlignedGroup("position", channels, z, fresh, origin=(42.37, -71.14, 7.3))
    run = SimpleNamespace(t=np.arange(n) * 0.1, dt=0.1, n_steps=n, groups={"position": gnss})
    path = path_of(run, get_model("wheeled", {}))
    assert path is not None and path.group == "position" and path.columns == (1, 0)
    assert path.channels == ("east (m from the first fix)", "north (m from the first fix)")
    np.testing.assert_array_equal(path.x, z[fresh, 1])
    gnss.origin = None  # the same columns not converted from geodetic: no map
    assert path_of(run, get_model("wheeled", {})) is None


def test_mode_intervals_of_a_flight_mode():
    n = 60_000
    mode = np.zeros(n)
    mode[1_500:] = 1.0
    mode[30_000:31_000] = np.nan  # not received: no interval
    mode[40_000:] = 2.0
    track = mode_of(quad_run(n, mode))
    assert track.channel == "/flight_mode/mode"
    expected = [(0.0, 15.0, 0.0), (15.0, 300.0, 1.0), (310.0, 400.0, 1.0), (400.0, 600.0, 2.0)]
    assert np.allclose(track.intervals, expected)
    assert track.n_changes == 4
    assert track.t.size <= 20  # flat runs drawn by their edges only


def test_a_continuous_set_point_is_a_decimated_series_without_bands():
    t = np.arange(N) * 0.01
    track = mode_of(quad_run(N, np.sin(t)))
    assert track.intervals == [] and track.n_changes > MAX_MODE_INTERVALS
    assert track.t.size <= 1_000 and track.value.max() == pytest.approx(1.0, abs=1e-6)


def test_no_mode_without_a_channel_or_samples():
    assert mode_of(quad_run(100)) is None
    assert mode_of(quad_run(100, np.full(100, np.nan))) is None


def test_prepare_keeps_the_context_after_the_series_are_released():
    from logscan.needs import Needs
    from logscan.pipeline import load_profile_for, prepare

    log = "sample_logs/quad_imu_bias.mcap"
    prepared = prepare(log, load_profile_for(log, None), Needs())
    prepared.release_series()
    context = prepared.context
    assert context.path.channels == ("/gps/position.x", "/gps/position.y") and context.path.t.size == 601
    assert np.allclose(context.mode.intervals, [(0.0, 15.0, 0.0), (15.0, 60.01, 1.0)])


def sample_context(n: int = N, hostile: bool = True) -> RunContext:
    """A path circling for the whole run and a mode with three values, in seconds of the grid."""
    t = np.linspace(0.0, (n - 1) * 0.01, MAX_PATH_POINTS)
    path = Path2D(t, 50 * np.cos(t / 100), 50 * np.sin(t / 100), (f"/gps/{HOSTILE if hostile else 'p'}.x", "/gps/p.y"),
                  "position")  # fmt: skip
    end = (n - 1) * 0.01
    cuts = [0.0, end / 3, 2 * end / 3, end]
    intervals = [(cuts[i], cuts[i + 1], float(i)) for i in range(3)]
    mode = ModeTrack("/flight_mode/mode" if not hostile else f"/{HOSTILE}/mode",
                     np.array([0.0, cuts[1], cuts[2], end]), np.array([0.0, 1.0, 2.0, 2.0]), intervals, 2)  # fmt: skip
    return RunContext(path, mode)


def test_the_report_draws_the_mode_on_the_time_axis_and_the_path_with_incidents():
    report = make_report(60_000)
    report.context = sample_context(60_000)
    report.incidents = [Incident(100.0, 101.0, "accel", "accel <b>x</b>", [])]
    page = render_html(report)
    specs = {spec["id"]: spec["figure"] for spec in figures(page)}
    # the mode is a row of the Context section's one figure on the time axis
    assert re.search(r'<div class="figure ls-timeseries ls-section" id="ctx-time" data-rows="1"', page)
    assert re.search(r'<div class="figure" id="ctx-path"', page)  # not on the time axis
    mode = specs["ctx-time"]
    assert [tr["name"] for tr in mode["data"]][:3] == [f"/{HOSTILE_SHOWN}/mode = {v}" for v in (0, 1, 2)]
    assert mode["layout"]["margin"]["l"] == specs["fig-0"]["layout"]["margin"]["l"]  # time axes align
    path = specs["ctx-path"]
    assert path["layout"]["yaxis"]["scaleanchor"] == "x"
    marks = next(tr for tr in path["data"] if tr["name"] == "incident start")
    assert marks["text"] == ["1"] and marks["hovertext"][0].startswith("incident 1: accel &lt;b&gt;x&lt;/b&gt;<br>")
    assert marks["customdata"] == [[100.0, 101.0]]  # a click zooms the time axis to the incident
    x0 = float(array(marks["x"])[0])
    assert x0 == pytest.approx(50 * np.cos(1.0), abs=0.1)  # where the vehicle was at 100 s
    assert HOSTILE not in page


def test_context_points_come_out_of_the_report_point_budget():
    report = make_report(60_000, hostile=False)
    plain = figures(render_html(report))
    report.context = sample_context(60_000, hostile=False)
    with_context = figures(render_html(report))

    def points(specs):
        return sum(array(tr["x"]).size for spec in specs for tr in spec["figure"]["data"] if isinstance(tr["x"], dict))

    assert points(with_context) <= points(plain) + 200  # the path's points were paid for
    assert points(with_context) <= POINT_BUDGET + 2_000


class TruthChannel(SimpleNamespace):
    def __len__(self) -> int:
        return len(self.values)


def test_true_states_hold_the_latest_truth_sample_and_are_nan_before_the_first():
    t_ns = np.array([15, 25, 40], dtype=np.int64) * 10**8  # 1.5, 2.5, 4.0 s after the log's zero
    shared = TruthChannel(t=t_ns, values=np.array([1.0, 2.0, 3.0]))
    late = TruthChannel(t=t_ns + 10**9, values=np.array([7.0, 8.0, 9.0]))
    log = SimpleNamespace(
        truth={"true_state_topic": "/truth", "true_state_fields": ["px", "py", "vx", "nope"]},
        channels={"/truth/px": shared, "/truth/py": TruthChannel(t=t_ns, values=-shared.values), "/truth/vx": late},
    )
    run = SimpleNamespace(start_ns=0, t=np.arange(0.0, 5.5, 0.5))
    model = SimpleNamespace(state_names=["px", "py", "vx"])
    nan = np.nan
    truth = true_states(log, run, model)
    assert sorted(truth) == ["px", "py", "vx"]
    px = [nan, nan, nan, 1.0, 1.0, 2.0, 2.0, 2.0, 3.0, 3.0, 3.0]
    np.testing.assert_array_equal(truth["px"], px)
    np.testing.assert_array_equal(truth["py"], -np.array(px))
    np.testing.assert_array_equal(truth["vx"], [nan] * 5 + [7.0, 7.0, 8.0, 8.0, 8.0, 9.0])
    assert all(values.dtype == np.float64 for values in truth.values())
