"""The real-flight regression corpus: every real log in ../shared/testdata with the verdict that the
log itself calls for, written down from what the autopilot logged (its messages, failsafes, land
detector and parameters), not from what logscan happened to print.

- px4-ulog/sample_appended_multiple: never armed, on the ground all log ("Not ready to fly: Sensors
  not set up correctly"): no alarm.
- px4-ulog/sample_log_small: CubeOrange VTOL, a 1.2 s hop (take-off 2.4 s, landing 3.5 s), disarmed
  by landing, no warning; its GNSS over EKF2_REQ_EPV but PX4's own checks pass every 2 s: no alarm.
- px4-ulog/sample_logging_tagged_and_default_params: SITL quadcopter on the ground, never armed:
  no alarm.
- px4-ulog/sample_px4_events: SITL quadcopter, take-off, RTL, landing, disarmed; only "GPS fix too
  low" before arming: no alarm.
- px4-ulog-extra/mcap_ulog2mcap_test_ulog: FMU-v6C armed by RC, a 2 s hop, disarmed by landing, no
  warning: no alarm.
- px4-ulog-extra/robologs_fmu_v5_test: ERROR "Dangerous battery level!, please land!" (4S at
  12.9-14.1 V, BAT1_V_EMPTY 3.5 V a cell), "primary EKF changed (filter fault)" in flight: an alarm
  on the battery with the ERROR listed (exit 1, or 2 with its flight unjudged by the model).
- ros-robots/robot_localization_test1_husky.bag: a healthy Husky drive (robot_localization's
  reference run) as a ROS 1 bag: one clear line and exit 2 until ROS 1 bags are read (issue 26).
- ros-robots/robot_localization_test1_husky_ros2: the same drive as a ROS 2 bag: no alarm, never a
  traceback (exit 0 or 2).

"No alarm" on a log that was not judged enough is not a pass: a log that exits 0 must have no
`not checked` line; one that exits 2 must say why. The false-alarm budget (at most 1 per flight-hour
over the real airborne time: under a minute here, so none at all) is checked over the healthy flights.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np
import pytest
from conftest import need_testdata


@dataclass(frozen=True)
class Expected:
    """A real log's expected verdict."""

    path: str
    exit_codes: tuple[int, ...]
    healthy: bool = True
    # substrings of which at least one must appear in an alarm's check name (an unhealthy log)
    alarm_on: tuple[str, ...] = ()
    # substrings that must appear in the summary's printed lines (messages the autopilot logged)
    printed: tuple[str, ...] = ()
    notes: dict = field(default_factory=dict)


CORPUS = [
    Expected("px4-ulog/sample_appended_multiple.ulg", (0, 2)),
    Expected("px4-ulog/sample_log_small.ulg", (0, 2)),
    Expected("px4-ulog/sample_logging_tagged_and_default_params.ulg", (0, 2)),
    Expected("px4-ulog/sample_px4_events.ulg", (0, 2)),
    Expected("px4-ulog-extra/mcap_ulog2mcap_test_ulog.ulg", (0, 2)),
    Expected(
        "px4-ulog-extra/robologs_fmu_v5_test.ulg",
        (1, 2),
        healthy=False,
        alarm_on=("battery",),
        printed=("Dangerous battery level",),
    ),
]


def _airborne_s(path) -> float:
    """Seconds PX4's land detector says the vehicle was in the air (landed == 0 spans)."""
    from pyulog import ULog

    ulog = ULog(str(path), ["vehicle_land_detected"])
    topics = [d for d in ulog.data_list if d.name == "vehicle_land_detected"]
    if not topics:
        return 0.0
    data = topics[0].data
    t_s = data["timestamp"] / 1e6
    landed = data["landed"].astype(bool)
    end_s = ulog.last_timestamp / 1e6
    ends = np.append(t_s[1:], end_s)
    return float(np.sum((ends - t_s)[~landed]))


def _alarm_checks(log: dict) -> list[str]:
    return [check for incident in log["incidents"] for check in incident["checks"]]


def _analyze(cli, path, tmp_path) -> tuple[int, str, dict]:
    summary = tmp_path / "summary.json"
    result = cli("analyze", path, "-o", tmp_path / "report.html", "--json", summary)
    assert "Traceback" not in result.stderr, result.stderr
    assert result.exit_code in (0, 1, 2), (result.exit_code, result.stderr)
    return result.exit_code, result.stdout + result.stderr, json.loads(summary.read_text())


@pytest.mark.parametrize("case", CORPUS, ids=[c.path.split("/")[-1] for c in CORPUS])
def test_real_log_gets_the_verdict_the_log_itself_calls_for(case, cli, tmp_path):
    path = need_testdata(case.path)
    code, printed, summary = _analyze(cli, path, tmp_path)
    (log,) = summary["logs"]
    assert code in case.exit_codes, f"{case.path}: exit {code}, expected {case.exit_codes}\n{printed}"
    if case.healthy:
        assert log["n_alarms"] == 0, f"{case.path}: false alarms {_alarm_checks(log)}\n{printed}"
    else:
        checks = _alarm_checks(log)
        assert any(word in check for check in checks for word in case.alarm_on), (checks, printed)
    if code == 0:
        # "no alarms" is a promise that the log was judged: nothing may be left unchecked
        assert not log["unchecked"], f"{case.path}: exit 0 with unchecked {log['unchecked']}"
        assert "not checked:" not in printed
    if code == 2:
        # too little judged: the summary says what and why
        assert log["unchecked"] or "not checked:" in printed, printed
    for text in case.printed:
        assert text in printed, f"{case.path}: {text!r} not in the summary\n{printed}"


def test_no_false_alarm_over_the_real_airborne_time(cli, tmp_path):
    """At most 1 false alarm per flight-hour over every healthy real flight's airborne time (PX4's
    own land detector says how long): with under a minute of flight here, that is none."""
    airborne_s = 0.0
    false_alarms = 0
    for n, case in enumerate(c for c in CORPUS if c.healthy):
        path = need_testdata(case.path)
        airborne_s += _airborne_s(path)
        out = tmp_path / str(n)
        out.mkdir()
        _, _, summary = _analyze(cli, path, out)
        false_alarms += summary["logs"][0]["n_alarms"]
    assert airborne_s > 10.0  # the corpus flies: a land detector that never said "airborne" is a bug here
    budget = int(np.floor(airborne_s / 3600.0 * 1.0))
    assert false_alarms <= budget, f"{false_alarms} false alarms in {airborne_s:.0f} s of real flight"


def test_ros1_bag_is_one_clear_line_and_exit_2(cli):
    path = need_testdata("ros-robots/robot_localization_test1_husky.bag")
    result = cli("analyze", path, "--no-report")
    assert "Traceback" not in result.stderr
    if result.exit_code == 2:
        assert "robot_localization_test1_husky.bag" in result.stderr
        assert len([line for line in result.stderr.splitlines() if line.startswith("logscan: error")]) == 1
    else:
        # once ROS 1 bags are read (issue 26), a healthy drive has no alarm
        assert result.exit_code == 0, result.stdout + result.stderr


def test_ros2_bag_of_a_healthy_drive_has_no_alarm(cli, tmp_path):
    path = need_testdata("ros-robots/robot_localization_test1_husky_ros2")
    result = cli("analyze", path, "-o", tmp_path / "r.html")
    assert "Traceback" not in result.stderr
    assert result.exit_code in (0, 2), result.stdout + result.stderr
    assert "alarm" not in result.stdout.split("\n")[0].replace("no alarms", "")


def test_a_gnss_gate_closed_for_a_few_steps_says_how_long(cli, tmp_path):
    """sample_log_small's GNSS holds no sample for its first few grid steps (before its first fix
    message): that is silence, not "no 3D fix", and no gate warning says so. With its first fix
    edited to fix_type 2, the gate is closed until the next: the warning gives its duration, not
    "for 0.0 s"."""
    from ulog_edit import edit_ulog

    def first_not_3d(data):
        data["fix_type"][0] = 2

    path = need_testdata("px4-ulog/sample_log_small.ulg")
    edited = edit_ulog(path, tmp_path / "first_2d.ulg", {"vehicle_gps_position": first_not_3d})
    for log, closed in ((path, False), (edited, True)):
        out = tmp_path / "s.json"
        cli("analyze", log, "--no-report", "-q", "--allow-partial", "--json", out)
        warnings = json.loads(out.read_text())["logs"][0]["warnings"]
        gated = [w for w in warnings if "fix_type below 3" in w]
        assert bool(gated) == closed, warnings
        assert not any(" for 0.0 s " in w for w in gated)
        assert all(float(w.split(" for ")[1].split(" s ")[0]) > 0 for w in gated)
