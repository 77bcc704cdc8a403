"""An incident's source where judging resumes after the [alarms] suspension (rule 3 of
`logscan.verdict.incidents`): the alarms under way there began somewhere in the suspension, so
which one updated first says nothing; the larger peak heads the incident."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import need_testdata
from ulog_edit import edit_ulog

from logscan.alarms import alarm_intervals
from logscan.results import DetectorResult
from logscan.verdict.incidents import alarm_onsets, find_incidents

EVENTS = "px4-ulog/sample_px4_events.ulg"  # SITL quadcopter: take-off 16.7 s, judged from 21.7 s


@pytest.mark.testdata(EVENTS)
def test_a_gnss_jump_inside_the_take_off_mask_is_headed_by_the_gnss(cli, tmp_path):
    """The real flight's GNSS position jumps 20 m north at 18 s, inside the 5 s after take-off that
    are not judged. Where judging resumes (21.74 s) the attitude test's first update came 20 ms
    before the GNSS's and exceeded 1.6 times; the GNSS test 257 times: the incident was headed
    "attitude sensor inconsistent"."""
    from pyulog import ULog

    source = need_testdata(EVENTS)
    start_us = ULog(str(source), ["vehicle_gps_position"]).start_timestamp

    def jump(data) -> None:
        t = (data["timestamp"].astype(np.int64) - start_us) / 1e6
        data["latitude_deg"][t >= 18.0] += 20.0 / 111_320.0  # 20 m north, in degrees

    path = edit_ulog(source, tmp_path / "jump.ulg", {"vehicle_gps_position": jump})
    out = tmp_path / "s.json"
    cli("analyze", str(path), "--no-report", "--json", str(out))
    log = json.loads(out.read_text())["logs"][0]
    first = log["incidents"][0]
    assert first["source"] == "gnss_position", first
    assert first["start"] < 23.0  # the incident where judging resumed, not a later one


def _result(t, name, x, judged) -> DetectorResult:
    result = DetectorResult(detector="nis")
    result.series[name] = x
    result.judged[name] = judged
    result.alarms = alarm_intervals(t, x, 1.0, valid=judged, signal=name, detector="nis")
    return result


def test_alarms_under_way_where_judging_resumes_start_together():
    t = np.arange(100) * 0.01
    suspended = t < 0.5
    # a 100 Hz group exceeding slightly from 0.5 s, a 10 Hz group far more from its first update at 0.52 s
    small = np.where(t >= 0.3, 1.5, 0.5)
    every_tenth = np.isclose((t * 100) % 10, 2)
    large = np.where(every_tenth, np.where(t >= 0.3, 50.0, 0.5), np.nan)
    fast = _result(t, "nis.fast", small, ~suspended)
    slow = _result(t, "nis.slow", large, every_tenth & ~suspended)
    onsets = alarm_onsets([fast, slow], t, suspended)
    assert set(onsets.values()) == {0.5}
    (incident,) = find_incidents([fast, slow], None, ["fast", "slow"], onsets=onsets)
    assert incident.source == "slow"
    (unsorted,) = find_incidents([fast, slow], None, ["fast", "slow"])
    assert unsorted.source == "fast"  # the rule before: whichever updated first


def test_an_alarm_that_begins_after_judged_samples_keeps_its_own_start():
    t = np.arange(100) * 0.01
    suspended = t < 0.2
    x = np.where(t >= 0.6, 2.0, 0.5)
    result = _result(t, "nis.fast", x, ~suspended)
    assert alarm_onsets([result], t, suspended) == {}
    assert alarm_onsets([result], t, None) == {}


def test_a_held_input_heads_the_model_checks_incident_but_not_the_autopilots():
    from logscan.verdict.incidents import InputGap

    t = np.arange(100) * 0.01
    gap = InputGap(0.2, 0.4, ("/imu/gyro_z",))
    model = _result(t, "nis.fast", np.where((t >= 0.3) & (t < 0.6), 2.0, 0.5), np.ones(t.size, bool))
    (incident,) = find_incidents([model], None, ["fast"], gaps=[gap])
    assert incident.source == "/imu/gyro_z" and incident.what.startswith("model input /imu/gyro_z missing")
    later = _result(t, "nis.fast", np.where(t >= 0.8, 2.0, 0.5), np.ones(t.size, bool))
    assert find_incidents([later], None, ["fast"], gaps=[gap], gap_s=0.2)[0].source == "fast"
    health = DetectorResult(detector="health")
    health.alarms = alarm_intervals(t, np.where(t >= 0.25, 2.0, 0.5), 1.0, signal="health.battery", detector="health")
    incidents = find_incidents([health, model], None, ["fast"], gaps=[gap])
    assert incidents[0].source != "/imu/gyro_z"  # the autopilot's own check does not read the held input


@pytest.mark.testdata(EVENTS)
def test_a_fault_over_most_of_the_log_is_not_called_a_profile_mismatch(cli, tmp_path):
    """The real flight's GNSS walked north at 2 m/s from 19 s to its end: most of its GNSS updates
    lie in the fault, so its median NIS is far above the chi-square's and the verdict warned "model
    or profile mismatch ... --calibrate", advice that would widen the noise over the fault. Its
    checks alarmed: the warning says a fault is as likely, and to calibrate only on healthy logs."""
    from pyulog import ULog

    source = need_testdata(EVENTS)
    start_us = ULog(str(source), ["vehicle_gps_position"]).start_timestamp

    def walk(data) -> None:
        t = (data["timestamp"].astype(np.int64) - start_us) / 1e6
        data["latitude_deg"][:] += 2.0 * np.clip(t - 19.0, 0.0, None) / 111_320.0

    path = edit_ulog(source, tmp_path / "walk.ulg", {"vehicle_gps_position": walk})
    out = tmp_path / "s.json"
    cli("analyze", str(path), "--no-report", "--json", str(out))
    log = json.loads(out.read_text())["logs"][0]
    assert log["incidents"] and log["incidents"][0]["source"] == "gnss_position"
    (median,) = [w for w in log["warnings"] if w.startswith("group 'gnss_position': median NIS")]
    assert "a fault over much of the log" in median and "--calibrate" not in median


def test_a_group_headed_by_its_stuck_sensor_check_says_stuck():
    """A tester froze the real flight's barometer: the incident quoted frozen.baro (12.6x) and said
    "barometer inconsistent", though that check's own label is "stuck sensor"."""
    t = np.arange(100) * 0.01
    stuck = DetectorResult(detector="frozen")
    stuck.alarms = alarm_intervals(t, np.where(t >= 0.3, 5.0, 0.5), 1.0, signal="frozen.baro", detector="frozen")
    (incident,) = find_incidents([stuck], None, ["baro"])
    assert incident.what == "barometer stuck (its samples repeat one value)", incident.what


def test_no_input_gap_at_the_first_step():
    """The filter does not predict at step 0: an input not there yet (the Husky's odometry starts 3 ms
    after its IMU) held nothing, and headed a GNSS jump's incident in the first second."""
    from types import SimpleNamespace

    from logscan.verdict.incidents import input_gaps

    t = np.arange(10) * 0.1
    held = np.zeros(10, bool)
    held[0] = True
    held[5:7] = True
    u = np.ones((10, 1))
    u[0] = u[5:7] = np.nan
    run = SimpleNamespace(u=u, input_channels=["/odom/v"])
    gaps = input_gaps(SimpleNamespace(input_held=held, t=t), run)
    assert [(g.start, g.end, g.channels) for g in gaps] == [(t[5], t[6], ("/odom/v",))]


def _edited_events(tmp_path, topic: str, field: str, delta: float, name: str):
    """The real SITL flight with ``delta`` added to ``topic``'s ``field`` from 22 s (judged from 21.7 s)."""
    from pyulog import ULog

    source = need_testdata(EVENTS)
    start_us = ULog(str(source), [topic]).start_timestamp

    def add(data) -> None:
        t = (data["timestamp"].astype(np.int64) - start_us) / 1e6
        data[field][t >= 22.0] += delta

    return edit_ulog(source, tmp_path / name, {topic: add})


def _first_incident(cli, path, tmp_path) -> dict:
    out = tmp_path / f"{path.stem}.json"
    cli("analyze", str(path), "--no-report", "--json", str(out))
    incidents = json.loads(out.read_text())["logs"][0]["incidents"]
    assert incidents, path
    return incidents[0]


@pytest.mark.testdata(EVENTS)
def test_an_accelerometer_bias_is_headed_by_the_imu_not_the_gnss_velocity(cli, tmp_path):
    """The real flight's accelerometer z reads +1 m/s^2 from 22 s (sensor_combined): under the ins
    model the IMU drives the prediction, so the GNSS velocity's test alarmed first and headed the
    incident ("GNSS velocity inconsistent"). What the log says: the GNSS velocity down, the GNSS
    position down and the barometer all leave the prediction the way the integrated bias does (the
    vehicle higher than predicted), so the one thing they agree against is the input (rule 6)."""
    path = _edited_events(tmp_path, "sensor_combined", "accelerometer_m_s2[2]", 1.0, "accel_z.ulg")
    first = _first_incident(cli, path, tmp_path)
    assert first["source"].startswith("/sensor_combined_0/accelerometer_m_s2[0]"), first
    assert first["headline"].startswith("IMU accelerometer (the model's input) suspect: GNSS velocity v_down"), first
    assert "barometer altitude agree against its prediction" in first["headline"], first
    assert "a spoof" not in first["headline"], first  # the barometer, a sensor of its own, confirms
    assert 22.0 <= first["start"] <= 23.5, first


@pytest.mark.testdata(EVENTS)
@pytest.mark.parametrize(
    ("field", "delta", "group"),
    [
        ("vel_d_m_s", -1.0, "gnss_velocity"),  # a velocity spoof: the filter follows it, the position disagrees
        ("vel_n_m_s", 1.0, "gnss_velocity"),
        ("altitude_msl_m", -5.0, "gnss_position"),  # a position jump: the velocity is pulled against it
    ],
)
def test_a_gnss_spoof_stays_the_gnss(cli, tmp_path, field, delta, group):
    path = _edited_events(tmp_path, "vehicle_gps_position", field, delta, f"{field}.ulg")
    first = _first_incident(cli, path, tmp_path)
    assert first["source"] == group, first


def test_the_input_is_suspect_only_when_a_pair_agrees_and_none_disagrees():
    from logscan.verdict.input_fault import KinematicEvidence, input_suspect

    t = np.arange(200) * 0.01
    alarm = alarm_intervals(t, np.where(t >= 1.0, 2.0, 0.5), 1.0, signal="nis.vel", detector="nis")[0]
    after = (t >= 1.0)[:, None]

    def evidence(rate: float, level: float, level2: float = 0.0) -> KinematicEvidence:
        noise = np.random.default_rng(1).normal(size=(200, 4)).astype(np.float32)
        rates = noise[:, :2] + np.float32(rate) * after
        levels = noise[:, 2:] + np.float32(level) * after * np.array([[1.0, 0.0]]) + level2 * after * np.array([[0, 1]])
        names = [("GNSS velocity v_down", "GNSS position down"), ("GNSS velocity v_down", "barometer altitude")]
        pairs = (t, names, rates, levels.astype(np.float32))
        return KinematicEvidence(*pairs, frozenset({"vel", "pos"}), "IMU", "/imu", 0.01, (False, True))

    words = input_suspect(evidence(-3.0, -2.0), "vel", alarm)
    assert words is not None and words.startswith("GNSS velocity v_down and GNSS position down agree"), words
    # only the one receiver's velocity and position agree: a coherent spoof of both is not ruled out
    assert words.endswith("its fault moving both together (a spoof) looks alike"), words
    confirmed = input_suspect(evidence(-3.0, -2.0, -2.0), "vel", alarm)  # the barometer agrees too
    assert confirmed is not None and confirmed.endswith("agree against its prediction (" + confirmed.split("(")[-1])
    assert "a spoof" not in confirmed, confirmed
    assert input_suspect(evidence(-3.0, 2.0), "vel", alarm) is None  # opposite: the sensor's own fault
    assert input_suspect(evidence(-3.0, -2.0, 2.0), "vel", alarm) is None  # the barometer disagrees
    assert input_suspect(evidence(-3.0, 0.0), "vel", alarm) is None  # the position says nothing
    assert input_suspect(evidence(-3.0, -2.0), "other", alarm) is None  # a group no pair reads
    kept = evidence(-3.0, -2.0).within([alarm])
    assert kept.t.size == np.count_nonzero(t >= alarm.start - 1e-9) and input_suspect(kept, "vel", alarm) == words
