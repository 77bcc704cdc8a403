"""Built-in profiles (logscan.profiles.builtin) and the filter-consistency warnings.

A PX4 ULog with no profile gets the `px4` profile of the ins model, built from its topics: each of
the real PX4 logs of ../shared/testdata/px4-ulog is analysed with no flags (exit 0 or 1, never 2).
A deliberately mis-scaled profile draws the "model or profile mismatch" warning, a sound one none.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import need_testdata

from logscan.pipeline import builtin_profile_for, consistency_warnings
from logscan.profiles import parse_profile
from logscan.readers import read_embedded_profile

PX4_LOGS = [
    "sample_log_small.ulg",
    "sample_logging_tagged_and_default_params.ulg",
    "sample_px4_events.ulg",
    "sample_appended_multiple.ulg",
]


@pytest.mark.parametrize("name", PX4_LOGS)
def test_px4_log_gets_the_builtin_profile_and_is_analysed_with_no_flags(name, cli, tmp_path):
    path = need_testdata(f"px4-ulog/{name}")
    built = builtin_profile_for(path)
    assert built is not None and built.name == "px4"
    profile = parse_profile(built.text)
    assert profile.vehicle.model == "ins" and profile.vehicle.rate_hz >= 50
    assert {"gnss_position", "baro", "attitude"} <= set(profile.measurements)
    summary = tmp_path / "summary.json"
    result = cli("analyze", str(path), "-o", str(tmp_path / "report.html"), "--json", str(summary))
    assert result.exit_code in (0, 1, 2), result.stdout + result.stderr
    entry = json.loads(summary.read_text())["logs"][0]
    assert (result.exit_code == 2) == bool(entry["unchecked"])  # 2: not fully checked, and why
    assert entry["model"] == "ins" and entry["profile_source"].startswith("built-in")
    assert entry["filter"]["divergence_episodes"] == 0
    assert min(entry["filter"]["updates"].values()) >= 20


def test_the_builtin_profile_uses_the_logs_own_ekf2_noise_and_notes_what_it_left_out():
    path = need_testdata("px4-ulog/sample_appended_multiple.ulg")
    built = builtin_profile_for(path)
    profile = parse_profile(built.text)
    # this early log has no GNSS topic: PX4's local position stands in, said in a note
    assert "/vehicle_local_position_0/x" in profile.measurements["gnss_position"].channels
    assert "gnss_velocity" not in profile.measurements
    assert any("local position" in note for note in built.notes)
    # the baro's noise from PX4's own innovations (ekf2_innovations), its EKF2_BARO_NOISE (2.0;
    # PX4's default 3.5) the ceiling
    (baro,) = profile.measurements["baro"].noise_std
    assert 0.011 <= baro < 2.0 and "EKF2_BARO_NOISE" in built.text


def test_a_log_that_does_not_name_itself_gets_no_builtin_profile(sample):
    assert builtin_profile_for(sample("quad_healthy.csv")) is None
    assert builtin_profile_for(sample("quad_healthy.mcap")) is None


def test_mis_scaled_profile_draws_the_mismatch_warning_and_the_sound_one_none(sample, tmp_path):
    from logscan.pipeline import LoadedProfile, create_detectors, needs_of, prepare

    path = sample("quad_healthy.mcap")
    text = read_embedded_profile(path)
    sound = parse_profile(text)
    prepared = prepare(
        path, LoadedProfile(sound, text, "embedded"), needs_of(create_detectors(LoadedProfile(sound, text, "x")))
    )
    assert consistency_warnings(prepared) == []
    # an accelerometer logged in another unit (twice the value): the filter's fit of it falls apart
    wrong = text.replace("[measurements.accel]\n", "[measurements.accel]\nscale = 2.0\n")
    assert wrong != text
    bad = parse_profile(wrong)
    loaded = LoadedProfile(bad, wrong, "embedded")
    prepared = prepare(path, loaded, needs_of(create_detectors(loaded)))
    warnings = consistency_warnings(prepared)
    (warning,) = [w for w in warnings if "group 'accel'" in w]
    assert "mismatch" in warning and "units" in warning


def test_init_profile_writes_the_builtin_profile_and_never_replaces_a_file(cli, tmp_path):
    path = need_testdata("px4-ulog/sample_px4_events.ulg")
    out = tmp_path / "px4.toml"
    assert cli("init-profile", str(path), "-o", str(out)).exit_code == 0
    text = out.read_text()
    assert 'model = "ins"' in text and "# logscan built-in profile `px4`" in text
    assert parse_profile(text).measurements["gnss_position"].source == "geodetic"
    again = cli("init-profile", str(path), "-o", str(out))
    assert again.exit_code == 2 and "never replaces" in again.stderr
    assert out.read_text() == text
    # the written profile, passed back, analyses the log as the built-in one does
    result = cli("analyze", str(path), "--profile", str(out), "--no-report", "--allow-partial")
    assert result.exit_code in (0, 1), result.stderr


def test_analyze_print_profile_shows_the_profile_used(cli, sample):
    result = cli("analyze", sample("quad_healthy.mcap"), "--no-report", "--print-profile")
    assert result.exit_code == 0
    assert "# profile for" in result.stdout and "(embedded)" in result.stdout
    assert 'model = "quadcopter"' in result.stdout


def test_the_autopilots_warnings_are_drawn_on_the_time_axis(cli, tmp_path):
    from logscan.log import logged_messages
    from logscan.readers import read_log

    path = need_testdata("px4-ulog/sample_px4_events.ulg")
    log = read_log(path, topics={"vehicle_status_0"})
    messages = logged_messages(log.source.metadata, log.start_ns)
    assert [m.level for m in messages] == ["WARNING", "WARNING"] and "GPS fix" in messages[0].text
    assert 0.0 < messages[0].t < messages[1].t < log.duration_s
    report = tmp_path / "r.html"
    assert cli("analyze", str(path), "-o", str(report), "--allow-partial").exit_code in (0, 1)
    assert "ctx-messages" in report.read_text(encoding="utf-8")


def test_time_zero_is_the_logs_own_whatever_the_topics_read(cli, tmp_path):
    """A ULog's times count from its logger's start: reading more topics (the health detector's)
    must not move the grid, so an alarm time means the same under any profile."""
    path = need_testdata("px4-ulog/sample_appended_multiple.ulg")  # some topics start before the logger

    def grid_start(*detectors):
        out = tmp_path / f"{len(detectors)}.json"
        args = [a for d in detectors for a in ("-d", d)]
        assert cli("analyze", str(path), "--no-report", "--json", str(out), "--allow-partial", *args).exit_code in (
            0,
            1,
        )
        return json.loads(out.read_text())["logs"][0]["log"]

    grid_start("nis"), grid_start("nis", "health")  # health reads topics that start before the logger
    first = [json.loads((tmp_path / f"{n}.json").read_text())["logs"][0]["detectors"][0]["series"] for n in (1, 2)]
    assert first[0] == first[1]  # the grid, and every statistic on it, is the same


def test_ground_time_and_the_start_are_not_judged_and_say_so(cli, tmp_path):
    """The built-in px4 profile suspends the model-based statistics on the ground
    (vehicle_land_detected.landed), for 5 s after take-off, 3 s before landing and for the filter's
    first 5 s: said in one line, a warning while it leaves most of the flight judged; here it leaves
    8.0 s of the 11.4 s in flight, so the log is not fully checked (exit 2)."""
    path = need_testdata("px4-ulog/sample_px4_events.ulg")
    built = parse_profile(builtin_profile_for(path).text)
    policy = built.alarm_policy
    assert policy.ground_channel == "/vehicle_land_detected_0/landed" and policy.ignore_start_s == 5.0
    assert policy.before_ground_s == 3.0  # PX4 confirms a touchdown about 2 s after it
    assert policy.min_ground_s == 1.0  # the log's LNDMC_TRIG_TIME
    out = tmp_path / "s.json"
    result = cli("analyze", str(path), "--no-report", "--json", str(out))
    assert result.exit_code == 2
    entry = json.loads(out.read_text())["logs"][0]
    assert not [w for w in entry["warnings"] if "not judged for" in w]  # said once, as the reason
    (line,) = [u for u in entry["unchecked"] if "not judged for" in u]
    assert "on the ground" in line and "the first 5 s" in line and "3 s before landing" in line
    # the flight: take-off 16.74 s, landed 28.13 s; judged 21.74-25.13 s of its 31.1 s
    assert "not judged for 27.7 s of 31.1 s (8.0 s of the 11.4 s in flight)" in line, line


def test_suspension_of_a_policy():
    import numpy as np

    from logscan.results import AlarmPolicy

    t = np.arange(0.0, 30.0, 0.5)
    ground = np.where((t < 10.0) | (t >= 25.0), 1.0, 0.0)  # landed, flies 10-25 s, landed
    suspended = AlarmPolicy(ground_channel="g", after_ground_s=3.0, ignore_start_s=2.0).suspend(t, ground).suspended
    flying_judged = t[~suspended]
    assert flying_judged.min() == 13.0 and flying_judged.max() == 24.5  # take-off + 3 s .. landing
    assert AlarmPolicy().suspend(t, None).suspended is None  # nothing asked: nothing suspended
    # and 2 s before each landing (the touchdown a land detector confirms late)
    policy = AlarmPolicy(ground_channel="g", after_ground_s=3.0, before_ground_s=2.0)
    judged = t[~policy.suspend(t, ground).suspended]
    assert judged.min() == 13.0 and judged.max() == 22.5
    # a log that ends in the air has no landing to come: nothing suspended before its end
    airborne = np.where(t < 10.0, 1.0, 0.0)
    assert t[~policy.suspend(t, airborne).suspended].max() == t[-1]
    from logscan.pipeline import load_profile_for

    quad = str(Path(__file__).resolve().parent.parent / "sample_logs" / "quad_healthy.mcap")
    with_landing = (
        load_profile_for(quad, None).text + '\n[alarms]\nground_channel = "/flight_mode/mode"\nbefore_ground_s = 2\n'
    )
    assert "before_ground_s = 2.0" in parse_profile(with_landing).to_toml()


def test_the_autopilots_armed_and_failsafe_states_are_drawn(cli, tmp_path):
    import numpy as np

    from logscan.log import Channel
    from logscan.report.run_context import autopilot_states

    t = np.arange(0, 10) * 1_000_000_000
    raw = {
        "/vehicle_status_0/arming_state": Channel("a", t, np.array([1, 1, 2, 2, 2, 1, 1, 2, 2, 1.0])),
        "/vehicle_status_0/failsafe": Channel("f", t, np.zeros(10)),
    }
    states = autopilot_states(raw, 0, 10.0)
    assert states == {"armed": [(2.0, 5.0), (7.0, 9.0)], "failsafe": []}
    path = need_testdata("px4-ulog/sample_px4_events.ulg")
    report = tmp_path / "r.html"
    assert cli("analyze", str(path), "-o", str(report), "--allow-partial").exit_code in (0, 1)
    assert "ctx-states" in report.read_text(encoding="utf-8")


def test_plain_words_for_the_autopilot_checks():
    from logscan.alarms import AlarmInterval
    from logscan.verdict.incidents import headline, plain_words

    assert plain_words("health.gnss_fix", "health") == "GNSS 3D fix lost"
    assert plain_words("px4.ekf1.pos_test_ratio", "px4_estimator") == "PX4's own test of the position failed"
    assert plain_words("nis.gnss_position", "nis") is None  # a model group: "<group> inconsistent"
    alarm = AlarmInterval(20.0, 24.0, 19.0, 21.0, 2.0, 1.0, 2.0, "upper", 5, "health.gnss_fix", "health")
    assert headline(alarm, None, 20.0, 24.0).startswith("GNSS 3D fix lost 20.00-24.00 s (health.gnss_fix")


def test_model_based_alarms_are_reported_against_px4s_own_tests():
    """PX4's gps_hpos test fails at 20-30 s: a model-based alarm overlapping it counts as also
    flagged by PX4; PX4's heading alarm at 45 s is PX4's alone."""
    from logscan.alarms import AlarmInterval
    from logscan.pipeline.analysis import Analysis
    from logscan.results import DetectorResult

    def alarm(start, end, signal, detector):
        return AlarmInterval(start, end, start, start, 2.0, 1.0, 2.0, "upper", 3, signal, detector)

    px4 = DetectorResult("px4_estimator", info={"sources": {"px4.gps_hpos": "estimator_innovation_test_ratios_0"}})
    px4.alarms = [alarm(20.0, 30.0, "px4.gps_hpos", "px4_estimator"), alarm(45.0, 46.0, "px4.heading", "px4_estimator")]
    nis = DetectorResult("nis")
    nis.alarms = [alarm(29.5, 33.0, "nis.gnss_position", "nis"), alarm(50.0, 51.0, "nis.baro", "nis")]
    analysis = Analysis.__new__(Analysis)
    analysis.results = [px4, nis]
    assert analysis.against_baseline() == {
        "logscan_alarms": 2,
        "also_flagged_by_px4": 1,
        "px4_alarms": 2,
        "px4_alone": 1,
    }
    analysis.results = [nis]
    assert analysis.against_baseline() is None


def test_gnss_samples_count_only_with_a_3d_fix(cli, tmp_path):
    """The built-in px4 profile gates GNSS on fix_type >= 3: a SITL log with a 3D fix only in its
    last 1.5 s uses only those fixes (the origin too), says how long the gate was closed, and still
    counts as fully checked (none expected without a fix)."""
    path = need_testdata("px4-ulog/sample_logging_tagged_and_default_params.ulg")
    profile = parse_profile(builtin_profile_for(path).text)
    gnss = profile.measurements["gnss_position"]
    assert (gnss.gate_channel, gnss.gate_min) == ("/vehicle_gps_position_0/fix_type", 3.0)
    assert parse_profile(profile.to_toml()) == profile
    out = tmp_path / "s.json"
    assert cli("analyze", str(path), "--no-report", "--json", str(out), "--allow-partial").exit_code in (0, 1)
    entry = json.loads(out.read_text())["logs"][0]
    assert entry["filter"]["updates"]["gnss_position"] < 40  # ~30 fixes with fix_type 3 of ~190
    assert any("fix_type below 3" in w for w in entry["warnings"])
    # not a starved group; the log is not fully checked because it never flew (on the ground all log)
    assert not [u for u in entry["unchecked"] if "gnss" in u.lower()], entry["unchecked"]
    assert any("never says airborne" in u for u in entry["unchecked"])


@pytest.mark.testdata("px4-ulog")
@pytest.mark.testdata("ros-robots")
@pytest.mark.parametrize(
    ("log", "note"),
    [
        ("px4-ulog/sample_appended_multiple.ulg", "built-in profile px4: no GNSS topic"),
        ("ros-robots/robot_localization_test1_husky.bag", "built-in profile ros_wheeled: /fix altitude not checked"),
    ],
)
def test_the_profile_init_profile_writes_says_what_the_builtin_one_says(cli, tmp_path, log, note):
    """A built-in profile's notes (what it left out: a GNSS, the altitude) were comments in the
    file init-profile writes, so analysing with that file lost them from the verdict's lines."""
    path = need_testdata(log)
    written = tmp_path / "p.toml"
    assert cli("init-profile", path, "-o", written).exit_code == 0
    assert parse_profile(written.read_text()).notes and note in written.read_text()
    builtin = cli("analyze", path, "--no-report")
    from_file = cli("analyze", path, "--profile", written, "--no-report")
    assert f"  warning: {note}" in builtin.stdout
    # the same lines, but the commands they suggest, which name the file given
    assert from_file.stdout.replace(f" --profile {written}", "") == builtin.stdout
    assert from_file.exit_code == builtin.exit_code
