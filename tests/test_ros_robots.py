"""Real ROS robots out of the box (issue 26): the Husky drive of ../shared/testdata/ros-robots as a
ROS 2 MCAP, the original ROS 1 bag and a rosbag2 .db3 made from it here, analysed with no flags.

What the log itself says: robot_localization's regression-test drive, a healthy Clearpath Husky on a
campus for 395 s (README of the test data). Expected verdict: no alarm, on all three files alike, by
the built-in `ros_wheeled` profile (its odometry twist is planar: a ground robot). A copy of the bag
with the GNSS fix moved 10 m north for 30 s (tests/ros_edit.py) must alarm at the jump.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import need_testdata
from ros_edit import drop_topics, hold_fix, shift_fix, to_db3

from logscan.log import Channel, Log, SourceInfo, TopicInfo
from logscan.profiles import parse_profile, ros, ros_wheeled

ROS2_DIR = "ros-robots/robot_localization_test1_husky_ros2"
ROS2_MCAP = f"{ROS2_DIR}/robot_localization_test1_husky_ros2.mcap"
ROS1_BAG = "ros-robots/robot_localization_test1_husky.bag"
MAX_FALSE_ALARMS = 1  # the bound on the healthy drive


@pytest.fixture(scope="module")
def husky_db3(tmp_path_factory) -> Path:
    """The Husky ROS 1 bag converted to a rosbag2 .db3 (sqlite3 storage) by rosbags itself."""
    out = tmp_path_factory.mktemp("db3") / "husky_sqlite"
    to_db3(need_testdata(ROS1_BAG), out)
    return next(out.glob("*.db3"))


def summary(cli, path, tmp_path: Path, *args) -> tuple[int, dict, str]:
    out = tmp_path / f"{Path(path).name}.json"
    result = cli("analyze", path, "--no-report", "--json", out, *args)
    assert "Traceback" not in result.stderr, result.stderr
    return result.exit_code, json.loads(out.read_text())["logs"][0], result.stdout + result.stderr


def test_the_healthy_husky_drive_gets_the_same_verdict_from_mcap_bag_and_db3(cli, tmp_path, husky_db3):
    entries = {}
    for path in (need_testdata(ROS2_MCAP), need_testdata(ROS1_BAG), husky_db3):
        code, entry, text = summary(cli, path, tmp_path)
        assert code == 0, text
        entries[entry["log"]["format"]] = entry
    assert set(entries) == {"mcap", "ros1bag", "rosbag2"}
    for entry in entries.values():
        assert entry["profile_source"] == "built-in ros_wheeled" and entry["model"] == "wheeled"
        assert entry["n_alarms"] <= MAX_FALSE_ALARMS and entry["verdict"] == "no alarms"
        assert entry["filter"]["updates"]["position"] >= 980  # every 2.5 Hz fix of the 395 s drive
        assert entry["filter"]["divergence_episodes"] == 0
        # a mean NIS per output of at most 1: the filter is not overconfident on a healthy drive
        assert 0.05 <= entry["filter"]["mean_nis"]["position"] <= 2.0
    nis = {fmt: e["filter"]["mean_nis"]["position"] for fmt, e in entries.items()}
    assert max(nis.values()) - min(nis.values()) < 1e-6, nis  # the same samples, the same filter


def test_a_ten_metre_gnss_jump_on_the_real_drive_alarms_at_its_onset(cli, tmp_path):
    jumped = tmp_path / "jump.bag"
    moved = shift_fix(need_testdata(ROS1_BAG), jumped, "/fix", 200.0, 230.0, 10.0)
    assert moved > 70  # 2.5 Hz over 30 s
    code, entry, text = summary(cli, jumped, tmp_path)
    assert code == 1, text
    starts = [incident["start"] for incident in entry["incidents"]]
    assert any(199.5 <= s <= 202.0 for s in starts), starts  # within 2 s of the jump
    assert all(195.0 <= s <= 235.0 for s in starts), starts  # nothing anywhere else on the drive


def test_a_stuck_gnss_alarms_while_driving_but_its_static_hold_at_a_stop_does_not(cli, tmp_path):
    # the real drive stops from 236.8 s to 247 s, where the receiver holds its position exactly
    code, entry, text = summary(cli, need_testdata(ROS1_BAG), tmp_path, "-d", "frozen")
    assert code == 0 and entry["n_alarms"] == 0, text
    stuck = tmp_path / "stuck.bag"
    assert hold_fix(need_testdata(ROS1_BAG), stuck, "/fix", 100.0, 130.0) > 70
    code, entry, text = summary(cli, stuck, tmp_path, "-d", "frozen")
    assert code == 1, text
    starts = [incident["start"] for incident in entry["incidents"]]
    assert starts and all(100.0 <= s <= 110.0 for s in starts), starts


def test_the_ros_wheeled_profile_of_the_husky(tmp_path):
    from logscan.pipeline import builtin_profile_for

    built = builtin_profile_for(need_testdata(ROS1_BAG))
    assert built.name == "ros_wheeled" and built.model_not_run == ""
    profile = parse_profile(built.text)
    assert profile.vehicle.model == "wheeled" and profile.vehicle.rate_hz == 30
    # the IMU is mounted with y up (gravity says so), and its y rate agrees with the wheels'
    assert profile.inputs.mapping["w"] == {"channels": ["/imu/data/angular_velocity.y"], "scale": [1.0]}
    assert profile.inputs.mapping["v"] == "/husky_velocity_controller/odom/twist.twist.linear.x"
    position = profile.measurements["position"]
    assert (position.source, position.frame, position.noise_std) == ("geodetic", "en", [0.8, 0.8])
    # /fix reports position_covariance_type 1 (approximated): the wander is the GPS SPS standard's
    assert profile.vehicle.params["gnss_error_std"] == pytest.approx(ros_wheeled.GPS_SPS_SIGMA_M, rel=1e-2)
    assert any("altitude not checked" in note for note in built.notes)
    # the fix's status is the mode, its values named as sensor_msgs/NavSatStatus.msg names them
    assert profile.mode.channel == "/fix/status.status"
    assert profile.mode.labels == {-2.0: "UNKNOWN", -1.0: "NO_FIX", 0.0: "FIX", 1.0: "SBAS_FIX", 2.0: "GBAS_FIX"}


@pytest.mark.parametrize("folder", ["px4-ulog", "px4-ulog-extra", "ros-robots"])
def test_init_profile_on_every_real_log_writes_a_profile_analyze_accepts(cli, tmp_path, folder):
    logs = [p for p in sorted(need_testdata(folder).iterdir()) if p.suffix in (".ulg", ".bag") or p.is_dir()]
    assert logs
    for log in logs:
        written = tmp_path / f"{log.name}.toml"
        made = cli("init-profile", log, "-o", written)
        assert made.exit_code == 0, made.stderr
        parse_profile(written.read_text())  # valid as written
        result = cli("analyze", log, "--profile", written, "--no-report")
        assert "Traceback" not in result.stderr and "invalid profile" not in result.stderr, result.stderr
        assert result.exit_code in (0, 1, 2), result.stderr


# in-memory ROS logs for the profile's cases the Husky lacks


def ground_robot_log(
    *,
    imu: bool = True,
    fix: bool = True,
    covariance: float = 1e-3,
    fix_type: int = 1,
    imu_up: str = "z",
    odometry: bool = True,
) -> Log:
    channels: dict[str, Channel] = {}
    topics: dict[str, TopicInfo] = {}
    rng = np.random.default_rng(1)

    def topic(name: str, schema: str, hz: float, fields: dict[str, np.ndarray | float]):
        t = (np.arange(int(60 * hz)) * (1e9 / hz)).astype(np.int64)
        for f, value in fields.items():
            v = value(t) if callable(value) else np.full(t.size, value)
            channels[f"{name}/{f}"] = Channel(f"{name}/{f}", t, np.asarray(v, dtype=float))
        topics[name] = TopicInfo(name, t.size, "ros1", schema, int(t[0]), int(t[-1]))

    def yaw_rate(t):
        return 0.3 * np.sin(t / 1e9 / 5.0)

    if odometry:
        odom = {f"twist.twist.{c}": 0.0 for c in ("linear.y", "linear.z", "angular.x", "angular.y")}
        odom["twist.twist.linear.x"] = 1.0
        odom["twist.twist.angular.z"] = yaw_rate
        odom.update({f"twist.covariance[{i}]": covariance for i in range(36)})
        topic("/odom", "nav_msgs/msg/Odometry", 20.0, odom)
    else:
        command: dict = {c: 0.0 for c in ("linear.y", "linear.z", "angular.x", "angular.y")}
        command.update({"linear.x": 1.0, "angular.z": yaw_rate})
        topic("/cmd_vel", "geometry_msgs/msg/Twist", 10.0, command)
    if imu:
        fields: dict = {f"angular_velocity.{a}": 0.0 for a in "xyz"}
        fields.update({f"linear_acceleration.{a}": 0.0 for a in "xyz"})
        fields[f"linear_acceleration.{imu_up}"] = lambda t: 9.81 + 0.1 * rng.standard_normal(t.size)
        fields[f"angular_velocity.{imu_up}"] = yaw_rate
        fields.update({f"angular_velocity_covariance[{i}]": covariance for i in range(9)})
        topic("/imu", "sensor_msgs/msg/Imu", 30.0, fields)
    if fix:
        lla = {"latitude": 47.0, "longitude": 8.0, "altitude": 400.0, "position_covariance_type": fix_type}
        lla.update({f"position_covariance[{i}]": 4.0 for i in range(9)})
        topic("/fix", "sensor_msgs/msg/NavSatFix", 5.0, lla)
    return Log(channels, SourceInfo("robot.bag", "ros1bag", topics=topics))


def test_unknown_covariances_by_ros_conventions_give_defaults_and_say_so():
    from logscan.models import get_model

    for unknown in (-1.0, 0.0, 1e6):
        built = ros.ros_profile(ground_robot_log(covariance=unknown))
        params = parse_profile(built.text).vehicle.params
        assert params["speed_noise"] == get_model("wheeled").p["speed_noise"]
        assert "the model's default" in built.text
    known = parse_profile(ros.ros_profile(ground_robot_log(covariance=0.01)).text).vehicle.params
    assert known["speed_noise"] == pytest.approx(0.1)


def test_the_gyro_axis_follows_gravity_and_a_known_gnss_covariance_is_its_wander():
    built = ros.ros_profile(ground_robot_log(imu_up="x", fix_type=2))
    profile = parse_profile(built.text)
    assert profile.inputs.mapping["w"] == {"channels": ["/imu/angular_velocity.x"], "scale": [1.0]}
    assert profile.vehicle.params["gnss_error_std"] == pytest.approx(2.0)  # sqrt of the reported 4 m^2


def test_without_odometry_the_velocity_commands_drive_the_model():
    built = ros.ros_profile(ground_robot_log(odometry=False))
    profile = parse_profile(built.text)
    assert profile.vehicle.model == "wheeled" and profile.inputs.mapping["v"] == "/cmd_vel/linear.x"
    assert profile.inputs.stamp == "start"  # a command acts from its stamp on
    assert profile.inputs.mapping["w"] == {"channels": ["/imu/angular_velocity.z"], "scale": [1.0]}
    assert "wheel_yaw_rate" not in profile.measurements  # a command's yaw rate is no measurement
    commands_only = parse_profile(ros.ros_profile(ground_robot_log(odometry=False, imu=False)).text)
    assert commands_only.inputs.mapping["w"] == "/cmd_vel/angular.z"


def test_without_an_imu_the_odometrys_yaw_rate_drives_the_heading():
    profile = parse_profile(ros.ros_profile(ground_robot_log(imu=False)).text)
    assert profile.inputs.mapping["w"] == "/odom/twist.twist.angular.z"
    assert profile.vehicle.rate_hz == 20


def test_without_gnss_the_wheels_yaw_rate_is_checked_against_the_gyro(cli, tmp_path):
    no_fix = tmp_path / "no_fix.bag"
    drop_topics(need_testdata(ROS1_BAG), no_fix, ("/fix",))
    code, entry, text = summary(cli, no_fix, tmp_path)
    assert code == 0 and entry["n_alarms"] == 0, text
    assert set(entry["filter"]["updates"]) == {"wheel_yaw_rate"}
    assert "the wheels' speed and the position are not checked" in text


def test_a_ground_robot_with_nothing_to_check_gets_an_incomplete_profile_and_analyze_says_why(cli, tmp_path):
    built = ros.ros_profile(ground_robot_log(fix=False, imu=False))
    assert "nothing independent of the wheels" in built.model_not_run and "INCOMPLETE" in built.text
    wheels_only = tmp_path / "wheels_only.bag"
    drop_topics(need_testdata(ROS1_BAG), wheels_only, ("/fix", "/imu/data"))
    result = cli("analyze", wheels_only, "--no-report")
    assert result.exit_code == 2 and "nothing independent of the wheels" in result.stderr, result.stderr
    assert "init-profile" in result.stderr  # what to do
    written = tmp_path / "robot.toml"
    made = cli("init-profile", wheels_only, "-o", written)
    assert made.exit_code == 0 and "complete the profile" in made.stderr, made.stderr
    text = written.read_text()
    assert "INCOMPLETE" in text and 'model = "wheeled"' in text and "[measurements.position]" in text


def test_an_mcap_of_numeric_channels_without_a_profile_gets_a_starter_profile(cli, tmp_path):
    from logscan.readers.mcap.writer import TopicData, write_mcap

    rng = np.random.default_rng(3)
    t = (np.arange(6000) * 1e7).astype(np.int64)  # 60 s at 100 Hz
    speed = 10 + np.cumsum(rng.normal(0, 0.02, t.size)) + rng.normal(0, 0.1, t.size)
    path = tmp_path / "rover.mcap"
    write_mcap(path, {"/rover": TopicData("rover/State", t, {"speed": speed, "temp": 20 + 0 * speed})})
    written = tmp_path / "rover.toml"
    made = cli("init-profile", path, "-o", written)
    assert made.exit_code == 0, made.stderr
    profile = parse_profile(written.read_text())
    assert profile.vehicle.model == "linear" and "/rover/speed" in written.read_text()
    result = cli("analyze", path, "--profile", written, "--no-report")
    assert result.exit_code in (0, 1), result.stderr
    assert "observability verdict not computed" not in result.stdout + result.stderr  # a model with no input


def test_a_log_without_numeric_channels_says_there_is_nothing_to_profile(cli):
    conformance = need_testdata("mcap-conformance/TenMessages")
    path = next(conformance.glob("*.mcap"))
    result = cli("init-profile", path)
    assert result.exit_code == 2 and "holds no numeric channel" in result.stderr, result.stderr


def test_a_folder_of_bags_is_one_log_per_bag_and_per_rosbag2_directory(tmp_path):
    from logscan.fleet import expand_logs

    fleet = tmp_path / "drives"
    fleet.mkdir()
    (fleet / "monday.bag").symlink_to(need_testdata(ROS1_BAG))
    ros2 = fleet / "tuesday"
    ros2.mkdir()
    for piece in need_testdata(ROS2_DIR).iterdir():
        (ros2 / piece.name).symlink_to(piece)
    assert expand_logs([str(fleet)]) == [str(fleet / "monday.bag"), str(ros2)]
    assert expand_logs([str(ros2)]) == [str(ros2)]  # its .mcap is a piece of it, not a second log


@pytest.mark.parametrize("flip_from_s", [140.0, 300.0])
def test_an_odometry_yaw_rate_that_flips_sign_does_not_overrule_the_gyro(cli, tmp_path, flip_from_s):
    """The wheels' yaw rate sign-flipped from 140 s (most of the drive) or 300 s: the whole log's
    correlation with the gyro's up axis (-0.78, 0.06) fell under the minimum and the built-in profile
    dropped the healthy IMU, drove the heading with the faulty yaw rate and blamed the GNSS. The two
    agree before the flip: a change in the log, for the detectors, who now name the wheels."""
    from ros_edit import edit_messages

    flipped = tmp_path / "flipped.bag"

    def flip(msg, first):
        msg.twist.twist.angular.z = -msg.twist.twist.angular.z

    assert edit_messages(need_testdata(ROS1_BAG), flipped, "/husky_velocity_controller/odom", flip_from_s, 1e9, flip)
    code, entry, text = summary(cli, flipped, tmp_path)
    assert "/imu/data: its up axis disagrees" not in text
    assert "agree over" in text and "detectors judge the odometry" in text
    assert code == 1 and entry["incidents"], text
    first = entry["incidents"][0]
    assert first["source"] == "wheel_yaw_rate", first
    assert flip_from_s <= first["start"] <= flip_from_s + 20.0, first


def test_an_incident_while_the_gyro_is_missing_is_headed_by_the_missing_input(cli, tmp_path):
    """The real drive without /imu/data for 10 s from 150 s: the filter holds the gyro's last yaw
    rate, and the checks that then alarm judge that held value against the wheels and the GNSS. The
    incident named the healthy wheels ("wheel yaw rate inconsistent"); it names the missing input."""
    from ros_edit import drop_window

    dropped = drop_window(need_testdata(ROS1_BAG), tmp_path / "no_gyro.bag", "/imu/data", 150.0, 160.0)
    code, entry, text = summary(cli, dropped, tmp_path)
    during = [i for i in entry["incidents"] if 150.0 <= i["start"] <= 161.0]
    assert during, text
    assert all(i["source"] == "/imu/data/angular_velocity.y" for i in during), during
    assert all(i["headline"].startswith("model input /imu/data/angular_velocity.y missing for") for i in during)
    report = tmp_path / "no_gyro.html"
    cli("analyze", dropped, "-o", report)
    html = report.read_text()
    assert during[0]["headline"].split(" 2015-")[0] in html
    assert "the filter held its last value), then:" not in html  # no healthy sensor's size in the report


def test_a_frozen_fix_is_headed_by_its_freeze_not_by_its_thaw(cli, tmp_path):
    """The real drive's GNSS frozen from 150 s to 200 s: the stuck-sensor check alarms at once, and
    the position test alarms far higher when the fix jumps back at 200 s. The headline quoted that
    largest alarm, 48 s late ("position sensor inconsistent 19:14:58..."); it quotes the group's
    first checks: the freeze."""
    stuck = tmp_path / "stuck.bag"
    assert hold_fix(need_testdata(ROS1_BAG), stuck, "/fix", 150.0, 200.0) > 100
    code, entry, text = summary(cli, stuck, tmp_path)
    first = entry["incidents"][0]
    assert first["source"] == "position" and 150.0 <= first["start"] <= 160.0, first
    assert first["headline"].startswith("position sensor stuck"), first["headline"]
    assert "(frozen.position" in first["headline"], first["headline"]


def test_a_fix_whose_status_says_no_fix_is_not_checked_as_a_position(cli, tmp_path):
    """NavSatStatus.msg: STATUS_NO_FIX (-1) means the position is not a fix (drivers still fill one
    in). The real drive with status -1 and a position 500 m off for 20 s from 150 s: those samples
    are gated out (the built-in profile's gate on status.status >= 0), no alarm, and a warning says
    how long; they judged the filter as a 500 m jump before."""
    from ros_edit import edit_messages

    def no_fix(msg, first):
        msg.status.status = -1
        msg.latitude += 500.0 / 111_132.954

    edited = tmp_path / "no_fix.bag"
    assert edit_messages(need_testdata(ROS1_BAG), edited, "/fix", 150.0, 170.0, no_fix) > 40
    code, entry, text = summary(cli, edited, tmp_path)
    assert code == 0 and entry["n_alarms"] == 0, text
    assert "/fix/status.status below 0 for 20" in text, text
    code, entry, text = summary(cli, need_testdata(ROS1_BAG), tmp_path)
    assert "status.status below" not in text, text  # every real fix has status 1; before the first: not "no fix"


def test_a_gnss_that_stops_before_the_drive_ends_is_not_checked_after_it(cli, tmp_path):
    """/fix gone from 250 s of the 395 s drive: "no alarms" with a gap warning said the drive was
    judged; the position was not judged for its last 145 s: not fully checked, and says from when."""
    from ros_edit import drop_window

    dropped = drop_window(need_testdata(ROS1_BAG), tmp_path / "fix_stops.bag", "/fix", 250.0, 400.0)
    code, entry, text = summary(cli, dropped, tmp_path)
    assert code == 2, text
    lines = [u for u in entry["unchecked"] if u.startswith("measurement group 'position': no sample after 2")]
    assert lines and "its sensor stopped" in lines[0], entry["unchecked"]
    mid = drop_window(need_testdata(ROS1_BAG), tmp_path / "fix_gap.bag", "/fix", 150.0, 180.0)
    code, entry, text = summary(cli, mid, tmp_path)
    assert not [u for u in entry["unchecked"] if "position" in u], entry["unchecked"]  # a gap: warned, not stopped


def test_a_stuck_wheel_speed_is_named_not_the_gnss_it_made_look_frozen(cli, tmp_path):
    """The real drive's wheel speed held at its 150 s value until 250 s: the robot stops at 236.8 s
    while the wheels still say it moves, so the GNSS's static hold there read as a freeze and the
    incident said "position sensor stuck". The wheel speed decides when the robot is at rest
    (`Model.rest_inputs`): its own freeze is checked, from its onset, and heads the incident."""
    from ros_edit import edit_messages

    def hold_speed(msg, first):
        msg.twist.twist.linear.x = first.twist.twist.linear.x

    held = tmp_path / "speed_stuck.bag"
    assert edit_messages(need_testdata(ROS1_BAG), held, "/husky_velocity_controller/odom", 150.0, 250.0, hold_speed)
    code, entry, text = summary(cli, held, tmp_path)
    assert code == 1, text
    speed = "/husky_velocity_controller/odom/twist.twist.linear.x"
    stuck = [i for i in entry["incidents"] if i["source"] == speed]
    assert len(stuck) == 1 and 150.0 <= stuck[0]["start"] <= 152.0, entry["incidents"]
    assert stuck[0]["headline"].startswith(f"model input v ({speed}) stuck"), stuck[0]["headline"]
    assert "(frozen.input.v, peak" in stuck[0]["headline"]
    # the GNSS's hold at the stop is in the wheel speed's incident, not one of its own
    assert not any(i["headline"].startswith("position sensor stuck") for i in entry["incidents"]), text


def test_the_healthy_drives_wheel_speed_is_far_from_a_freeze(cli, tmp_path):
    """The real drive's wheel speed repeats one value only where it creeps at two encoder counts
    (5 samples of 2 mm/s as it stops, against its own 7 mm/s noise): that is stillness, not a
    freeze. Judged, it stood exactly at the check's threshold (5 of 5 samples); a drive of the
    same robot with one more such sample would have called its wheel speed stuck."""
    code, entry, text = summary(cli, need_testdata(ROS1_BAG), tmp_path, "-d", "frozen")
    assert code == 0, text
    frozen = next(d for d in entry["detectors"] if d["detector"] == "frozen")
    h = frozen["info"]["h"]["frozen.input.v"]
    peak = max(frozen["series"]["frozen.input.v"]["max"], 0.0)
    assert peak <= 0.5 * h, (peak, h)  # its moving samples repeat at most twice


def test_a_stuck_gyro_is_named_not_the_wheels_it_made_disagree(cli, tmp_path):
    """The real drive's /imu/data held at its 150 s message until 200 s: the gyro's yaw rate drives
    the heading (a model input), so the wheels' yaw rate and then the GNSS disagreed with it and the
    incident said "wheel yaw rate inconsistent", a healthy sensor. A sensor input is checked for a
    freeze as the wheel speed is (`Model.inputs_are_sensors`), and its freeze heads the incident."""
    from ros_edit import edit_messages

    def hold_imu(msg, first):
        msg.angular_velocity, msg.linear_acceleration = first.angular_velocity, first.linear_acceleration

    held = tmp_path / "gyro_stuck.bag"
    assert edit_messages(need_testdata(ROS1_BAG), held, "/imu/data", 150.0, 200.0, hold_imu) > 1000
    code, entry, text = summary(cli, held, tmp_path)
    assert code == 1, text
    first = entry["incidents"][0]
    assert first["source"].startswith("/imu/data/angular_velocity."), first
    assert 150.0 <= first["start"] <= 151.0 and first["headline"].startswith("model input w ("), first
    # the healthy drive's gyro repeats one reading at most twice: far below the check's threshold
    code, entry, text = summary(cli, need_testdata(ROS1_BAG), tmp_path, "-d", "frozen")
    frozen = next(d for d in entry["detectors"] if d["detector"] == "frozen")
    assert frozen["series"]["frozen.input.w"]["max"] <= 0.5 * frozen["info"]["h"]["frozen.input.w"], frozen["info"]


def test_a_wheel_speed_stuck_at_zero_while_driving_is_named_not_the_gnss(cli, tmp_path):
    """The real drive's wheel speed held at exactly 0 from 150 s to 170 s while the robot drives on
    at about 1 m/s: 0 said "at rest", so its exact repeats were stillness and the GNSS that kept
    moving (16 m) headed the incident ("position sensor inconsistent", a cusum alarm 12 s late).
    The gyro shakes as in driving and the GNSS moves past its noise and wander: both deny the rest
    (detectors/frozen_rest.py), so the held zero is judged and heads the incident. At the drive's
    real stop (236.6-246.3 s, its speed repeating 2.4e-15 m/s exactly) the gyro is quiet: rest."""
    from ros_edit import edit_messages

    def zero(msg, first):
        msg.twist.twist.linear.x = 0.0

    held = tmp_path / "speed_zero.bag"
    assert edit_messages(need_testdata(ROS1_BAG), held, "/husky_velocity_controller/odom", 150.0, 170.0, zero) > 150
    code, entry, text = summary(cli, held, tmp_path)
    assert code == 1, text
    speed = "/husky_velocity_controller/odom/twist.twist.linear.x"
    first = entry["incidents"][0]
    assert first["source"] == speed and 150.0 <= first["start"] <= 152.0, entry["incidents"]
    assert first["headline"].startswith(f"model input v ({speed}) stuck"), first["headline"]
    frozen = next(d for d in entry["detectors"] if d["detector"] == "frozen")
    (denied,) = frozen["info"]["rest_denied"]
    assert 149.9 <= denied[0] <= 150.2 and 169.8 <= denied[1] <= 170.1, denied
    code, entry, text = summary(cli, need_testdata(ROS1_BAG), tmp_path, "-d", "frozen")
    assert code == 0 and "rest_denied" not in entry["detectors"][0]["info"], text


def test_a_gnss_jump_while_the_robot_stands_does_not_deny_its_rest(cli, tmp_path):
    """The other side of the stuck-at-zero wheel speed: the real drive's fix moved 10 m north from
    238 s to 244 s, while the robot stands (236.6-246.3 s). The GNSS alone says it moved; the gyro is
    quiet, so the rest stands, the wheel speed's exact repeats there are stillness, and the
    incident is the GNSS's."""
    jumped = tmp_path / "jump_at_stop.bag"
    assert shift_fix(need_testdata(ROS1_BAG), jumped, "/fix", 238.0, 244.0, 10.0) > 10
    code, entry, text = summary(cli, jumped, tmp_path)
    assert code == 1 and entry["incidents"][0]["source"] == "position", entry["incidents"]
    frozen = next(d for d in entry["detectors"] if d["detector"] == "frozen")
    assert "rest_denied" not in frozen["info"], frozen["info"]["rest_denied"]
