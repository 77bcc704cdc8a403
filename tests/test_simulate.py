"""`logscan simulate`: closed loop per model, determinism, formats, CLI errors, filter consistency."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from logscan.align import align
from logscan.filters.ekf import run_ekf
from logscan.models import get_model
from logscan.profiles import load_profile, resolve_profile
from logscan.readers import read_log
from logscan.simulate import simulate

REPO = Path(__file__).resolve().parents[1]
QUAD_HEALTHY = REPO / "sample_logs" / "quad_healthy.mcap"


def _mean_nis_per_measurement(log, profile) -> tuple[float, dict]:
    run = align(log, profile)
    model = get_model(profile.vehicle.model, profile.vehicle.params)
    trace = run_ekf(model, run, store_gain=False, store_S=False)
    updated = trace.m_k > 0
    return float(np.nansum(trace.nis[updated]) / trace.m_k[updated].sum()), trace.summary()


def test_healthy_quadcopter_log_nis_averages_the_number_of_measurements():
    """Acceptance: the analysis EKF on the healthy sample log is consistent."""
    if not QUAD_HEALTHY.exists():
        pytest.skip("sample_logs/quad_healthy.mcap is absent (python sample_logs/make_samples.py)")
    log = read_log(QUAD_HEALTHY)
    ratio, summary = _mean_nis_per_measurement(log, resolve_profile(log))
    assert abs(ratio - 1.0) < 0.10, ratio
    assert summary["divergence_episodes"] == 0
    assert all(n == 0 for n in summary["rejected"].values())


@pytest.mark.parametrize("model_name", ["quadcopter", "steer_by_wire", "dc_motor"])
def test_every_model_is_consistent_with_its_analysis_filter(model_name, tmp_path, cli):
    out = tmp_path / "h.mcap"
    result = cli("simulate", model_name, "--duration", "40", "--seed", "5", "-q", "-o", out)
    assert result.exit_code == 0, result.output
    log = read_log(out)
    profile = resolve_profile(log)
    profile.check_channels(log)
    ratio, _ = _mean_nis_per_measurement(log, profile)
    assert abs(ratio - 1.0) < 0.10, ratio


def test_quadcopter_flies_the_figure_eight_on_its_estimate():
    sim = simulate("quadcopter", duration=60, seed=2)
    ref = sim.scenario.reference
    assert np.abs(sim.x_true[:, :3] - ref[:, :3]).max() < 1.0
    assert np.ptp(sim.x_true[:, 0]) > 4.0 and np.ptp(sim.x_true[:, 1]) > 2.0  # it did fly the eight
    hover = sim.t < 14.0
    assert np.abs(sim.x_true[hover, :2]).max() < 0.5
    estimate_error = np.sqrt(np.mean((sim.x_hat - sim.x_true) ** 2, axis=0))
    assert estimate_error[:3].max() < 0.2  # position from 10 Hz GPS + IMU


def test_aggressive_flight_tilts_more():
    calm = simulate("quadcopter", duration=40, seed=3)
    wild = simulate("quadcopter", duration=40, seed=3, aggressive=True)
    assert np.abs(wild.x_true[:, 6:8]).max() > 2 * np.abs(calm.x_true[:, 6:8]).max()


def test_steer_by_wire_front_wheel_follows_the_hand_wheel():
    sim = simulate("steer_by_wire", duration=40, seed=4)
    n_theta = sim.scenario.ctrl_params[8]
    delta_ref = sim.scenario.reference[:, 0] / n_theta
    assert np.abs(sim.x_true[:, 0]).max() > 0.03  # lane changes were driven
    lag = int(round(0.3 / sim.dt))  # the hand wheel PD lags its reference
    assert np.abs(sim.x_true[lag:, 0] - delta_ref[:-lag]).max() < 0.02


def test_dc_motor_tracks_every_speed_mode():
    sim = simulate("dc_motor", duration=180, seed=8)
    radius = sim.scenario.model.p["wheel_radius"]
    command = sim.scenario.mode_values
    assert set(np.round(np.unique(command), 3)) == {0.4, 0.7, 1.0, 1.3, 1.6, 1.9}
    settled = np.ones(sim.n_steps, dtype=bool)
    for change in np.flatnonzero(np.diff(command)) + 1:
        settled[change : change + int(3.0 / sim.dt)] = False
    speed = radius * sim.x_true[:, 1]
    assert np.abs(speed - command)[settled].mean() < 0.05


def test_glitch_tolerance_follows_the_sensor_rates():
    from dataclasses import replace

    from logscan.simulate.scenario import NIS_WINDOW, glitch_tolerance

    groups = simulate("dc_motor", duration=1, seed=0).scenario.groups  # encoder 20 Hz, GPS 10 Hz
    alarms, detectors = glitch_tolerance(groups)
    assert alarms == {"min_duration_s": 0.15}  # > the 0.1 s between two GPS samples
    assert detectors["nis"] == {"window": NIS_WINDOW, "n_persist": NIS_WINDOW + 3}
    faster = [replace(g, rate_hz=50.0) if g.rate_hz == 20.0 else g for g in groups]
    # two GPS samples 0.1 s apart span 6 updates of a 50 Hz group in the overall NIS test
    assert glitch_tolerance(faster)[1]["nis"]["n_persist"] == NIS_WINDOW + 6
    assert "[alarms]" not in simulate("quadcopter", duration=1, seed=0).profile_toml()


def test_dc_motor_profile_tolerates_glitches_and_still_sees_a_gps_bias(tmp_path, cli):
    glitchy, faulty = tmp_path / "glitchy.mcap", tmp_path / "faulty.mcap"
    common = ("simulate", "dc_motor", "--duration", "120", "--glitches", "10", "--seed", "5", "-q", "-o")
    assert cli(*common, glitchy).exit_code == 0
    assert cli(*common, faulty, "--fault", "bias:gps_speed:40:50:0.15").exit_code == 0
    assert len(read_log(glitchy).truth["transients"]) >= 10
    result = cli("analyze", glitchy, "--no-report")
    assert result.exit_code == 0, result.stdout
    result = cli("analyze", faulty, "--no-report")
    assert result.exit_code == 1 and "nis.gps_speed" in result.stdout


def test_same_seed_same_bytes_other_seed_other_bytes(tmp_path, cli):
    paths = [tmp_path / name for name in ("a.mcap", "b.mcap", "c.mcap")]
    for path, seed in zip(paths, ("7", "7", "8")):
        args = [
            "simulate",
            "quadcopter",
            "--duration",
            "5",
            "--seed",
            seed,
            "--fault",
            "imu-bias",
            "--at",
            "2",
            "-q",
            "-o",
            str(path),
        ]
        assert cli(*args).exit_code == 0
    a, b, c = (p.read_bytes() for p in paths)
    assert a == b
    assert a != c


def test_imu_bias_at_30_embeds_truth_and_profile(tmp_path, cli):
    out = tmp_path / "q.mcap"
    result = cli("simulate", "quadcopter", "--fault", "imu-bias", "--at", "30", "-q", "-o", out)
    assert result.exit_code == 0, result.output
    log = read_log(out)
    (event,) = log.truth["events"]
    assert event == {
        "kind": "bias",
        "target": "accel.x",
        "start": 30.0,
        "end": 40.0,
        "magnitude": 1.0,
        "channels": ["/imu/accel.x"],
    }
    assert log.truth["true_state_topic"] == "/truth/state"
    assert {
        "/imu/accel.x",
        "/imu/gyro.z",
        "/gps/position.x",
        "/attitude/yaw",
        "/cmd/thrust",
        "/cmd/tau.x",
        "/ekf/state/vx",
        "/ekf/variance/vx",
        "/truth/state/x",
    } <= set(log.channels)
    inspect = cli("inspect", out)
    assert inspect.exit_code == 0 and "ground truth: yes" in inspect.output


def test_fault_options_apply_to_short_faults_and_colon_faults_keep_theirs(tmp_path, cli):
    out = tmp_path / "q.mcap"
    args = [
        "simulate",
        "quadcopter",
        "--duration",
        "20",
        "-q",
        "-o",
        str(out),
        "--fault",
        "drift",
        "--at",
        "5",
        "--fault-duration",
        "3",
        "--magnitude",
        "0.1",
        "--target",
        "gyro.y",
        "--fault",
        "stuck:position.z:12:14",
    ]
    assert cli(*args).exit_code == 0
    drift, stuck = read_log(out).truth["events"]
    assert (drift["kind"], drift["target"], drift["start"], drift["end"], drift["magnitude"]) == (
        "drift",
        "gyro.y",
        5.0,
        8.0,
        0.1,
    )
    assert (stuck["target"], stuck["start"], stuck["end"]) == ("position.z", 12.0, 14.0)


def test_ros2_encoding_reads_back_the_same_channels(tmp_path, cli):
    json_path, ros_path = tmp_path / "j.mcap", tmp_path / "r.mcap"
    for path, fmt in ((json_path, "mcap-json"), (ros_path, "mcap-ros2")):
        args = ["simulate", "steer_by_wire", "--duration", "5", "--format", fmt, "-q", "-o", str(path)]
        assert cli(*args).exit_code == 0
    a, b = read_log(json_path), read_log(ros_path)
    assert set(a.channels) == set(b.channels)
    np.testing.assert_array_equal(a.channel("/imu/yaw_rate").values, b.channel("/imu/yaw_rate").values)
    assert a.truth == b.truth


def test_csv_format_writes_truth_and_profile_sidecars(tmp_path, cli):
    out = tmp_path / "sbw.csv"
    args = [
        "simulate",
        "steer_by_wire",
        "--duration",
        "10",
        "--format",
        "csv",
        "--fault",
        "bias:steering_angle:4:6:0.01",
        "-q",
        "-o",
        str(out),
    ]
    assert cli(*args).exit_code == 0
    truth = json.loads((tmp_path / "sbw.truth.json").read_text())
    assert truth["events"][0]["channels"] == ["/steering/angle"]
    log = read_log(out)
    profile = load_profile(tmp_path / "sbw.profile.toml")
    ratio, _ = _mean_nis_per_measurement(log, profile)
    assert ratio > 1.5  # the 0.01 rad step on a 0.002 rad sensor shows in the innovations
    assert log.truth == truth


@pytest.mark.parametrize(
    "args, words",
    [
        (["simulate", "submarine", "-o", "x.mcap"], "cannot simulate model 'submarine'"),
        (["simulate", "quadcopter", "--fault", "wobble", "-o", "x.mcap"], "unknown fault kind 'wobble'"),
        (["simulate", "quadcopter", "--fault", "imu-bias", "--at", "90", "-o", "x.mcap"], "outside the log"),
        (["simulate", "quadcopter", "--duration", "-1", "-o", "x.mcap"], "out of range"),
        (["simulate", "quadcopter"], "no output file"),
    ],
)
def test_bad_requests_exit_2_with_one_line(args, words, cli, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = cli(*args)
    assert result.exit_code == 2
    assert words in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x.mcap").exists()


def test_unknown_model_error_lists_the_simulated_models(cli, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    err = cli("simulate", "tank", "-o", "x.mcap").stderr
    assert all(name in err for name in ("quadcopter", "steer_by_wire", "dc_motor"))


def test_help_documents_every_option(cli):
    result = cli("simulate", "--help")
    for option in (
        "--fault",
        "--at",
        "--fault-duration",
        "--magnitude",
        "--target",
        "--duration",
        "--seed",
        "--rate",
        "--format",
        "--aggressive",
        "--output",
    ):
        assert option in result.output
    assert "logscan simulate quadcopter --fault imu-bias --at 30 -o q.mcap" in result.output


def test_every_help_example_runs(tmp_path, monkeypatch, cli):
    from logscan.cli.simulate_cmd import simulate as command

    examples = [line.strip() for line in command.epilog.splitlines() if line.strip().startswith("logscan ")]
    assert len(examples) >= 3
    for i, example in enumerate(examples):
        here = tmp_path / str(i)  # each in a folder of its own: simulate never replaces a file
        here.mkdir()
        monkeypatch.chdir(here)
        args = example.split()[1:] + ["-q"]
        result = cli(*args)
        assert result.exit_code == 0, (example, result.output)
        assert (here / args[args.index("-o") + 1]).stat().st_size > 0


def test_output_suffix_csv_selects_the_csv_format(tmp_path, cli):
    out = tmp_path / "d.csv"
    assert cli("simulate", "dc_motor", "--duration", "5", "-q", "-o", out).exit_code == 0
    assert out.read_text().startswith("time_ns,")
    assert (tmp_path / "d.truth.json").exists() and (tmp_path / "d.profile.toml").exists()


def test_output_that_is_a_directory_is_a_usage_error(cli, tmp_path):
    result = cli("simulate", "dc_motor", "-o", tmp_path)
    assert result.exit_code == 2 and "directory" in result.stderr
