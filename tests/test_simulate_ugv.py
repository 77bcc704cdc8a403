"""Jackal-like UGV scenarios of `logscan simulate dc_motor` (A-TFM issue, item 1): commanded-speed
profiles (--speed), speed-dependent sensor noise, attacks on one redundant speed sensor, and healthy
transients (encoder slips, GPS glitches) listed in the truth apart from the faults."""

from __future__ import annotations

import numpy as np
import pytest

from logscan.readers import read_log
from logscan.simulate import parse_fault, simulate
from logscan.simulate.scenario import DCM_MODES, SPEED_NOISE

SENSORS = {"left": "/enc/left.v", "right": "/enc/right.v", "gps": "/gps/speed"}


def _channel(log, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(t in s, values) of a logged channel."""
    channel = log.channels[name]
    return channel.t * 1e-9, channel.values


def _true_speed(log) -> tuple[np.ndarray, np.ndarray]:
    t, w_v = _channel(log, "/truth/state/w_v")
    return t, 0.1 * w_v  # wheel radius 0.1 m


def _reading_error(log, channel: str) -> tuple[np.ndarray, np.ndarray]:
    """(t, reading - true speed) of a speed sensor, against the logged truth."""
    t, z = _channel(log, channel)
    t_true, v = _true_speed(log)
    return t, z - np.interp(t, t_true, v)


def _commanded(tmp_path, cli, *args: str):
    out = tmp_path / "ugv.mcap"
    result = cli("simulate", "dc_motor", "-q", "--force", "-o", out, *args)  # tests call it more than once
    assert result.exit_code == 0, result.stderr
    return read_log(out)


def test_constant_speed_is_commanded_the_whole_log(tmp_path, cli):
    log = _commanded(tmp_path, cli, "--speed", "0.7", "--duration", "30", "--seed", "1")
    t, cmd = _channel(log, "/cmd_vel/linear.x")
    assert t[-1] == pytest.approx(30.0) and np.all(cmd == 0.7)
    t_true, v = _true_speed(log)
    # the vehicle drives it (its on-board EKF assumes the top mode's sensor noise: a few cm/s of lag)
    assert abs(np.median(v[t_true > 3.0]) - 0.7) < 0.01 and np.abs(v[t_true > 3.0] - 0.7).mean() < 0.04
    assert log.truth["speed_profile"] == "0.7"


def test_speed_changes_are_commanded_from_their_times(tmp_path, cli):
    log = _commanded(tmp_path, cli, "--speed", "1.0,0.4@30,1.3@50", "--duration", "70", "--seed", "2")
    t, cmd = _channel(log, "/cmd_vel/linear.x")
    expected = np.where(t < 30.0 - 1e-6, 1.0, np.where(t < 50.0 - 1e-6, 0.4, 1.3))
    np.testing.assert_array_equal(cmd, expected)
    t_true, v = _true_speed(log)
    for lo, hi, speed in ((5, 30, 1.0), (35, 50, 0.4), (55, 70, 1.3)):
        assert np.abs(v[(t_true > lo) & (t_true < hi)] - speed).mean() < 0.03


def test_random_speed_profile_is_seeded_modes_held_5_to_20_s(tmp_path, cli):
    profiles = []
    for seed in ("3", "3", "4"):
        log = _commanded(tmp_path, cli, "--speed", "random", "--duration", "300", "--seed", seed)
        profiles.append(_channel(log, "/cmd_vel/linear.x"))
    (t, cmd), (_, again), (_, other) = profiles
    np.testing.assert_array_equal(cmd, again)
    assert not np.array_equal(cmd, other)
    assert set(np.unique(cmd)) <= set(DCM_MODES) and len(np.unique(cmd)) >= 4
    changes = np.flatnonzero(np.diff(cmd)) + 1
    holds = np.diff(np.concatenate([[0.0], t[changes]]))
    assert len(changes) >= 300 / 20 - 1
    assert holds.min() >= 5.0 - 0.1 and holds.max() <= 20.0 + 0.1


def test_default_is_still_the_mode_cycle():
    sim = simulate("dc_motor", duration=120, seed=8)
    speeds = sim.scenario.mode_values
    assert set(np.round(np.unique(speeds), 3)) == set(DCM_MODES)
    changes = np.flatnonzero(np.diff(speeds)) + 1
    np.testing.assert_allclose(changes[:5] * sim.dt, [20.0, 40.0, 60.0, 80.0, 100.0])  # 20 s each
    assert sim.scenario.groups[0].noise_slope is None  # constant noise, as the analysis filter has it


@pytest.mark.parametrize("channel, group", [("/enc/left.v", "encoder"), ("/gps/speed", "gps_speed")])
def test_sensor_noise_grows_with_the_speed(tmp_path, cli, channel, group):
    stds = {}
    for speed in ("0.4", "1.9"):
        log = _commanded(tmp_path, cli, "--speed", speed, "--duration", "120", "--seed", "5")
        t, err = _reading_error(log, channel)
        stds[speed] = err[t > 3.0].std()
    base, k = SPEED_NOISE[group]
    assert stds["0.4"] == pytest.approx(base + k * 0.4, rel=0.12)
    assert stds["1.9"] == pytest.approx(base + k * 1.9, rel=0.12)
    assert stds["1.9"] > 1.6 * stds["0.4"]
    # the profile keeps the group's nominal noise; --noise constant keeps it in the log too
    log = _commanded(tmp_path, cli, "--speed", "1.9", "--noise", "constant", "--duration", "120", "--seed", "5")
    t, err = _reading_error(log, channel)
    nominal = {"encoder": 0.02, "gps_speed": 0.05}[group]
    assert err[t > 3.0].std() == pytest.approx(nominal, rel=0.12)
    assert f"noise_std = [{nominal}" in log.profile_text.replace(", ", ",")


@pytest.mark.parametrize(
    "target, attacked",
    [
        ("gps_speed", "gps"),
        ("/gps/speed", "gps"),
        ("gps", "gps"),
        ("encoder.v_left", "left"),
        ("left", "left"),
        ("/enc/left.v", "left"),
        ("encoder.v_right", "right"),
        ("right", "right"),
    ],
)
def test_a_bias_attack_shifts_only_its_sensor_in_its_window(tmp_path, cli, target, attacked):
    log = _commanded(
        tmp_path,
        cli,
        *("--speed", "1.0,0.4@30", "--duration", "90", "--seed", "6"),
        *("--fault", f"bias:{target}:45:75:0.22"),
    )
    (event,) = log.truth["events"]
    canonical = {"gps": "gps_speed", "left": "encoder.v_left", "right": "encoder.v_right"}[attacked]
    assert (event["kind"], event["target"], event["start"], event["end"]) == ("bias", canonical, 45.0, 75.0)
    assert event["channels"] == [SENSORS[attacked]]
    assert log.truth["transients"] == []
    for name, channel in SENSORS.items():
        t, err = _reading_error(log, channel)
        inside, before = (t >= 45.5) & (t < 75.0), (t > 35.0) & (t < 45.0)
        shift = err[inside].mean() - err[before].mean()
        assert shift == pytest.approx(0.22 if name == attacked else 0.0, abs=0.02), name
        after = t > 76.0
        assert abs(err[after].mean()) < 0.02, name


def _healthy_and_attacked(fault: str):
    kwargs = dict(duration=90, seed=7, speed="1.0,0.4@30")
    return simulate("dc_motor", **kwargs), simulate("dc_motor", [parse_fault(fault)], **kwargs)


def test_random_attack_values_lie_within_m_of_the_healthy_reading():
    m = 0.3
    healthy, attacked = _healthy_and_attacked(f"random:gps:45:75:{m}")
    (event,) = attacked.events
    assert (event.kind, event.target, event.magnitude) == ("random", "gps_speed", m)
    col = attacked.group_slices()["gps_speed"].start
    t = attacked.t
    sampled = ~np.isnan(attacked.z[:, col])
    offset = (attacked.z[:, col] - healthy.z[:, col])[sampled]
    ts = t[sampled]
    inside = (ts >= 45.0) & (ts < 75.0)
    # the GPS barely moves the closed loop: outside the window it reads as in the healthy run
    assert np.all(offset[ts < 45.0] == 0.0)
    assert np.abs(offset[ts >= 75.0]).max() < 0.01
    assert np.abs(offset[inside]).max() <= m + 0.01
    assert offset[inside].min() < -0.8 * m and offset[inside].max() > 0.8 * m
    assert offset[inside].std() == pytest.approx(m / np.sqrt(3.0), rel=0.2)  # uniform in [-m, m]


@pytest.mark.parametrize("target, col", [("left", 0), ("right", 1)])
def test_random_attack_on_an_encoder_is_uniform_in_m_against_the_truth(target, col):
    m = 0.3
    _, attacked = _healthy_and_attacked(f"random:{target}:45:75:{m}")
    c = attacked.group_slices()["encoder"].start + col
    err = attacked.z[:, c] - 0.1 * attacked.x_true[:, 1]
    inside = (attacked.t >= 45.0) & (attacked.t < 75.0) & ~np.isnan(err)
    noise = SPEED_NOISE["encoder"][0] + SPEED_NOISE["encoder"][1] * 0.4
    assert np.abs(err[inside]).max() <= m + 4.5 * noise
    assert err[inside].min() < -0.8 * m and err[inside].max() > 0.8 * m
    assert err[inside].std() == pytest.approx(np.sqrt(m**2 / 3.0 + noise**2), rel=0.2)


def test_glitches_are_encoder_slips_and_gps_glitches_in_the_truth_transients(tmp_path, cli):
    log = _commanded(tmp_path, cli, "--speed", "random", "--glitches", "8", "--duration", "180", "--seed", "9")
    truth = log.truth
    assert truth["events"] == []
    glitches = truth["transients"]
    causes = {g["cause"] for g in glitches}
    assert causes == {"encoder-slip", "gps-glitch"} and len(glitches) >= 12
    for glitch in glitches:
        assert glitch["kind"] == "glitch"
        (channel,) = glitch["channels"]
        assert channel in SENSORS.values()
        assert glitch["cause"] == ("gps-glitch" if channel == "/gps/speed" else "encoder-slip")
        if glitch["cause"] == "encoder-slip":
            assert glitch["magnitude"] < 0  # a slipping encoder reads low
        t, err = _reading_error(log, channel)
        window = (t >= glitch["start"] - 1e-6) & (t < glitch["end"] - 1e-6)
        assert 1 <= window.sum() <= 2  # one or two samples of one sensor
        assert err[window][0] == pytest.approx(glitch["magnitude"], abs=0.25 * abs(glitch["magnitude"]) + 0.05)


@pytest.mark.parametrize(
    "args, words",
    [
        (("dc_motor", "--speed", "fast"), "is not a speed profile"),
        (("dc_motor", "--speed", "1.0,0.4"), "needs its start time"),
        (("dc_motor", "--speed", "1.0@5"), "without @"),
        (("dc_motor", "--speed", "1.0,0.4@30,0.7@20"), "not after the previous one"),
        (("dc_motor", "--speed", "1.0,0.4@300"), "inside the log"),
        (("dc_motor", "--speed", "2.5"), "out of range"),
        (("quadcopter", "--speed", "1.0"), "--speed is for dc_motor"),
        (("steer_by_wire", "--noise", "speed"), "--noise speed is for dc_motor"),
    ],
)
def test_a_bad_speed_exits_2_with_one_line(tmp_path, cli, args, words):
    out = tmp_path / "never.mcap"
    result = cli("simulate", *args, "-o", out)
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0], result.stderr
    assert not out.exists()
