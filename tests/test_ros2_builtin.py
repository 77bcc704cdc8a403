"""ROS 2 logs: the generator of a ROS 2 MCAP from an `ins` simulation (logscan/simulate/ros2_export.py)
and the built-in `ros` profile (logscan/profiles/ros.py) a ROS 2 MCAP without a profile gets:
topics picked by message type, ROS frames converted (Task A's transforms), noise from covariances.

sample_logs/ros2_ins.mcap is analysed with no flags: every group updates, its mean NIS per output
is near 1 (no consistency warning); a variant with +1 m/s^2 on the IMU's x acceleration alarms.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from logscan.conversions import geodetic_to_local, quaternion_enu_flu_to_ned_frd, quaternion_to_euler
from logscan.log import Channel, Log, SourceInfo, TopicInfo
from logscan.pipeline import builtin_profile_for, consistency_warnings, load_profile_for
from logscan.profiles import builtin, parse_profile, ros
from logscan.readers import read_log
from logscan.simulate import ros2_export, simulate
from logscan.simulate.ros2_export import ORIGIN, local_to_geodetic, ros_quaternion, write_ros2_mcap, write_sample

SAMPLE = "ros2_ins.mcap"
GROUPS = {"gnss_position": 3, "odometry": 3, "attitude": 3}


@pytest.fixture(scope="module")
def short_sim():
    return simulate("ins", [], duration=6.0, seed=5)


# ------------------------------------------------------------------------------------------------
# The generator
# ------------------------------------------------------------------------------------------------


def test_local_to_geodetic_inverts_geodetic_to_local():
    ned = np.array([[0.0, 0.0, 0.0], [12.5, -8.0, -10.0], [-1000.0, 2500.0, 30.0]])
    lla = local_to_geodetic(ned, ORIGIN)
    np.testing.assert_allclose(lla[0], ORIGIN, atol=1e-9)
    np.testing.assert_allclose(geodetic_to_local(lla, ORIGIN), ned, atol=1e-6)


def test_ros_quaternion_is_the_enu_flu_orientation_of_an_ned_attitude():
    euler = np.array([[0.1, -0.2, 0.3], [0.0, 0.0, 0.0], [-0.4, 0.3, -2.9]])
    q = ros_quaternion(euler)
    np.testing.assert_allclose(quaternion_to_euler(quaternion_enu_flu_to_ned_frd(q)), euler, atol=1e-12)
    # a level body facing north (NED yaw 0) faces ENU yaw +90 deg
    np.testing.assert_allclose(np.abs(q[1]), [math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)], atol=1e-12)


def test_the_mcap_holds_the_standard_topics_in_ros_frames(short_sim, tmp_path):
    path = write_ros2_mcap(short_sim, tmp_path / "r.mcap")
    log = read_log(path)
    topics = {name: (t.encoding, t.schema, t.message_count) for name, t in log.source.topics.items()}
    n = short_sim.n_steps
    assert topics == {
        "/imu/data": ("cdr", "sensor_msgs/msg/Imu", n),
        "/gps/fix": ("cdr", "sensor_msgs/msg/NavSatFix", len(range(0, n, 25))),
        "/odom": ("cdr", "nav_msgs/msg/Odometry", len(range(0, n, 5))),
    }
    # the IMU in FLU: y and z of the logged FRD IMU negated; 250 Hz stamps = log times
    u = short_sim.u_cmd
    for j, (field, sign) in enumerate([("x", 1), ("y", -1), ("z", -1)]):
        np.testing.assert_array_equal(log.channels[f"/imu/data/angular_velocity.{field}"].values, sign * u[:, j])
        np.testing.assert_array_equal(log.channels[f"/imu/data/linear_acceleration.{field}"].values, sign * u[:, 3 + j])
    imu_t = log.channels["/imu/data/angular_velocity.x"].t
    np.testing.assert_array_equal(np.diff(imu_t), 4_000_000)
    stamps = log.channels["/imu/data/header.stamp.sec"].values.astype(np.int64) * 1_000_000_000 + log.channels[
        "/imu/data/header.stamp.nanosec"
    ].values.astype(np.int64)
    np.testing.assert_array_equal(stamps, imu_t)
    # the IMU's orientation is the true attitude
    q = np.column_stack([log.channels[f"/imu/data/orientation.{c}"].values for c in "wxyz"])
    euler = quaternion_to_euler(quaternion_enu_flu_to_ned_frd(q))
    np.testing.assert_allclose(euler, short_sim.x_true[:, 6:9], atol=1e-9)
    # the fixes are the simulated NED positions about the origin
    lla = np.column_stack([log.channels[f"/gps/fix/{f}"].values for f in ("latitude", "longitude", "altitude")])
    cols = short_sim.group_slices()["gnss_position"]
    np.testing.assert_allclose(geodetic_to_local(lla, ORIGIN), short_sim.z[::25, cols], atol=1e-6)
    assert log.channels["/gps/fix/position_covariance[8]"].values[0] == pytest.approx(1.0)  # up: (1 m)^2
    # the odometry's body velocity in FLU: forward along the NED velocity's heading
    assert log.channels["/odom/twist.covariance[0]"].values[0] == pytest.approx(0.01)
    # the embedded truth names the ROS channels
    assert log.truth["imu_topic"] == "/imu/data" and log.truth["events"] == []
    assert log.profile_text is None


def test_the_same_simulation_gives_the_same_bytes(short_sim, tmp_path):
    a = write_ros2_mcap(short_sim, tmp_path / "a.mcap")
    b = write_ros2_mcap(short_sim, tmp_path / "b.mcap")
    assert a.read_bytes() == b.read_bytes()
    assert not list(tmp_path.glob("*.tmp"))


def test_only_the_ins_model_is_exported(tmp_path):
    with pytest.raises(ValueError, match="ins model"):
        write_ros2_mcap(simulate("quadcopter", [], duration=1.0, seed=1), tmp_path / "q.mcap")


# ------------------------------------------------------------------------------------------------
# Identification and the built-in profile
# ------------------------------------------------------------------------------------------------


def test_identify_tells_a_ros2_mcap_from_logscans_own(sample):
    assert builtin.identify(read_log(sample(SAMPLE), topics=())) == "ros"
    assert builtin.identify(read_log(sample("quad_healthy.mcap"), topics=())) is None
    assert builtin_profile_for(sample("quad_healthy.mcap")) is None
    assert ros.is_ros_topic("cdr", "sensor_msgs/msg/Imu") and ros.is_ros_topic("ros1", "sensor_msgs/msg/Imu")
    assert not ros.is_ros_topic("json", "sensor_msgs/msg/Imu")
    assert not ros.is_ros_topic("cdr", "logscan/Imu")


def test_the_topic_list_comes_from_the_summary_and_only_candidates_are_read(sample, monkeypatch):
    import importlib

    # builtin_profile_for reads through this module's read_log (the package's `prepare` is a function)
    prepare = importlib.import_module("logscan.pipeline.preparation")

    schemas = builtin.topic_schemas(sample(SAMPLE), "mcap")
    assert schemas == {
        "/imu/data": ("cdr", "sensor_msgs/msg/Imu"),
        "/gps/fix": ("cdr", "sensor_msgs/msg/NavSatFix"),
        "/odom": ("cdr", "nav_msgs/msg/Odometry"),
    }
    asked = []
    real = prepare.read_log

    def spy(path, topics=None, **kwargs):
        asked.append(None if topics is None else sorted(topics))
        return real(path, topics, **kwargs)

    monkeypatch.setattr(prepare, "read_log", spy)
    monkeypatch.setattr(builtin, "read_log", spy)  # and the topic list: never from a read
    built = builtin_profile_for(sample(SAMPLE))
    assert built.name == "ros" and asked == [["/gps/fix", "/imu/data", "/odom"]]


def test_the_ros2_profile_of_the_sample(sample):
    built = builtin_profile_for(sample(SAMPLE))
    assert built.name == "ros" and built.notes == []
    profile = parse_profile(built.text)
    assert profile.vehicle.model == "ins" and profile.vehicle.rate_hz == 250
    assert profile.vehicle.params == {"gyro_noise": 0.015, "accel_noise": 0.35}
    assert profile.inputs.mapping["gyro"] == {
        "channels": ["/imu/data/angular_velocity.x", "/imu/data/angular_velocity.y", "/imu/data/angular_velocity.z"],
        "frame": "flu",
    }
    assert profile.inputs.factors == [1.0, -1.0, -1.0] * 2
    assert set(profile.measurements) == set(GROUPS)
    gnss, odom, att = (profile.measurements[g] for g in ("gnss_position", "odometry", "attitude"))
    assert (gnss.source, gnss.frame, gnss.noise_std, gnss.rate_hz) == ("geodetic", "ned", [0.5, 0.5, 1.0], 10)
    assert (odom.source, odom.frame, odom.noise_std, odom.rate_hz) == (None, "flu", [0.1, 0.1, 0.1], 50)
    assert odom.channels[0] == "/odom/twist.twist.linear.x"
    assert (att.source, att.frame, att.noise_std) == ("quaternion", "enu_flu", [0.02, 0.02, 0.02])
    assert att.channels == [f"/odom/pose.pose.orientation.{c}" for c in "wxyz"]
    # what `analyze` uses without --profile
    loaded = load_profile_for(sample(SAMPLE), None)
    assert loaded.source == "built-in ros" and loaded.profile == profile


def test_topics_are_picked_by_message_type_not_by_name(short_sim, tmp_path, monkeypatch):
    monkeypatch.setattr(ros2_export, "IMU_TOPIC", "/sensors/xsens")
    monkeypatch.setattr(ros2_export, "GNSS_TOPIC", "/ublox/navsat")
    monkeypatch.setattr(ros2_export, "ODOM_TOPIC", "/vio/odometry")
    path = write_ros2_mcap(short_sim, tmp_path / "renamed.mcap")
    profile = parse_profile(builtin_profile_for(path).text)
    assert profile.inputs.channels[0] == "/sensors/xsens/angular_velocity.x"
    assert profile.measurements["gnss_position"].channels[0] == "/ublox/navsat/latitude"
    assert profile.measurements["odometry"].channels[0] == "/vio/odometry/twist.twist.linear.x"


# in-memory ROS 2 logs for the profile's edge cases


def ros_log(imu_hz: float = 100.0, *, covariance: float = 0.0, with_odom: bool = True, with_fix: bool = True) -> Log:
    channels: dict[str, Channel] = {}
    topics: dict[str, TopicInfo] = {}

    def topic(name: str, schema: str, hz: float, fields: dict[str, float]):
        t = (np.arange(int(2 * hz)) * (1e9 / hz)).astype(np.int64)
        for f, value in fields.items():
            channels[f"{name}/{f}"] = Channel(f"{name}/{f}", t, np.full(t.size, value))
        topics[name] = TopicInfo(name, t.size, "cdr", schema, int(t[0]), int(t[-1]))

    imu = {f"{v}.{a}": 0.0 for v in ("angular_velocity", "linear_acceleration") for a in "xyz"}
    imu.update({f"angular_velocity_covariance[{i}]": covariance for i in range(9)})
    topic("/imu", "sensor_msgs/msg/Imu", imu_hz, imu)
    if with_fix:
        fix = {"latitude": 47.0, "longitude": 8.0, "altitude": 400.0}
        fix.update({f"position_covariance[{i}]": covariance for i in range(9)})
        topic("/fix", "sensor_msgs/msg/NavSatFix", 5.0, fix)
    if with_odom:
        odom = {f"twist.twist.linear.{a}": 0.0 for a in "xyz"}
        odom.update({f"pose.pose.orientation.{c}": float(c == "w") for c in "wxyz"})
        topic("/odom", "nav_msgs/msg/Odometry", 20.0, odom)
    return Log(channels, SourceInfo("ros.mcap", "mcap", topics=topics))


def test_zero_covariances_give_the_models_defaults():
    from logscan.models import get_model

    model = get_model("ins", {})
    built = ros.ros_profile(ros_log())
    profile = parse_profile(built.text)
    assert profile.vehicle.params == {"gyro_noise": model.p["gyro_noise"], "accel_noise": model.p["accel_noise"]}
    assert profile.measurements["gnss_position"].noise_std == list(model.groups["gnss_position"].noise_std)
    assert profile.measurements["odometry"].noise_std == list(model.groups["odometry"].noise_std)
    assert "the model's defaults" in built.text and "rate_hz = 100" in built.text


def test_missing_optional_topics_are_noted_and_an_imu_alone_is_not_run():
    built = ros.ros_profile(ros_log(with_odom=False))
    assert set(parse_profile(built.text).measurements) == {"gnss_position"}
    assert len(built.notes) == 2 and all("nav_msgs/msg/Odometry" in n for n in built.notes)
    alone = ros.ros_profile(ros_log(with_odom=False, with_fix=False))
    assert "nothing to check it against" in alone.model_not_run and "INCOMPLETE" in alone.text


def test_a_slow_imu_is_noted_one_too_slow_or_none_is_not_run():
    built = ros.ros_profile(ros_log(imu_hz=20.0))
    assert built.model_not_run == "" and parse_profile(built.text).vehicle.rate_hz == 20
    assert any("/imu is logged at 20 Hz, below the ins model's 50 Hz" in note for note in built.notes)
    assert "/imu is logged at 10 Hz" in ros.ros_profile(ros_log(imu_hz=10.0)).model_not_run
    log = ros_log()
    log.source.topics.pop("/imu")
    assert "no sensor_msgs/msg/Imu topic" in ros.ros_profile(log).model_not_run


# ------------------------------------------------------------------------------------------------
# Analysis end to end
# ------------------------------------------------------------------------------------------------


def test_the_sample_is_analysed_with_no_flags_and_its_filter_is_consistent(cli, sample, tmp_path):
    out = tmp_path / "summary.json"
    result = cli("analyze", sample(SAMPLE), "--no-report", "--json", out)
    assert result.exit_code in (0, 1), result.stdout + result.stderr
    entry = json.loads(out.read_text())["logs"][0]
    assert entry["model"] == "ins" and entry["profile_source"] == "built-in ros"
    f = entry["filter"]
    assert set(f["updates"]) == set(GROUPS) and min(f["updates"].values()) >= 300
    for group, size in GROUPS.items():
        assert 0.3 * size <= f["mean_nis"][group] <= 3.0 * size, (group, f["mean_nis"])
    assert f["divergence_episodes"] == 0
    assert not [w for w in entry["warnings"] if "mean NIS per output" in w]


def test_consistency_warnings_stay_silent_on_the_sample(sample):
    from logscan.pipeline import create_detectors, needs_of, prepare

    loaded = load_profile_for(sample(SAMPLE), None)
    prepared = prepare(sample(SAMPLE), loaded, needs_of(create_detectors(loaded)))
    assert consistency_warnings(prepared) == []


def test_init_profile_prints_the_ros_profile(cli, sample):
    result = cli("init-profile", sample(SAMPLE))
    assert result.exit_code == 0, result.stderr
    assert result.stdout.startswith("# logscan built-in profile `ros`")
    profile = parse_profile(result.stdout)
    assert profile.measurements["attitude"].frame == "enu_flu"


def test_an_accelerometer_bias_on_the_ros2_imu_alarms(cli, tmp_path):
    path = write_sample(tmp_path / "ros2_bias.mcap", ["imu-bias:accel.x:15:25:1.0"])
    out = tmp_path / "summary.json"
    result = cli("analyze", path, "--no-report", "--json", out)
    assert result.exit_code == 1, result.stdout + result.stderr
    entry = json.loads(out.read_text())["logs"][0]
    assert entry["profile_source"] == "built-in ros"
    assert entry["scores"]["nis"]["tp"] == 1 and entry["scores"]["nis"]["fp"] == 0
