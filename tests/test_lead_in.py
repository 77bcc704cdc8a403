"""A window's EKF starts from its lead-in (`logscan.pipeline.lead_in`): the log before the window,
filtered into its first step, so that the window judges what the whole log's analysis judges there."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import SAMPLES, need_testdata

from logscan.needs import Needs
from logscan.pipeline import lead_in, load_profile_for, preparation, prepare
from logscan.pipeline import stages as pipeline_stages
from logscan.results import AlarmPolicy

QUAD = str(SAMPLES / "quad_healthy.mcap")
TRACE_ROWS = ("x_prior", "x_post", "P_prior_diag", "P_post_diag", "nis", "nis_group", "updated", "seeded")


def _prepared(path: str, **window):
    return prepare(path, load_profile_for(path, None), Needs.of(ekf=()), **window)


@pytest.fixture(scope="module")
def whole():
    return _prepared(QUAD)


def _first_row(whole, window) -> int:
    return int(np.flatnonzero(whole.run.t == window.run.t[0])[0])


@pytest.mark.parametrize(
    ("log", "start"),
    [
        ("quad_healthy.mcap", 10.0),
        ("quad_healthy.mcap", 10.05),  # the position group not fresh at the window's first step
        ("quad_healthy.mcap", 12.34),
        ("ros2_ins.mcap", 12.34),
        ("jackal_healthy.mcap", 10.0037),  # between two grid steps
    ],
)
def test_a_lead_in_back_to_the_log_start_gives_the_whole_runs_rows(log, start):
    path = str(SAMPLES / log)
    whole, window = _prepared(path), _prepared(path, start_s=start, end_s=start + 5.0)
    assert window.lead_in is not None and window.lead_in.start_s == whole.run.t[0]
    first = _first_row(whole, window)
    rows = slice(first, first + window.run.n_steps)
    for name in TRACE_ROWS:
        assert np.array_equal(getattr(window.trace, name), getattr(whole.trace, name)[rows], equal_nan=True), name
    assert window.filter_summary()["lead_in_s"] == pytest.approx(window.run.t[0] - whole.run.t[0])


def test_a_log_starting_before_time_zero_is_led_in_from_its_first_step():
    """This real ULog's first grid step is at -0.028 s: the lead-in starts there, the whole run's
    start, so the window is the whole run's rows."""
    path = str(need_testdata("px4-ulog/sample_logging_tagged_and_default_params.ulg"))
    whole, window = _prepared(path), _prepared(path, start_s=10.05, end_s=10.7)
    assert whole.run.t[0] < 0.0 and window.lead_in is not None and window.lead_in.start_s == whole.run.t[0]
    first = _first_row(whole, window)
    rows = slice(first, first + window.run.n_steps)
    for name in TRACE_ROWS:
        assert np.array_equal(getattr(window.trace, name), getattr(whole.trace, name)[rows], equal_nan=True), name


def test_a_mid_flight_window_starts_where_two_lead_ins_agree(whole, monkeypatch):
    """Lead-ins of 10, 20 and 40 s before a window from 50 s (the sample is 60 s long): the window's
    first second of innovations from the 10-s and the 20-s one agree, so the 20-s one is taken; its
    start is the whole run's to a hundredth of a standard deviation, where the model's prior is tens
    of them away."""
    monkeypatch.setattr(lead_in, "LEAD_IN_S", 10.0)
    monkeypatch.setattr(lead_in, "MAX_LEAD_IN_S", 40.0)
    window = _prepared(QUAD, start_s=50.0, end_s=55.0)
    first = _first_row(whole, window)
    assert window.lead_in is not None and window.lead_in.start_s == pytest.approx(30.0)
    assert not window.lead_in.warning
    sigma = np.sqrt(whole.trace.P_prior_diag[first])
    assert (np.abs(window.trace.x_prior[0] - whole.trace.x_prior[first]) / sigma).max() < 1e-2
    monkeypatch.setattr(preparation, "lead_in_start", lambda start_s: None)  # no lead-in: the prior
    cold = _prepared(QUAD, start_s=50.0, end_s=55.0)
    assert cold.lead_in is None
    assert (np.abs(cold.trace.x_prior[0] - whole.trace.x_prior[first]) / sigma).max() > 1.0


def test_a_geodetic_window_takes_the_lead_ins_origin():
    """The INS sample's GNSS is converted about its first fix: the window's about the lead-in's, so
    the state carried in is in the window's frame (a window's own first fix moved the positions by
    metres under a state that was not: NIS 54 against 12). Led in from the log's start, the window
    is the whole run's."""
    path = str(SAMPLES / "ros2_ins.mcap")
    whole, window = _prepared(path), _prepared(path, start_s=33.0, end_s=35.0)
    first = _first_row(whole, window)
    assert window.run.groups["gnss_position"].origin == whole.run.groups["gnss_position"].origin
    rows = slice(first, first + window.run.n_steps)
    for name in TRACE_ROWS:
        assert np.array_equal(getattr(window.trace, name), getattr(whole.trace, name)[rows], equal_nan=True), name


def test_a_lead_in_that_does_not_settle_is_said(monkeypatch):
    """Lead-ins of 10 and 20 s asked to agree to 1e-12 of the innovations' spread (they differ by
    more): the longest is taken, and the verdict's warnings say the window's first steps may still
    judge the filter's start."""
    monkeypatch.setattr(lead_in, "LEAD_IN_S", 10.0)
    monkeypatch.setattr(lead_in, "MAX_LEAD_IN_S", 20.0)
    monkeypatch.setattr(lead_in, "SETTLED_SIGMA", 1e-12)
    window = _prepared(str(SAMPLES / "ros2_ins.mcap"), start_s=33.0, end_s=35.0)
    assert window.lead_in is not None and window.lead_in.start_s == pytest.approx(13.0)
    assert any("had not settled over the 20 s before the window" in w for w in window.warnings)


def test_a_window_from_the_log_start_has_no_lead_in():
    assert _prepared(QUAD, start_s=0.0, end_s=20.0).lead_in is None
    assert _prepared(QUAD, end_s=20.0).lead_in is None
    assert lead_in.lead_in_start(None) is None and lead_in.lead_in_start(0.0) is None
    assert lead_in.lead_in_start(300.0) == 300.0 - lead_in.MAX_LEAD_IN_S
    assert lead_in.lead_in_start(12.0) == 12.0 - lead_in.MAX_LEAD_IN_S  # alignment starts at the log's first step


def test_a_window_whose_filter_diverges_is_filtered_from_the_prior(monkeypatch):
    """A restart returns to x0, P0: with the lead-in's they would not be the model's prior."""
    calls = []
    ekf = pipeline_stages.FILTERS["ekf"]

    def diverging(model, run, parts, **start):
        calls.append(sorted(start))
        trace = ekf(model, run, parts, **start)
        if "x0" in start:
            trace.diverged[5] = True
        return trace

    monkeypatch.setitem(pipeline_stages.FILTERS, "ekf", diverging)
    window = _prepared(QUAD, start_s=45.0, end_s=55.0)
    assert calls == [["P0", "seed", "steps_done", "x0"], ["steps_done"]]
    assert window.lead_in is None and not window.trace.diverged.any()


def test_ignore_start_counts_from_where_the_filter_started():
    t = np.arange(0.0, 20.0, 0.01)
    policy = AlarmPolicy(ignore_start_s=5.0)
    cold = policy.suspend(t, None)
    assert cold.start_held and cold.suspended[:500].all() and not cold.suspended[500:].any()
    led = policy.suspend(t, None, filter_from=-30.0)  # the filter led in from 30 s before the run
    assert led.suspended is None and not led.start_held
    partly = policy.suspend(t + 2.0, None, filter_from=0.0)  # a window from 2 s, led in from the log's start
    assert partly.suspended[:300].all() and not partly.suspended[300:].any()


def test_a_px4_window_is_judged_from_its_first_step(cli, tmp_path):
    """The built-in PX4 profile holds back the first 5 s while its filter converges: the log's, not
    each window's. The window from 8 s of this real flight starts before the GNSS's first sample
    (9.1 s): the lead-in seeds attitude, and the window seeds every direct group from its next
    sample."""
    path = str(need_testdata("px4-ulog/sample_px4_events.ulg"))
    out = tmp_path / "w.json"
    result = cli("analyze", path, "--start", "8", "--end", "25", "--no-report", "--json", str(out))
    assert result.exit_code in (0, 1, 2), result.stdout + result.stderr
    assert "filtered from 0.0 s" in result.stdout.splitlines()[0]
    log = json.loads(out.read_text())["logs"][0]
    assert log["filter"]["lead_in_s"] == 8.0
    judged = [line for line in log["warnings"] + log["unchecked"] if "not judged" in line]
    assert judged and not any("the first 5 s" in line for line in judged)
    whole = tmp_path / "whole.json"
    cli("analyze", path, "--no-report", "--json", str(whole))
    whole_log = json.loads(whole.read_text())["logs"][0]
    assert any("the first 5 s" in line for line in whole_log["warnings"] + whole_log["unchecked"])


def test_a_state_no_sensor_sees_does_not_hold_the_lead_in_back():
    """The husky's drive (a real ROS 1 bag): its wheeled model has states the sensors barely see (a
    GNSS error, a yaw-rate ratio), where the 60-s lead-in ends 15 standard deviations from the whole
    run; the window's first second of innovations is the whole run's within 0.1 of NIS (from the
    model's prior: 0.26). The lead-ins agree where the detectors look: the 60-s one is taken,
    without a warning."""
    path = str(need_testdata("ros-robots/robot_localization_test1_husky.bag"))
    whole, window = _prepared(path), _prepared(path, start_s=300.0, end_s=390.0)
    assert window.lead_in is not None and not window.lead_in.warning
    assert float(window.run.t[0]) - window.lead_in.start_s == pytest.approx(60.0)
    assert not any("had not settled" in w for w in window.warnings)
    first = _first_row(whole, window)
    sigma = np.sqrt(whole.trace.P_prior_diag[first])
    assert (np.abs(window.trace.x_prior[0] - whole.trace.x_prior[first]) / sigma).max() > 1.0
    second = int(round(1.0 / window.run.dt))
    nis = np.abs(window.trace.nis[:second] - whole.trace.nis[first : first + second])
    assert np.nanmax(nis) < 0.1


def test_the_lead_in_filtered_a_chunk_at_a_time_is_the_same(monkeypatch):
    """Chunks of 7 rows, each from the state the one before left: the window's rows are still the
    whole run's; with the direct groups' seeding half done at a chunk's start (this real flight's
    GNSS has no sample before 9.1 s) the lead-in is filtered in one go, and gives what it gave."""
    monkeypatch.setattr(lead_in, "CHUNK", 7)
    test_a_lead_in_back_to_the_log_start_gives_the_whole_runs_rows("quad_healthy.mcap", 12.34)
    path = str(need_testdata("px4-ulog/sample_px4_events.ulg"))
    chunked = _prepared(path, start_s=8.0, end_s=12.0)
    monkeypatch.setattr(lead_in, "CHUNK", 4096)
    whole_lead = _prepared(path, start_s=8.0, end_s=12.0)
    assert chunked.lead_in is not None and chunked.lead_in.seed
    assert np.array_equal(chunked.lead_in.x0, whole_lead.lead_in.x0)
    assert np.array_equal(chunked.lead_in.P0, whole_lead.lead_in.P0)


def test_the_window_options_help_states_the_longest_lead_in():
    from logscan.cli.options import window_options

    command = window_options("Analyse", "the log", "e.g.")(lambda **kwargs: None)
    start = next(p for p in command.__click_params__ if p.name == "start_s")
    assert f"up to {lead_in.MAX_LEAD_IN_S:g} s of the log before it" in start.help
