"""The [alarms] masks cannot hide a fault: a land detector's blip in flight is flight, the checks of
the vehicle's own reports (health, logged messages, PX4's estimator flags) are never suspended, and a
log whose flight was mostly not judged is "not fully checked", never "no alarms"."""

from __future__ import annotations

import json
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import need_testdata
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.detectors.base import Detector
from logscan.needs import Needs
from logscan.pipeline import load_profile_for, prepare
from logscan.results import AlarmPolicy, GroundAround
from logscan.training.calibration import judged_steps
from logscan.verdict.coverage import MAX_UNJUDGED_FLIGHT, judged_share, unjudged_flight

DT = 0.02
T = np.arange(0.0, 30.0, DT)


def _ground(*spans) -> np.ndarray:
    """1.0 on the ground over each (start, end) span of T, 0.0 in the air."""
    out = np.zeros(T.size)
    for start, end in spans:
        out[(T >= start - 1e-9) & (T < end - 1e-9)] = 1.0
    return out


def test_a_land_detector_blip_in_flight_is_flight():
    """A 'landed' of 0.14 s in flight (PX4's flag true for a message or two during a fall) neither
    suspends the steps around it nor starts a take-off transient: min_ground_s ignores it, a real
    landing longer than that is kept, and so is ground time at the log's start or end."""
    policy = AlarmPolicy(ground_channel="g", after_ground_s=5.0, before_ground_s=3.0, min_ground_s=1.0)
    clean = policy.suspend(T, _ground((0, 10), (25, 30))).suspended
    blip = _ground((0, 10), (17.0, 17.14), (25, 30))
    assert np.array_equal(policy.suspend(T, blip).suspended, clean)
    assert not clean[(T >= 15.0) & (T < 22.0)].any()  # judged through the blip
    # the same blip without min_ground_s: 3 s before it to 5 s after it unjudged (the fault hidden)
    old = AlarmPolicy(ground_channel="g", after_ground_s=5.0, before_ground_s=3.0).suspend(T, blip).suspended
    assert old[(T >= 14.0) & (T < 22.1)].all()
    # the flight mask counts the blip as flight
    assert np.array_equal(policy.suspend(T, blip).airborne, _ground((0, 10), (25, 30)) == 0.0)
    # a landing of 2 s in flight is a landing: suspended, with its take-off transient after it
    hop = policy.suspend(T, _ground((0, 10), (17, 19), (25, 30))).suspended
    assert hop[(T >= 14.0) & (T < 24.0)].all()
    # ground time shorter than min_ground_s at the log's start or end is still ground
    edges = policy.suspend(T, _ground((0, 0.5), (29.6, 30))).suspended
    assert edges[T < 5.5].all() and edges[T >= 26.6].all()


class _Flags(Detector):
    """A check of what the vehicle reported: it reads the autopilot's own topics."""

    name = "flags_under_test"
    raw_topics = ("vehicle_status_0",)

    def _run(self, run, trace, **context):
        result = self.new_result()
        result.add_statistic(run.t, "flags_under_test.flag", np.where(run.t >= 2.0, 2.0, 0.0), upper=1.0)
        return result


class _Model(_Flags):
    """The same statistic from a model: suspended like every model-based statistic."""

    name = "model_under_test"
    raw_topics = ()


@pytest.mark.parametrize(("detector", "alarms"), [(_Flags, 1), (_Model, 0)])
def test_only_model_based_statistics_are_suspended(detector, alarms):
    t = np.arange(0.0, 4.0, 0.1)
    run = SimpleNamespace(t=t, n_steps=t.size)
    policy = AlarmPolicy(ignore_start_s=5.0).suspend(t, None)  # the whole run suspended
    result = detector().run(run, None, alarm_policy=policy)
    assert len(result.alarms) == alarms
    assert policy.suspended is not None  # the policy itself is left as it was


def _unjudged(policy, ground):
    return unjudged_flight(policy.suspend(T, ground), SimpleNamespace(dt=DT))


def test_more_than_half_of_the_flight_unjudged_is_not_fully_checked():
    on_ground = AlarmPolicy(ground_channel="g", after_ground_s=5.0, before_ground_s=3.0, min_ground_s=1.0)
    # 20 s of flight, 8 s of it unjudged (take-off, landing): a warning, and the flight is said
    line, over = _unjudged(on_ground, _ground((0, 5), (25, 30)))
    assert not over and line.startswith("not judged for") and "8.0 s of the 20.0 s in flight" in line
    # 10 s of flight, 8 s of it unjudged: more than MAX_UNJUDGED_FLIGHT, the log is not fully checked
    line, over = _unjudged(on_ground, _ground((0, 10), (20, 30)))
    assert MAX_UNJUDGED_FLIGHT == 0.5 and over and "8.0 s of the 10.0 s in flight" in line
    assert "model-based statistics" in line and "5 s after take-off and 3 s before landing" in line
    # never in flight: the model-based statistics judged nothing
    line, over = _unjudged(on_ground, np.ones(T.size))
    assert over and "g never says airborne" in line
    # no ground channel: the scope is the whole log
    assert _unjudged(AlarmPolicy(ignore_start_s=5.0), None)[1] is False
    assert _unjudged(AlarmPolicy(ignore_start_s=20.0), None)[1] is True
    assert unjudged_flight(AlarmPolicy(), SimpleNamespace(dt=DT)) is None  # nothing suspended


def _quaternion_product(q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """q r for (n, 4) q and one (4,) r, w first (Hamilton)."""
    w1, x1, y1, z1 = q.T
    w2, x2, y2, z2 = r
    return np.stack(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ],
        axis=1,
    )


def blip_and_attitude_failure(source, target, at_s: float, roll_deg: float, blip_s: float = 0.14):
    """A copy of a real ULog with PX4's land detector saying 'landed' for ``blip_s`` from ``at_s``
    (seconds from the log's start: two messages, as during a fall) and its attitude estimate rolled by
    ``roll_deg`` from then on (an attitude failure): both at the same moment."""
    from pyulog import ULog

    ulog = ULog(str(source))
    at_us = ulog.start_timestamp + int(at_s * 1e6)
    for data in ulog.data_list:
        if data.name == "vehicle_land_detected" and data.multi_id == 0:
            i = int(np.searchsorted(data.data["timestamp"], at_us))
            for key, values in data.data.items():  # two messages like the one before, then edited
                data.data[key] = np.insert(values, [i, i], values[i - 1])
            data.data["timestamp"][i : i + 2] = (at_us, at_us + int(blip_s * 1e6))
            data.data["landed"][i : i + 2] = (1, 0)
        if data.name == "vehicle_attitude" and data.multi_id == 0:
            after = data.data["timestamp"] >= at_us
            q = np.stack([data.data[f"q[{j}]"] for j in range(4)], axis=1).astype(np.float64)
            half = np.radians(roll_deg) / 2.0
            rolled = _quaternion_product(q, np.array([np.cos(half), np.sin(half), 0.0, 0.0]))
            for j in range(4):
                data.data[f"q[{j}]"][after] = rolled[after, j]
    ulog.write_ulog(str(target))
    return target


def _first_alarm(cli, path, tmp_path, *args) -> tuple[int, dict, float]:
    out = tmp_path / f"summary{len(args)}.json"
    result = cli("analyze", str(path), "--no-report", "--json", str(out), *args)
    assert "Traceback" not in result.stderr, result.stderr
    (log,) = json.loads(out.read_text())["logs"]
    starts = [a["start"] for d in log["detectors"] if d["detector"] == "nis" for a in d["alarms"]]
    return result.exit_code, log, min(starts, default=float("inf"))


@pytest.mark.testdata("px4-ulog/sample_px4_events.ulg")
def test_a_fault_inside_a_land_detector_blip_is_alarmed_within_1_s(cli, tmp_path):
    """The real SITL flight (take-off 16.74 s, landing 28.13 s) edited: a 0.14 s 'landed' blip and a
    60 degree attitude failure both at 23.0 s. The built-in profile alarms within 1 s of the onset;
    the same profile without min_ground_s (the blip taken for a landing) hides it."""
    from logscan.pipeline import builtin_profile_for

    source = need_testdata("px4-ulog/sample_px4_events.ulg")
    edited = blip_and_attitude_failure(source, tmp_path / "blip.ulg", at_s=23.0, roll_deg=60.0)
    code, log, first = _first_alarm(cli, edited, tmp_path)
    assert 23.0 <= first <= 24.0, (first, log["verdict"])
    assert code in (1, 2) and log["n_alarms"] > 0
    text = builtin_profile_for(edited).text
    assert "min_ground_s = 1  # LNDMC_TRIG_TIME" in text  # the log's own land detector trigger time
    old = tmp_path / "old.toml"
    old.write_text("\n".join(line for line in text.splitlines() if not line.startswith("min_ground_s")))
    _, log_old, first_old = _first_alarm(cli, edited, tmp_path, "--profile", str(old))
    assert first_old > 24.0, log_old["verdict"]  # the mask hid it: the test can fail


@pytest.mark.testdata("px4-ulog-extra/robologs_fmu_v5_test.ulg")
def test_the_autopilots_battery_error_is_never_no_alarms(cli, tmp_path):
    """A 9 s real flight whose first 5 s are the filter converging and the rest take-off transients:
    the model-based statistics judged none of its 2.7 s in flight (not fully checked), while the
    autopilot's own ERROR ("Dangerous battery level", 3.24 s boot time) and the battery check alarm."""
    path = need_testdata("px4-ulog-extra/robologs_fmu_v5_test.ulg")
    out = tmp_path / "s.json"
    result = cli("analyze", str(path), "--no-report", "--json", str(out))
    (log,) = json.loads(out.read_text())["logs"]
    assert result.exit_code == 2 and "not fully checked" in log["verdict"]
    assert not log["verdict"].startswith("no alarms")
    (line,) = [u for u in log["unchecked"] if "model-based statistics" in u]
    assert "2.7 s of the 2.7 s in flight" in line
    alarms = {a["signal"]: a for d in log["detectors"] if d["detector"] == "health" for a in d["alarms"]}
    error = alarms["health.logged_error"]  # at 3.24 s of PX4's boot time, 0.11 s into the log
    assert abs(error["start_clock"] - 3.24) < 0.05 and error["start"] < 5.0  # inside the first 5 s
    assert "health.battery" in alarms
    assert cli("analyze", str(path), "--no-report", "--allow-partial").exit_code == 1


def test_a_partly_suspended_log_is_never_said_to_be_checked_on_the_whole_log(cli, sample, tmp_path):
    """At most half of the log unjudged: a warning, the verdict stands, and the report says what the
    model-based statistics skipped where it would say "Every check ran on the whole log"."""
    from logscan.readers import read_embedded_profile

    path = sample("quad_healthy.mcap")
    profile = tmp_path / "p.toml"
    profile.write_text(read_embedded_profile(path) + "\n[alarms]\nignore_start_s = 2\n")
    report, out = tmp_path / "r.html", tmp_path / "s.json"
    result = cli("analyze", str(path), "--profile", str(profile), "-o", str(report), "--json", str(out))
    (log,) = json.loads(out.read_text())["logs"]
    assert result.exit_code == 0 and log["unchecked"] == [], log["unchecked"]
    (line,) = [w for w in log["warnings"] if w.startswith("not judged for 2.0 s of")]
    page = report.read_text(encoding="utf-8")
    assert "Every check ran on the whole log" not in page
    assert f"Every check ran; the model-based statistics were {line}" in page


@settings(max_examples=200, deadline=None)
@given(
    spans=st.lists(st.tuples(st.floats(0.0, 29.0), st.floats(0.02, 6.0)), max_size=5),
    window=st.tuples(st.floats(0.0, 29.0), st.floats(0.5, 30.0)),
    min_ground_s=st.sampled_from([0.0, 1.0]),
    before_ground_s=st.sampled_from([0.0, 3.0]),
)
def test_a_windows_suspension_is_the_whole_logs_with_the_ground_around_it(spans, window, min_ground_s, before_ground_s):
    """A window (--start/--end) given the ground channel over `margins_s` before and after it holds
    back exactly the steps the whole log holds back there: a take-off before it, a landing after it
    and a blip across its edge are seen as in the whole log."""
    policy = AlarmPolicy(
        ground_channel="g", after_ground_s=5.0, before_ground_s=before_ground_s, min_ground_s=min_ground_s
    )
    ground = _ground(*[(start, start + length) for start, length in spans])
    whole = policy.suspend(T, ground)
    first = int(np.searchsorted(T, window[0]))
    stop = max(first + 1, int(np.searchsorted(T, window[0] + window[1])))
    before_s, after_s = policy.margins_s()
    lo = int(np.searchsorted(T, T[first] - before_s - 2 * DT))
    hi = int(np.searchsorted(T, T[stop - 1] + after_s + 2 * DT))
    around = GroundAround(T[lo:first], ground[lo:first], T[stop:hi], ground[stop:hi])
    windowed = policy.suspend(T[first:stop], ground[first:stop], around=around)
    expected = np.zeros(T.size, dtype=bool) if whole.suspended is None else whole.suspended
    got = np.zeros(stop - first, dtype=bool) if windowed.suspended is None else windowed.suspended
    assert np.array_equal(got, expected[first:stop])
    assert np.array_equal(windowed.airborne, whole.airborne[first:stop])


def test_a_px4_window_holds_back_what_the_whole_flight_does(cli, tmp_path):
    """This real flight's land detector says landed after 28 s. The whole log holds back the 3 s
    before (PX4 confirms a touchdown late); a window ending at 28 s had judged them and alarmed on
    the GNSS's vertical velocity at 26 s, in the descent. It now sees the landing after its end."""
    path = str(need_testdata("px4-ulog/sample_px4_events.ulg"))
    loaded = load_profile_for(path, None)
    policy = loaded.profile.alarm_policy
    whole = prepare(path, loaded, Needs.of(ekf=()))
    window = prepare(path, load_profile_for(path, None), Needs.of(ekf=()), start_s=12.0, end_s=28.0)
    assert window.run.ground_around is not None
    whole_held = policy.suspend(whole.run.t, whole.run.ground).suspended
    held = policy.suspend(window.run.t, window.run.ground, around=window.run.ground_around).suspended
    inside = np.isin(whole.run.t, window.run.t)
    assert np.array_equal(held, whole_held[inside])
    assert held[window.run.t >= 25.5].all()  # the descent before the landing
    out = tmp_path / "w.json"
    result = cli("analyze", path, "--start", "12", "--end", "28", "--no-report", "--json", str(out))
    assert result.exit_code == 2, result.stdout + result.stderr  # as the whole log: too little judged
    assert json.loads(out.read_text())["logs"][0]["n_alarms"] == 0


def _flight_csv(path, landed, seconds=600.0, rate=20):
    """A CSV flight: one slowly varying column and a `landed` flag from ``landed(t)``."""
    t = np.arange(int(round(seconds * rate)) + 1) / rate
    a = np.sin(t / 7.0) + 0.05 * np.random.default_rng(1).standard_normal(t.size)
    rows = "".join(f"{ti:.3f},{ai:.6f},{int(gi)}\n" for ti, ai, gi in zip(t, a, landed(t)))
    path.write_text("time_s,a,landed\n" + rows)


_PARAMS = """states = ["a"]
A = [[-0.005]]
B = [[]]
Q = [[0.01]]
C = { a = [[1]] }
R = { a = [0.05] }"""
# the log's profile and a further loop at half its rate, each with the same [alarms]
_LOOP_PROFILE = """
[vehicle]
model = "linear"
rate_hz = 20
[vehicle.params]
PARAMS
[measurements.a]
channels = ["/a"]
rate_hz = 20
noise_std = 0.05
[alarms]
ground_channel = "/landed"
ALARMS
[loops.twin.vehicle]
model = "linear"
rate_hz = 10
[loops.twin.vehicle.params]
PARAMS
[loops.twin.alarms]
ground_channel = "/landed"
ALARMS
[loops.twin.measurements.a]
channels = ["/a"]
rate_hz = 20
noise_std = 0.05
"""


@pytest.mark.parametrize(
    ("landed", "alarms", "windows"),
    [
        # a take-off at 20 s holds back 300 s after it: longer than the lead-in's 240 s
        (lambda t: t < 20, "after_ground_s = 300", [(280.0, 400.0), (300.0, None)]),
        # a ground span of 250 s within flight, a blip under min_ground_s = 300
        (lambda t: (t >= 10) & (t < 260), "min_ground_s = 300", [(255.0, 400.0)]),
        # landed on the last row only: an --end less than a grid step before it
        (lambda t: t >= 600.0 - 1e-9, "before_ground_s = 3", [(500.0, 599.99), (None, 599.96)]),
    ],
)
def test_a_windows_suspension_is_the_whole_logs_on_any_profile(tmp_path, landed, alarms, windows):
    """Each window (and a hierarchical profile's further loop, on its own grid) holds back the steps
    the whole log holds back there, whatever the margins: the window's alignment holds the ground
    channel on the whole grid's steps around it (`logscan.align.onto_grid`)."""
    log = tmp_path / "flight.csv"
    _flight_csv(log, landed)
    profile = tmp_path / "p.toml"
    profile.write_text(_LOOP_PROFILE.replace("PARAMS", _PARAMS).replace("ALARMS", alarms))
    whole = prepare(str(log), load_profile_for(str(log), str(profile)), Needs())
    for start, end in windows:
        window = prepare(str(log), load_profile_for(str(log), str(profile)), Needs(), start_s=start, end_s=end)
        for whole_run, run, policy in (
            (whole.run, window.run, whole.profile.alarm_policy),
            (whole.loops["twin"].run, window.loops["twin"].run, whole.loops["twin"].profile.alarm_policy),
        ):
            inside = np.isin(whole_run.t, run.t)
            expected = policy.suspend(whole_run.t, whole_run.ground)
            got = policy.suspend(run.t, run.ground, around=run.ground_around)
            none = np.zeros(whole_run.t.size, dtype=bool)
            want = (none if expected.suspended is None else expected.suspended)[inside]
            have = none[: run.t.size] if got.suspended is None else got.suspended
            assert np.array_equal(have, want), (start, end, int(have.sum()), int(want.sum()))
            assert np.array_equal(got.airborne, expected.airborne[inside])


def test_the_calibration_and_blind_warning_judge_a_window_as_its_detectors_do():
    """`judged_steps` (train --calibrate, the "blind" warning) counts ignore_start_s from where a
    window's filter started, as detection does: on this real flight from 18 s, led in from 0 s,
    nothing is held back as the filter's start."""
    path = str(need_testdata("px4-ulog/sample_px4_events.ulg"))
    window = prepare(path, load_profile_for(path, None), Needs.of(ekf=()), start_s=18.0)
    policy = window.profile.alarm_policy
    detected = policy.suspend(window.run.t, window.run.ground, window.filter_from, window.run.ground_around)
    judged = judged_steps(window.profile, window.run, window.filter_from)
    assert window.filter_from == 0.0 and not detected.start_held
    assert np.array_equal(judged, ~detected.suspended)
    cold = judged_steps(window.profile, window.run)  # as if the window's filter had started at 18 s
    assert cold.sum() < judged.sum()


def test_a_block_counts_its_own_steps_and_one_held_back_nowhere_still_counts():
    """Block mode (`AlarmPolicy.alarms_from_s`: the block's first step): the share counts from there,
    not the lead-in before it; a block all in flight, held back nowhere, gives a share of nothing
    unjudged (the log's sum needs its flight), where a log at once held back nowhere gives none."""
    on_ground = AlarmPolicy(ground_channel="g", after_ground_s=5.0)
    flying = on_ground.suspend(T, np.zeros(T.size))
    assert flying.suspended is None and unjudged_flight(flying, SimpleNamespace(dt=DT)) is None
    block = replace(flying, alarms_from_s=float(T[100]))
    share = judged_share(block, SimpleNamespace(t=T, dt=DT))
    assert share is not None and share.suspended_s == 0.0 and share.air_s == pytest.approx((T.size - 100) * DT)
    led = replace(on_ground.suspend(T, _ground((0, 10))), alarms_from_s=float(T[100]) + 1e-12)  # a border's rounding
    share = judged_share(led, SimpleNamespace(t=T, dt=DT))
    assert share is not None and share.total_s == pytest.approx((T.size - 100) * DT)
