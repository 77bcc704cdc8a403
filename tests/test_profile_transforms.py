"""Channel transforms of profiles: `offset`, `frame` of 3-vector groups ("flu", "enu"), `frame =
"enu_flu"` of quaternion groups, and the inline-table form of `[inputs]` (frame, scale, offset):
their maths (logscan/conversions.py), validation, TOML round trip and alignment onto the grid."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.align import align
from logscan.conversions import (
    Q_ENU_TO_NED,
    Q_FLU_TO_FRD,
    enu_to_ned,
    euler_matrix,
    euler_to_quaternion,
    flu_to_frd,
    quaternion_enu_flu_to_ned_frd,
    quaternion_matrix,
    quaternion_multiply,
    quaternion_to_euler,
    vector_to_frd_ned,
)
from logscan.errors import ProfileError
from logscan.log import Channel, Log, SourceInfo
from logscan.profiles import parse_profile

MS = 1_000_000
T = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # ENU -> NED
B = np.diag([1.0, -1.0, -1.0])  # FRD <-> FLU


# ------------------------------------------------------------------------------------------------
# Maths
# ------------------------------------------------------------------------------------------------


def test_flu_to_frd_negates_y_and_z():
    np.testing.assert_array_equal(flu_to_frd([[1.0, 2.0, 3.0]]), [[1.0, -2.0, -3.0]])


def test_enu_to_ned_swaps_x_y_and_negates_z():
    np.testing.assert_array_equal(
        enu_to_ned([[1.0, 2.0, 3.0], [0.0, -1.0, np.nan]]), [[2.0, 1.0, -3.0], [-1, 0, np.nan]]
    )


def test_identity_frames_copy():
    v = np.array([[1.0, 2.0, 3.0]])
    out = vector_to_frd_ned(v, "frd")
    np.testing.assert_array_equal(out, v)
    assert out is not v
    np.testing.assert_array_equal(vector_to_frd_ned(v, "ned"), v)
    with pytest.raises(ValueError):
        vector_to_frd_ned(v, "nwu")


def test_the_fixed_rotations_are_t_and_b():
    np.testing.assert_allclose(quaternion_matrix(Q_ENU_TO_NED)[0], T, atol=1e-15)
    np.testing.assert_allclose(quaternion_matrix(Q_FLU_TO_FRD)[0], B, atol=1e-15)


def test_quaternion_product_is_the_rotation_product():
    a = euler_to_quaternion([[0.3, -0.2, 1.0]])
    b = euler_to_quaternion([[-1.1, 0.4, -2.0]])
    np.testing.assert_allclose(
        quaternion_matrix(quaternion_multiply(a, b))[0], quaternion_matrix(a)[0] @ quaternion_matrix(b)[0], atol=1e-12
    )


def test_ros_identity_orientation_is_facing_east():
    # a ROS body at the identity faces east (x forward = east) and is level: NED yaw +90 deg
    euler = quaternion_to_euler(quaternion_enu_flu_to_ned_frd([[1.0, 0.0, 0.0, 0.0]]))[0]
    np.testing.assert_allclose(euler, [0.0, 0.0, math.pi / 2], atol=1e-12)


def test_ros_yaw_90_deg_is_facing_north():
    # ENU yaw +90 deg (counter-clockwise from east) is north: NED yaw 0
    q = np.array([[math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)]])
    np.testing.assert_allclose(quaternion_to_euler(quaternion_enu_flu_to_ned_frd(q))[0], 0.0, atol=1e-12)


def test_ros_nose_up_is_positive_pitch():
    # FLU pitch is about +y (left): nose up is a negative rotation about y; FRD pitch nose up is positive
    angle = 0.3
    q = np.array([[math.cos(-angle / 2), 0.0, math.sin(-angle / 2), 0.0]])
    roll, pitch, _ = quaternion_to_euler(quaternion_enu_flu_to_ned_frd(q))[0]
    assert pitch == pytest.approx(angle) and roll == pytest.approx(0.0, abs=1e-12)


unit_quaternions = st.lists(st.floats(-1.0, 1.0, allow_nan=False), min_size=4, max_size=4).filter(
    lambda v: 0.1 < math.sqrt(sum(x * x for x in v))
)


@settings(max_examples=200, deadline=None)
@given(unit_quaternions)
def test_enu_flu_conversion_is_t_r_b_and_keeps_the_norm(raw):
    q = np.array([raw])
    out = quaternion_enu_flu_to_ned_frd(q)
    np.testing.assert_allclose(np.linalg.norm(out), np.linalg.norm(q), rtol=1e-12)
    np.testing.assert_allclose(quaternion_matrix(out)[0], T @ quaternion_matrix(q)[0] @ B, atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(st.floats(-1.4, 1.4), st.floats(-1.4, 1.4), st.floats(-3.1, 3.1))
def test_an_ned_attitude_written_as_a_ros_orientation_comes_back(roll, pitch, yaw):
    r_ned_frd = euler_matrix([[roll, pitch, yaw]])[0]
    r_enu_flu = T @ r_ned_frd @ B  # T and B are their own inverses
    # the ROS quaternion of R_enu_flu: its matrix's Euler angles, back to a quaternion
    q_ros = euler_to_quaternion(_matrix_euler(r_enu_flu))
    np.testing.assert_allclose(quaternion_matrix(q_ros)[0], r_enu_flu, atol=1e-9)
    euler = quaternion_to_euler(quaternion_enu_flu_to_ned_frd(q_ros))[0]
    np.testing.assert_allclose(euler_matrix([euler])[0], r_ned_frd, atol=1e-9)


def _matrix_euler(r):
    return np.array(
        [[math.atan2(r[2, 1], r[2, 2]), math.asin(max(-1.0, min(1.0, -r[2, 0]))), math.atan2(r[1, 0], r[0, 0])]]
    )


def test_nan_and_bad_norm_survive_the_ros_conversion_as_nan_angles():
    q = np.array([[np.nan, 0, 0, 1.0], [3.0, 0, 0, 0]])
    assert np.isnan(quaternion_to_euler(quaternion_enu_flu_to_ned_frd(q))).all()


# ------------------------------------------------------------------------------------------------
# Validation
# ------------------------------------------------------------------------------------------------

BASE = """
[vehicle]
model = "ins"
rate_hz = 10
"""
INPUTS = """
[inputs]
gyro = { channels = ["/imu/gyro.x", "/imu/gyro.y", "/imu/gyro.z"], frame = "flu" }
accel = { channels = ["/imu/accel.x", "/imu/accel.y", "/imu/accel.z"], frame = "flu", scale = 2.0, \
offset = [0.5, 0, -1] }
"""
PLAIN_INPUTS = """
[inputs]
gyro = ["/imu/gyro.x", "/imu/gyro.y", "/imu/gyro.z"]
accel = ["/imu/accel.x", "/imu/accel.y", "/imu/accel.z"]
"""
ODOM = """
[measurements.odometry]
channels = ["/odom/v.x", "/odom/v.y", "/odom/v.z"]
rate_hz = 5
frame = "flu"
"""
ATTITUDE = """
[measurements.attitude]
channels = ["/odom/q.w", "/odom/q.x", "/odom/q.y", "/odom/q.z"]
rate_hz = 5
from = "quaternion"
frame = "enu_flu"
"""
VELOCITY = """
[measurements.gnss_velocity]
channels = ["/gps/v.x", "/gps/v.y", "/gps/v.z"]
rate_hz = 5
frame = "enu"
scale = [1.0, 1.0, 0.5]
offset = 0.25
"""


def parse(text: str):
    return parse_profile(BASE + text)


def problems(text: str) -> list[str]:
    with pytest.raises(ProfileError) as info:
        parse(text)
    return info.value.problems


def test_transforms_parse():
    p = parse(INPUTS + ODOM + ATTITUDE + VELOCITY)
    assert p.inputs.mapping["gyro"] == {"channels": ["/imu/gyro.x", "/imu/gyro.y", "/imu/gyro.z"], "frame": "flu"}
    assert p.inputs.mapping["accel"]["scale"] == [2.0, 2.0, 2.0]
    assert p.inputs.names == ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"]
    assert p.inputs.factors == [1.0, -1.0, -1.0, 2.0, -2.0, -2.0]
    assert p.inputs.offsets == [0.0, 0.0, 0.0, 0.5, 0.0, -1.0]
    odom, att, vel = p.measurements["odometry"], p.measurements["attitude"], p.measurements["gnss_velocity"]
    assert (odom.frame, odom.source, odom.width, odom.output_names()) == ("flu", None, 3, ("forward", "right", "down"))
    assert (att.frame, att.source, att.width) == ("enu_flu", "quaternion", 3)
    assert (vel.frame, vel.offset, vel.scale, vel.output_names()) == (
        "enu",
        [0.25, 0.25, 0.25],
        [1.0, 1.0, 0.5],
        ("north", "east", "down"),
    )


def test_plain_inputs_keep_working_with_identity_transforms():
    p = parse(PLAIN_INPUTS + ODOM)
    assert p.inputs.factors == [1.0] * 6 and p.inputs.offsets == [0.0] * 6
    assert p.inputs.mapping["gyro"] == ["/imu/gyro.x", "/imu/gyro.y", "/imu/gyro.z"]


def test_identity_frames_and_offset_on_any_group():
    p = parse(
        PLAIN_INPUTS + ODOM.replace('"flu"', '"frd"') + '[measurements.baro]\nchannels = ["/b"]\nrate_hz = 5\n'
        "offset = -488.0\n"
    )
    assert p.measurements["odometry"].frame == "frd" and not p.measurements["odometry"].converted
    assert p.measurements["baro"].offset == [-488.0]


@pytest.mark.parametrize(
    "text, expected",
    [
        (
            PLAIN_INPUTS + ODOM.replace('"flu"', '"nwu"'),
            "[measurements.odometry] frame: expected 'frd', 'ned', 'flu' or 'enu' (a 3-vector without from), "
            "got string 'nwu'",
        ),
        (
            PLAIN_INPUTS + ODOM.replace(', "/odom/v.z"', ""),
            '[measurements.odometry] frame: frame = "flu" needs exactly 3 channels (x, y, z), got 2',
        ),
        (
            PLAIN_INPUTS + ATTITUDE.replace('"enu_flu"', '"flu"'),
            "[measurements.attitude] frame: expected 'ned' or 'enu_flu' (from = \"quaternion\"), got string 'flu'",
        ),
        (
            PLAIN_INPUTS + ODOM.replace('"flu"', "3"),
            "[measurements.odometry] frame: expected 'frd', 'ned', 'flu' or 'enu' (a 3-vector without from), "
            "got number 3",
        ),
        (
            PLAIN_INPUTS + VELOCITY.replace("offset = 0.25", "offset = [1, 2]"),
            "[measurements.gnss_velocity] offset: 2 values for 3 channels (give one number or 3)",
        ),
        (
            PLAIN_INPUTS + VELOCITY.replace("offset = 0.25", "offset = inf"),
            "[measurements.gnss_velocity] offset: must be finite, got inf",
        ),
        (
            PLAIN_INPUTS + VELOCITY.replace("offset = 0.25", 'offset = "1"'),
            "[measurements.gnss_velocity] offset: expected a number or an array of numbers, got string '1'",
        ),
        (
            INPUTS.replace('frame = "flu" }', 'frame = "enu" }', 1) + ODOM,
            "[inputs] gyro frame: expected 'frd' or 'flu', got string 'enu'",
        ),
        (
            INPUTS.replace('"/imu/gyro.x", "/imu/gyro.y", "/imu/gyro.z"', '"/imu/gyro.x", "/imu/gyro.y"') + ODOM,
            '[inputs] gyro frame: frame = "flu" needs exactly 3 channels (x, y, z), got 2',
        ),
        (
            INPUTS.replace("scale = 2.0", "scale = [1, 2]") + ODOM,
            "[inputs] accel scale: 2 values for 3 channels (give one number or 3)",
        ),
        (INPUTS.replace("scale = 2.0", "scale = 0") + ODOM, "[inputs] accel scale: must be non-zero, got 0"),
        (
            INPUTS.replace("offset = [0.5, 0, -1]", "ofset = 1") + ODOM,
            "[inputs] accel: unknown key 'ofset' (did you mean 'offset'?)",
        ),
        (
            INPUTS.replace(
                '{ channels = ["/imu/gyro.x", "/imu/gyro.y", "/imu/gyro.z"], frame = "flu" }', '{ frame = "flu" }'
            )
            + ODOM,
            "[inputs] gyro: missing required key 'channels'",
        ),
        (
            PLAIN_INPUTS.replace('accel = ["/imu/accel.x", "/imu/accel.y", "/imu/accel.z"]', "accel = 1") + ODOM,
            "[inputs] accel: expected a channel name, an array of them or a table { channels = [...] }, got number 1",
        ),
        (
            INPUTS.replace('"/imu/gyro.x", "/imu/gyro.y", "/imu/gyro.z"', '"/g.x", "/g.y", "/g.z", "/g.w"').replace(
                ', frame = "flu" }', " }", 1
            )
            + ODOM,
            "[inputs] gyro: 4 channels but model 'ins' has 3 inputs starting with 'gyro' (gyro_x, gyro_y, gyro_z)",
        ),
    ],
)
def test_transform_problems(text, expected):
    assert problems(text)[0] == expected


def test_transforms_round_trip_through_to_toml():
    p = parse(INPUTS + ODOM + ATTITUDE + VELOCITY)
    text = p.to_toml()
    assert 'frame = "enu_flu"' in text and 'frame = "flu"' in text and "offset = [0.25, 0.25, 0.25]" in text
    q = parse_profile(text)
    assert q == p and q.to_toml() == text
    assert q.inputs.factors == p.inputs.factors and q.inputs.offsets == p.inputs.offsets
    # a quaternion group in the default frame writes none (as before)
    r = parse(PLAIN_INPUTS + ATTITUDE.replace('frame = "enu_flu"\n', ""))
    assert "frame" not in r.to_toml() and parse_profile(r.to_toml()) == r


def test_a_changed_transform_is_a_different_profile():
    assert parse(INPUTS + ODOM) != parse(INPUTS.replace("scale = 2.0", "scale = 3.0") + ODOM)
    assert parse(INPUTS + ODOM) != parse(INPUTS + ODOM.replace('"flu"', '"frd"'))


# ------------------------------------------------------------------------------------------------
# Alignment end to end
# ------------------------------------------------------------------------------------------------


def make_log(channels: dict[str, tuple]) -> Log:
    chans = {
        name: Channel(name, np.asarray(t_ms, dtype=np.int64) * MS, np.asarray(v, dtype=np.float64))
        for name, (t_ms, v) in channels.items()
    }
    return Log(chans, SourceInfo("ros.mcap", "mcap"))


def ros_log(n: int = 11) -> tuple[Log, dict]:
    """IMU at 10 Hz, odometry (body velocity, orientation) and an ENU velocity at 5 Hz."""
    t10 = np.arange(n) * 100
    t5 = np.arange((n + 1) // 2) * 200
    m = t5.size
    data = {
        "gyro": np.column_stack([np.full(n, 0.1), np.full(n, 0.2), np.full(n, 0.3)]),
        "accel": np.column_stack([np.full(n, 1.0), np.full(n, 2.0), np.full(n, 9.81)]),
        "v": np.column_stack([np.linspace(1, 2, m), np.full(m, 0.5), np.full(m, -0.25)]),
        "q": euler_to_quaternion(np.column_stack([np.zeros(m), np.zeros(m), np.linspace(0, 1, m)])),
        "gv": np.column_stack([np.full(m, 3.0), np.full(m, 4.0), np.full(m, 5.0)]),
    }
    channels = {}
    for i, axis in enumerate("xyz"):
        channels[f"/imu/gyro.{axis}"] = (t10, data["gyro"][:, i])
        channels[f"/imu/accel.{axis}"] = (t10, data["accel"][:, i])
        channels[f"/odom/v.{axis}"] = (t5, data["v"][:, i])
        channels[f"/gps/v.{axis}"] = (t5, data["gv"][:, i])
    for i, c in enumerate("wxyz"):
        channels[f"/odom/q.{c}"] = (t5, data["q"][:, i])
    return make_log(channels), data


def test_alignment_applies_every_transform():
    log, data = ros_log()
    run = align(log, parse(INPUTS + ODOM + ATTITUDE + VELOCITY))
    assert run.input_names == ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"]
    np.testing.assert_allclose(run.u[:, :3], np.tile([0.1, -0.2, -0.3], (11, 1)))
    np.testing.assert_allclose(run.u[:, 3:], np.tile([2.0 + 0.5, -4.0, -2 * 9.81 - 1.0], (11, 1)))
    assert run.u_fresh.all()

    odom = run.groups["odometry"]
    assert odom.channels == ["/odom/v.{x,y,z} forward", "/odom/v.{x,y,z} right", "/odom/v.{x,y,z} down"]
    np.testing.assert_allclose(odom.z[::2], data["v"] * [1.0, -1.0, -1.0])
    assert odom.fresh.tolist() == [k % 2 == 0 for k in range(11)]
    assert odom.channel_fresh.shape == (11, 3) and (odom.channel_fresh == odom.fresh[:, None]).all()

    att = run.groups["attitude"]
    assert [c.rsplit(" ", 1)[1] for c in att.channels] == ["roll", "pitch", "yaw"]
    # an ENU yaw psi is the NED yaw pi/2 - psi
    np.testing.assert_allclose(att.z[::2, 2], math.pi / 2 - np.linspace(0, 1, 6), atol=1e-12)
    np.testing.assert_allclose(att.z[::2, :2], 0.0, atol=1e-12)

    vel = run.groups["gnss_velocity"]
    assert [c.rsplit(" ", 1)[1] for c in vel.channels] == ["north", "east", "down"]
    # raw * scale + offset (3.25, 4.25, 2.75), then ENU -> NED
    np.testing.assert_allclose(vel.z[::2], np.tile([4.25, 3.25, -2.75], (6, 1)))

    # every group shares the one array of measurements, in the profile's order
    assert odom.z.base is att.z.base is vel.z.base and odom.z.base.shape == (11, 9)


def test_enu_channel_fresh_follows_the_permutation():
    log, _ = ros_log()
    # the north (y) channel misses a sample: the NED north column is stale there, not east
    t5 = log.channels["/gps/v.y"].t
    log.channels["/gps/v.y"] = Channel("/gps/v.y", t5[[0, 1, 3, 4, 5]], np.full(5, 4.0))
    run = align(log, parse(PLAIN_INPUTS + VELOCITY))
    vel = run.groups["gnss_velocity"]
    assert not vel.channel_fresh[4, 0] and vel.channel_fresh[4, 1] and vel.channel_fresh[4, 2]
    assert not vel.fresh[4] and vel.fresh[2]


def test_plain_inputs_are_held_unchanged():
    log, data = ros_log()
    run = align(log, parse(PLAIN_INPUTS + ODOM.replace('frame = "flu"\n', "")))
    np.testing.assert_allclose(run.u[:, :3], np.tile([0.1, 0.2, 0.3], (11, 1)))
    np.testing.assert_allclose(run.groups["odometry"].z[::2], data["v"])
    assert run.groups["odometry"].channels == ["/odom/v.x", "/odom/v.y", "/odom/v.z"]


def test_offset_applies_before_a_geodetic_conversion_and_to_its_first_fix():
    t = np.arange(6) * 200
    log = make_log(
        {
            "/imu/gyro.x": (np.arange(11) * 100, np.zeros(11)),
            "/imu/gyro.y": (np.arange(11) * 100, np.zeros(11)),
            "/imu/gyro.z": (np.arange(11) * 100, np.zeros(11)),
            "/imu/accel.x": (np.arange(11) * 100, np.zeros(11)),
            "/imu/accel.y": (np.arange(11) * 100, np.zeros(11)),
            "/imu/accel.z": (np.arange(11) * 100, np.zeros(11)),
            "/fix/lat": (t, np.full(6, 47.0)),
            "/fix/lon": (t, np.full(6, 8.0)),
            "/fix/alt": (t, 10.0 * np.arange(6)),  # above the ellipsoid; offset: + 400 m
        }
    )
    gnss = (
        '[measurements.gnss_position]\nchannels = ["/fix/lat", "/fix/lon", "/fix/alt"]\nrate_hz = 5\n'
        'from = "geodetic"\noffset = [0, 0, 400]\n'
    )
    run = align(log, parse(PLAIN_INPUTS + gnss))
    g = run.groups["gnss_position"]
    assert g.origin == pytest.approx((47.0, 8.0, 400.0))
    np.testing.assert_allclose(g.z[::2, 2], -10.0 * np.arange(6), atol=1e-6)
