"""Per-group channel conversions of profiles: `scale`, `from = "quaternion"`, `from = "geodetic"`
(logscan/conversions.py, their validation and their alignment onto the grid)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.align import align
from logscan.conversions import (
    WGS84_A,
    WGS84_E2,
    euler_matrix,
    euler_to_quaternion,
    geodetic_to_ecef,
    geodetic_to_local,
    invalid_quaternions,
    quaternion_matrix,
    quaternion_to_euler,
)
from logscan.errors import ProfileError
from logscan.log import Channel, Log, SourceInfo
from logscan.models.base import GroupSpec
from logscan.profiles import parse_profile

MS = 1_000_000  # ns per millisecond
DEG = math.pi / 180


# ------------------------------------------------------------------------------------------------
# Quaternion -> ZYX Euler angles
# ------------------------------------------------------------------------------------------------


def test_identity_quaternion_is_zero_angles():
    np.testing.assert_array_equal(quaternion_to_euler(np.array([[1.0, 0, 0, 0]])), [[0.0, 0.0, 0.0]])


def test_yaw_90_deg_roll_30_deg_round_trip_through_a_quaternion():
    euler = np.array([[30 * DEG, 0.0, 90 * DEG], [-10 * DEG, 20 * DEG, -135 * DEG]])
    q = euler_to_quaternion(euler)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0)
    np.testing.assert_allclose(quaternion_to_euler(q), euler, atol=1e-12)
    # yaw 90 deg alone: q = (cos 45, 0, 0, sin 45)
    np.testing.assert_allclose(euler_to_quaternion([[0, 0, 90 * DEG]])[0], [math.sqrt(0.5), 0, 0, math.sqrt(0.5)])


def test_q_and_minus_q_give_the_same_angles_and_the_norm_is_normalised_away():
    q = euler_to_quaternion([[0.3, -0.2, 2.5]])
    np.testing.assert_allclose(quaternion_to_euler(-q), quaternion_to_euler(q), atol=1e-12)
    np.testing.assert_allclose(quaternion_to_euler(1.3 * q), quaternion_to_euler(q), atol=1e-12)


def test_invalid_norm_or_nan_component_gives_nan_angles():
    q = np.array([[0.4, 0, 0, 0], [1.6, 0, 0, 0], [0, 0, 0, 0], [np.nan, 0, 0, 1], [0.5, 0, 0, 0], [1.5, 0, 0, 0]])
    out = quaternion_to_euler(q)
    assert np.isnan(out[:4]).all()
    assert np.isfinite(out[4:]).all()  # the bounds are inclusive
    # held but invalid: only the finite rows with a bad norm (a NaN row is stale, not invalid)
    assert invalid_quaternions(q).tolist() == [True, True, True, False, False, False]


def test_gimbal_lock_pitch_is_clipped_not_nan():
    q = euler_to_quaternion([[0.0, math.pi / 2, 0.0]]) * (1 + 1e-15)
    assert quaternion_to_euler(q)[0, 1] == pytest.approx(math.pi / 2)


unit_quaternions = st.lists(st.floats(-1.0, 1.0, allow_nan=False), min_size=4, max_size=4).filter(
    lambda v: 0.1 < math.sqrt(sum(x * x for x in v))
)


def away_from_gimbal_lock(raw) -> bool:
    """|sin pitch| < 0.999: at pitch = +-90 deg roll and yaw are not unique, and the ZYX equations
    give atan2(0, 0) for both (the rotation's yaw - roll is lost)."""
    w, x, y, z = np.asarray(raw) / np.linalg.norm(raw)
    return abs(2 * (w * y - z * x)) < 0.999


@settings(max_examples=300, deadline=None)
@given(unit_quaternions.filter(away_from_gimbal_lock))
def test_euler_angles_give_the_quaternions_rotation(raw):
    q = np.array([raw]) / np.linalg.norm(raw)
    euler = quaternion_to_euler(q)
    assert np.isfinite(euler).all()
    np.testing.assert_allclose(euler_matrix(euler), quaternion_matrix(q), atol=1e-9)
    np.testing.assert_allclose(quaternion_to_euler(euler_to_quaternion(euler)), euler, atol=1e-9)


# ------------------------------------------------------------------------------------------------
# Geodetic -> local NED / ENU
# ------------------------------------------------------------------------------------------------

ORIGIN = (47.397742, 8.545594, 488.0)  # PX4's default SITL home


def ecef(lat, lon, h):
    lat, lon = math.radians(lat), math.radians(lon)
    n = WGS84_A / math.sqrt(1 - WGS84_E2 * math.sin(lat) ** 2)
    return np.array(
        [
            (n + h) * math.cos(lat) * math.cos(lon),
            (n + h) * math.cos(lat) * math.sin(lon),
            (n * (1 - WGS84_E2) + h) * math.sin(lat),
        ]
    )


def test_the_origin_maps_to_zero():
    np.testing.assert_allclose(geodetic_to_local([ORIGIN], ORIGIN), [[0.0, 0.0, 0.0]], atol=1e-9)


def test_ecef_matches_the_direct_formula():
    np.testing.assert_allclose(geodetic_to_ecef([ORIGIN])[0], ecef(*ORIGIN), rtol=1e-15)
    np.testing.assert_allclose(geodetic_to_ecef([[0.0, 0.0, 0.0]])[0], [WGS84_A, 0, 0])


def test_a_thousandth_of_a_degree_north_is_about_111_m_north():
    lat, lon, h = ORIGIN
    ned = geodetic_to_local([[lat + 0.001, lon, h]], ORIGIN)[0]
    assert 110.0 < ned[0] < 112.0
    assert abs(ned[1]) < 1e-6
    # the tangent plane is exact: |ned| is the ECEF distance, and "down" is the chord's sag
    distance = np.linalg.norm(ecef(lat + 0.001, lon, h) - ecef(*ORIGIN))
    assert np.linalg.norm(ned) == pytest.approx(distance, rel=1e-12)
    assert 0 < ned[2] < 0.01


def test_east_and_altitude():
    lat, lon, h = ORIGIN
    ned = geodetic_to_local([[lat, lon + 0.001, h], [lat, lon, h + 10.0]], ORIGIN)
    assert ned[0, 1] == pytest.approx(111.32 * 1000 * 0.001 * math.cos(math.radians(lat)), rel=5e-3)
    np.testing.assert_allclose(ned[1], [0.0, 0.0, -10.0], atol=1e-9)


def test_enu_is_east_north_up():
    lat, lon, h = ORIGIN
    points = [[lat + 0.001, lon + 0.002, h + 10.0]]
    ned = geodetic_to_local(points, ORIGIN)[0]
    enu = geodetic_to_local(points, ORIGIN, "enu")[0]
    np.testing.assert_allclose(enu, [ned[1], ned[0], -ned[2]])


def test_latitude_or_longitude_out_of_range_is_nan():
    out = geodetic_to_local([[91.0, 8.0, 0.0], [47.0, 181.0, 0.0], [47.0, 8.0, np.nan], [-90.0, 180.0, 0.0]], ORIGIN)
    assert np.isnan(out[:3]).all() and np.isfinite(out[3]).all()


# ------------------------------------------------------------------------------------------------
# Profile validation
# ------------------------------------------------------------------------------------------------


class FakeIns:
    input_names = ("accel",)
    state_names = ("north", "east", "down", "roll", "pitch", "yaw")
    groups = {
        "attitude": GroupSpec("attitude", 0, ("roll", "pitch", "yaw"), (0.05,) * 3, (-4.0,) * 3, (4.0,) * 3),
        "gnss_position": GroupSpec("gnss_position", 1, ("north", "east", "down"), (0.5,) * 3, (-1e7,) * 3, (1e7,) * 3),
        "baro": GroupSpec("baro", 2, ("alt",), (0.5,), (-1e4,), (1e4,)),
    }


BASE = """
[vehicle]
model = "fake"
rate_hz = 10

[inputs]
accel = "/accel"
"""
ATTITUDE = """
[measurements.attitude]
channels = [
    "/vehicle_attitude_0/q[0]", "/vehicle_attitude_0/q[1]", "/vehicle_attitude_0/q[2]", "/vehicle_attitude_0/q[3]",
]
rate_hz = 10
from = "quaternion"
"""
GNSS = """
[measurements.gnss_position]
channels = ["/vehicle_gps_position_0/lat", "/vehicle_gps_position_0/lon", "/vehicle_gps_position_0/alt"]
rate_hz = 5
scale = [1e-7, 1e-7, 1e-3]
from = "geodetic"
"""


def parse(toml: str):
    return parse_profile(BASE + toml, model=FakeIns())


def problems(toml: str) -> list[str]:
    with pytest.raises(ProfileError) as info:
        parse(toml)
    return info.value.problems


def test_a_converted_profile_parses_with_its_width():
    p = parse(ATTITUDE + "noise_std = [0.02, 0.02, 0.1]\n" + GNSS + 'frame = "ned"\norigin = [47.0, 8.0, 400.0]\n')
    att, gnss = p.measurements["attitude"], p.measurements["gnss_position"]
    assert (att.source, att.width, att.noise_std, att.scale) == ("quaternion", 3, [0.02, 0.02, 0.1], None)
    assert (gnss.source, gnss.width, gnss.scale, gnss.frame, gnss.origin) == (
        "geodetic",
        3,
        [1e-7, 1e-7, 1e-3],
        "ned",
        [47.0, 8.0, 400.0],
    )
    assert att.output_names() == ("roll", "pitch", "yaw")


def test_a_scalar_scale_applies_to_every_channel_and_a_plain_group_may_be_scaled():
    p = parse('[measurements.baro]\nchannels = ["/baro/alt_mm"]\nrate_hz = 10\nscale = -1e-3\n')
    assert p.measurements["baro"].scale == [-1e-3] and p.measurements["baro"].width == 1


@pytest.mark.parametrize(
    "toml, expected",
    [
        (
            ATTITUDE.replace(', "/vehicle_attitude_0/q[3]"', ""),
            '[measurements.attitude] channels: from = "quaternion" needs exactly 4 channels, '
            "in the order w, x, y, z; got 3",
        ),
        (
            GNSS.replace('"/vehicle_gps_position_0/alt"', '"/a", "/b"').replace("1e-3]", "1e-3, 1]"),
            '[measurements.gnss_position] channels: from = "geodetic" needs exactly 3 channels, in the order '
            "latitude (deg), longitude (deg), altitude (m, up); got 4",
        ),
        (
            ATTITUDE.replace('"quaternion"', '"quaternions"'),
            "[measurements.attitude] from: unknown conversion 'quaternions' (did you mean 'quaternion'?) "
            '(choices: "quaternion", "geodetic")',
        ),
        (
            ATTITUDE.replace('"quaternion"', "4"),
            '[measurements.attitude] from: expected a string ("quaternion", "geodetic"), got number 4',
        ),
        (
            ATTITUDE + 'frame = "enu"\n',
            "[measurements.attitude] frame: expected 'ned' or 'enu_flu' (from = \"quaternion\"), got string 'enu'",
        ),
        (ATTITUDE + "origin = [1, 2, 3]\n", '[measurements.attitude] origin: only allowed with from = "geodetic"'),
        (
            '[measurements.baro]\nchannels = ["/b"]\nrate_hz = 10\nframe = "ned"\n',
            '[measurements.baro] frame: frame = "ned" needs exactly 3 channels (x, y, z), got 1',
        ),
        (
            GNSS + 'frame = "nwu"\n',
            "[measurements.gnss_position] frame: expected 'ned', 'enu', 'ne' or 'en', got string 'nwu'",
        ),
        (
            GNSS + "origin = [47.0, 8.0]\n",
            "[measurements.gnss_position] origin: expected [latitude_deg, longitude_deg, altitude_m] (3 numbers)",
        ),
        (
            GNSS + "origin = [95.0, 8.0, 0]\n",
            "[measurements.gnss_position] origin: latitude must be within [-90, 90] degrees, got 95",
        ),
        (
            GNSS + "origin = [45.0, -200, 0]\n",
            "[measurements.gnss_position] origin: longitude must be within [-180, 180] degrees, got -200",
        ),
        (GNSS + "origin = [45.0, 8.0, nan]\n", "[measurements.gnss_position] origin: must be finite, got nan"),
        (
            GNSS.replace("scale = [1e-7, 1e-7, 1e-3]", "scale = [1e-7, 0, 1e-3]"),
            "[measurements.gnss_position] scale: must be non-zero, got 0",
        ),
        (
            GNSS.replace("scale = [1e-7, 1e-7, 1e-3]", "scale = inf"),
            "[measurements.gnss_position] scale: must be finite, got inf",
        ),
        (
            GNSS.replace("scale = [1e-7, 1e-7, 1e-3]", "scale = [1e-7, 1e-7]"),
            "[measurements.gnss_position] scale: 2 values for 3 channels (give one number or 3)",
        ),
        (
            ATTITUDE + "noise_std = [0.1, 0.1, 0.1, 0.1]\n",
            "[measurements.attitude] noise_std: 4 values for 3 outputs (give one number or 3)",
        ),
        (
            ATTITUDE + "range_lo = [-1, -1, -1]\nrange_hi = [1, -2, 1]\n",
            "[measurements.attitude]: range_lo must be < range_hi, got -1 >= -2 for 'pitch'",
        ),
    ],
)
def test_conversion_problems(toml, expected):
    assert problems(toml)[0] == expected


def test_noise_is_sized_to_the_converted_width_and_checked_against_its_outputs():
    assert parse(ATTITUDE + "noise_std = [0.01, 0.01, 0.05]\n").measurements["attitude"].noise_std == [0.01, 0.01, 0.05]
    assert problems(ATTITUDE + "noise_std = [0.01, 0.01, 9.0]\n")[0].startswith(
        "[measurements.attitude] noise_std: 9 ('yaw') exceeds the group's range span 8"
    )


def test_the_model_size_check_uses_the_converted_width():
    # 4 quaternion channels feed 3 outputs: fine; the same conversion into a 1-output group is not
    with pytest.raises(ProfileError) as info:
        parse(ATTITUDE.replace("measurements.attitude", "measurements.baro"))
    assert info.value.problems == [
        '[measurements.baro] channels: 4 channels (from = "quaternion" gives 3 values: roll, pitch, yaw) but '
        "model 'fake' group 'baro' has 1 outputs (alt)"
    ]
    # without `from`, 4 channels for 3 outputs is the old error
    assert problems(ATTITUDE.replace('from = "quaternion"\n', ""))[0] == (
        "[measurements.attitude] channels: 4 channels but model 'fake' group 'attitude' has 3 outputs "
        "(roll, pitch, yaw)"
    )


def test_a_converted_profile_round_trips_through_to_toml():
    p = parse(ATTITUDE + "noise_std = 0.05\nscale = -1\n" + GNSS + 'frame = "enu"\norigin = [47.0, 8.0, 400.0]\n')
    text = p.to_toml()
    assert 'from = "quaternion"' in text and 'frame = "enu"' in text and "origin = [47.0, 8.0, 400.0]" in text
    q = parse_profile(text, model=FakeIns())
    assert q == p and q.to_toml() == text
    r = parse(GNSS)  # the default frame is written out, no origin
    assert 'frame = "ned"' in r.to_toml() and "origin" not in r.to_toml()
    assert parse_profile(r.to_toml(), model=FakeIns()) == r


# ------------------------------------------------------------------------------------------------
# Alignment end to end
# ------------------------------------------------------------------------------------------------


def make_log(channels: dict[str, tuple]) -> Log:
    """channels: name -> (times in ms, values)."""
    chans = {
        name: Channel(name, np.asarray(t_ms, dtype=np.int64) * MS, np.asarray(v, dtype=np.float64))
        for name, (t_ms, v) in channels.items()
    }
    return Log(chans, SourceInfo("px4.mcap", "mcap"))


def px4_log(quaternions: np.ndarray, lla_int: np.ndarray) -> Log:
    t10 = np.arange(len(quaternions)) * 100  # 10 Hz attitude
    t5 = np.arange(len(lla_int)) * 200  # 5 Hz GNSS
    channels = {"/accel": (t10, np.zeros(t10.size))}
    for i in range(4):
        channels[f"/vehicle_attitude_0/q[{i}]"] = (t10, quaternions[:, i])
    for j, field in enumerate(("lat", "lon", "alt")):
        channels[f"/vehicle_gps_position_0/{field}"] = (t5, lla_int[:, j])
    return make_log(channels)


def test_alignment_converts_quaternions_and_integer_geodetic_fixes():
    euler = np.column_stack([np.linspace(-0.3, 0.3, 11), np.linspace(0.1, -0.1, 11), np.linspace(-3.0, 3.0, 11)])
    q = euler_to_quaternion(euler)
    q[4] *= 3.0  # a corrupt quaternion: norm 3
    lat = np.array([ORIGIN[0], ORIGIN[0] + 0.001, ORIGIN[0], ORIGIN[0], ORIGIN[0], ORIGIN[0]])
    lla = np.column_stack(
        [np.round(lat * 1e7), np.full(6, round(ORIGIN[1] * 1e7)), [488000, 488000, 498000, 488000, 488000, 488000]]
    )
    run = align(px4_log(q, lla), parse(ATTITUDE + GNSS))

    att = run.groups["attitude"]
    assert att.z.shape == (11, 3) and att.channel_fresh.shape == (11, 3)
    assert att.channels == [
        "/vehicle_attitude_0/q[0..3] roll",
        "/vehicle_attitude_0/q[0..3] pitch",
        "/vehicle_attitude_0/q[0..3] yaw",
    ]
    good = np.arange(11) != 4
    np.testing.assert_allclose(att.z[good], euler[good], atol=1e-12)
    assert np.isnan(att.z[4]).all() and att.fresh.all() and att.origin is None
    assert any(
        "group 'attitude': 1 grid step holds a quaternion whose norm is outside [0.5, 1.5]" in w for w in run.warnings
    )

    gnss = run.groups["gnss_position"]
    assert gnss.channels[0] == "/vehicle_gps_position_0/{lat,lon,alt} north"
    assert [c.rsplit(" ", 1)[1] for c in gnss.channels] == ["north", "east", "down"]
    assert gnss.origin == pytest.approx((round(ORIGIN[0] * 1e7) * 1e-7, round(ORIGIN[1] * 1e7) * 1e-7, 488.0))
    np.testing.assert_allclose(gnss.z[0:2], 0.0, atol=1e-6)  # the first fix, held for two steps
    assert 110.0 < gnss.z[2, 0] < 112.0
    np.testing.assert_allclose(gnss.z[4], [0.0, 0.0, -10.0], atol=1e-6)
    assert steps(gnss.fresh) == [0, 2, 4, 6, 8, 10]
    assert gnss.nonfinite_count == 0

    # the groups sit side by side in one array of the converted widths
    assert att.z.base is gnss.z.base and att.z.base.shape == (11, 6)
    assert not any("origin" in w for w in run.warnings)


def steps(mask) -> list[int]:
    return [int(i) for i in np.flatnonzero(mask)]


def test_the_default_origin_is_the_first_valid_fix_inside_the_window():
    q = euler_to_quaternion(np.zeros((21, 3)))
    lat = ORIGIN[0] + 0.0001 * np.arange(11)
    lla = np.column_stack([lat * 1e7, np.full(11, ORIGIN[1] * 1e7), np.full(11, 488000.0)])
    lla[0, 0] = 95e7  # not a fix: latitude out of range
    lla[1, 2] = np.nan  # dropped as non-finite by cleaning
    run = align(px4_log(q, lla), parse(ATTITUDE + GNSS))
    gnss = run.groups["gnss_position"]
    assert gnss.origin[0] == pytest.approx(lat[2])
    assert np.isnan(gnss.z[0]).all()  # held latitude 95 deg: NaN after conversion
    np.testing.assert_allclose(gnss.z[4], 0.0, atol=1e-6)
    assert gnss.nonfinite_count == 1
    # with --start: the first fix at or after the window's start
    later = align(px4_log(q, lla), parse(ATTITUDE + GNSS), start_s=1.0)
    assert later.groups["gnss_position"].origin[0] == pytest.approx(lat[5])
    # an explicit origin wins
    fixed = align(px4_log(q, lla), parse(ATTITUDE + GNSS + f"origin = [{lat[0] - 1:.7f}, {ORIGIN[1]}, 0.0]\n"))
    assert fixed.groups["gnss_position"].origin == pytest.approx((lat[0] - 1, ORIGIN[1], 0.0))
    assert fixed.groups["gnss_position"].z[4, 0] > 1e5


def test_enu_frame_and_float_degrees_without_scale():
    q = euler_to_quaternion(np.zeros((11, 3)))
    lla = np.column_stack([np.full(6, ORIGIN[0]), np.full(6, ORIGIN[1]), 488.0 + np.arange(6)])
    log = px4_log(q, lla)
    run = align(log, parse(ATTITUDE + GNSS.replace("scale = [1e-7, 1e-7, 1e-3]\n", "") + 'frame = "enu"\n'))
    gnss = run.groups["gnss_position"]
    assert [c.rsplit(" ", 1)[1] for c in gnss.channels] == ["east", "north", "up"]
    np.testing.assert_allclose(gnss.z[::2, 2], np.arange(6), atol=1e-6)


def test_scale_alone_multiplies_the_held_values():
    t = np.arange(11) * 100
    log = make_log({"/accel": (t, np.zeros(11)), "/baro/alt_mm": (t, 1000.0 * np.arange(11))})
    run = align(log, parse('[measurements.baro]\nchannels = ["/baro/alt_mm"]\nrate_hz = 10\nscale = 1e-3\n'))
    g = run.groups["baro"]
    np.testing.assert_allclose(g.z[:, 0], np.arange(11.0))
    assert g.channels == ["/baro/alt_mm"] and g.origin is None


def test_no_valid_fix_leaves_the_group_nan_with_a_warning():
    q = euler_to_quaternion(np.zeros((11, 3)))
    lla = np.column_stack([np.full(6, 1e10), np.full(6, 0.0), np.full(6, 0.0)])
    run = align(px4_log(q, lla), parse(ATTITUDE + GNSS))
    gnss = run.groups["gnss_position"]
    assert np.isnan(gnss.z).all() and gnss.origin is None
    assert any("group 'gnss_position': no sample with a valid latitude" in w for w in run.warnings)
