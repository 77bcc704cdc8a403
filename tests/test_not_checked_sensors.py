"""Checks skipped for a sensor in the log that never gave a valid sample are said, never silent:
real PX4 logs edited so that the battery reports connected=0 all flight and the GNSS has no 3D fix
all flight name that check as `not checked` with its reason in the summary, the JSON and the
report (the log is then not fully checked, exit 2: docs/algorithms.md section 9.2); checks with
nothing to judge in a log are listed but leave the verdict as it is; "Every check ran" is said only
when it is true."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import need_testdata
from ulog_edit import edit_ulog

EVENTS = "px4-ulog/sample_px4_events.ulg"  # SITL quadcopter: battery connected, GNSS 3D fix in flight
APPENDED = "px4-ulog/sample_appended_multiple.ulg"  # no battery_status, no GNSS topic, never armed

pytestmark = pytest.mark.testdata("px4-ulog")


def _analyze(cli, path, tmp_path, *extra):
    summary, report = tmp_path / "summary.json", tmp_path / "report.html"
    result = cli("analyze", path, "-o", report, "--json", summary, *extra)
    assert "Traceback" not in result.stderr, result.stderr
    (log,) = json.loads(summary.read_text())["logs"]
    return result, log, report.read_text(encoding="utf-8")


def _health(log) -> dict:
    return next(d for d in log["detectors"] if d["detector"] == "health")


def _unmonitored_battery(data) -> None:
    data["connected"].fill(0)
    data["voltage_v"][:] = np.linspace(0.0, 0.13, data["voltage_v"].size)  # as a real unmonitored pack reads


def test_a_battery_with_connected_0_all_flight_is_named_not_checked_everywhere(cli, tmp_path):
    path = edit_ulog(need_testdata(EVENTS), tmp_path / "no_battery.ulg", {"battery_status": _unmonitored_battery})
    result, log, page = _analyze(cli, path, tmp_path)
    line = "battery not monitored: connected=0 all flight"
    assert f"not checked: health: {line}" in result.stdout
    assert any(line in u for u in log["unchecked"]), log["unchecked"]
    reason = next(u for u in log["unchecked"] if line in u).removeprefix("health: ")
    assert {"reason": reason, "partial": True} in _health(log)["not_checked"]
    assert "voltage 0.00-0.13 V" in result.stdout
    assert line in page and "Every check ran" not in page
    assert "not fully checked" in log["verdict"] and result.exit_code == 2
    # no battery statistic pretends to have judged it
    assert not any(name.startswith("health.battery") for name in _health(log)["series"])


def test_the_same_log_unedited_has_no_battery_or_gnss_line(cli, tmp_path):
    result, log, page = _analyze(cli, need_testdata(EVENTS), tmp_path)
    assert "battery not monitored" not in result.stdout and "no 3D fix all flight" not in result.stdout
    assert _health(log)["not_checked"] == [] and log["skipped_checks"] == []
    assert "health.battery" in _health(log)["series"] and "health.gnss_eph" in _health(log)["series"]


def test_a_gnss_without_3d_fix_all_flight_is_named_not_checked(cli, tmp_path):
    def no_fix(data):
        data["fix_type"].fill(2)

    path = edit_ulog(
        need_testdata(EVENTS), tmp_path / "no_fix.ulg", {"vehicle_gps_position": no_fix, "sensor_gps": no_fix}
    )
    result, log, page = _analyze(cli, path, tmp_path)
    line = "not checked: health: GNSS: no 3D fix all flight (vehicle_gps_position_0.fix_type at most 2)"
    assert line in result.stdout
    # the model's GNSS groups say it too, instead of "the filter used 0 of the ~0 updates"
    gated = [u for u in log["unchecked"] if "gate was closed all flight" in u]
    assert sorted(u.split("'")[1] for u in gated) == ["gnss_position", "gnss_velocity"], log["unchecked"]
    assert not any("of the ~0 updates" in u for u in log["unchecked"])
    assert "GNSS: no 3D fix all flight" in page and "Every check ran" not in page
    assert result.exit_code == 2
    assert not any(name.startswith(("health.gnss_eph", "health.gnss_epv")) for name in _health(log)["series"])


def test_a_window_before_the_first_3d_fix_quotes_the_fix_it_judged(cli, tmp_path):
    """0-3 s of the unedited log: fix_type 0 there (2 from 8.45 s, 3 from 9.18 s). The reason names
    the window and the best fix judged, not the whole log's 3."""
    result, log, _ = _analyze(cli, need_testdata(EVENTS), tmp_path, "--start", "-5", "--end", "3")
    line = "GNSS: no 3D fix over the window (vehicle_gps_position_0.fix_type at most 0 while judged)"
    assert f"not checked: health: {line}" in result.stdout
    assert f"health: {line}" in log["unchecked"], log["unchecked"]
    assert "at most 3" not in result.stdout and "all flight (vehicle_gps" not in result.stdout


def test_checks_with_nothing_to_judge_are_listed_and_leave_the_verdict(cli, tmp_path):
    result, log, page = _analyze(cli, need_testdata(APPENDED), tmp_path, "--allow-partial")
    skipped = log["skipped_checks"]
    assert "health: battery: no battery_status topic" in skipped, skipped
    assert "not checked (nothing to judge in this log): health: battery: no battery_status topic" in result.stdout
    assert "health: gnss: no vehicle_gps_position or sensor_gps topic" in skipped
    assert len(skipped) == len(set(skipped))  # one line per reason
    assert not any("battery" in u or "gnss" in u for u in log["unchecked"])
    assert "no battery_status topic" in page and "Every check ran" not in page


def test_checks_sharing_a_reason_are_one_line_naming_them():
    from logscan.detectors.raw_topics import skipped_lines

    reason = "actuator_outputs_0: no sample to judge on the analysis grid (armed)"
    skipped = {f"health.motor_max.{k}": reason for k in range(1, 9)} | {"health.imu_clipping": "no sensor_combined"}
    assert skipped_lines(skipped, "health") == [
        f"motor_max.1, motor_max.2 and 6 more: {reason}",
        "imu_clipping: no sensor_combined",
    ]
    assert skipped_lines({"health.a": "r", "health.b": "r"}, "health") == ["a, b: r"]


def test_a_log_never_armed_says_so_for_the_while_armed_checks(cli, tmp_path):
    path = need_testdata("px4-ulog/sample_logging_tagged_and_default_params.ulg")  # SITL on the ground, never armed
    result, log, page = _analyze(cli, path, tmp_path)
    gnss = [s for s in log["skipped_checks"] if s.startswith("health: gnss_fix")]
    assert len(gnss) == 1, log["skipped_checks"]  # the while-armed GNSS checks in one line
    assert gnss[0].endswith("vehicle_gps_position_0: never armed in the log")
    assert "no sample to judge" not in " ".join(log["skipped_checks"])
