"""`logscan simulate ins`: the open-loop IMU-driven simulation (logscan/simulate/ins_sim.py)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from logscan.align import align
from logscan.filters.ekf import run_ekf
from logscan.models import get_model
from logscan.models.ins import so3_log
from logscan.profiles import resolve_profile
from logscan.readers import read_log
from logscan.simulate import parse_fault, simulate
from logscan.simulate.ins_sim import so3_log_batch

IMU = ["/imu/gyro.x", "/imu/gyro.y", "/imu/gyro.z", "/imu/accel.x", "/imu/accel.y", "/imu/accel.z"]


@pytest.fixture(scope="module")
def flight():
    """40 s: the hover and the first move (20 s on), aggressive so the vehicle tilts and turns."""
    return simulate("ins", duration=40, seed=11, aggressive=True)


def test_truth_obeys_the_model_step_exactly_with_the_true_imu(flight):
    """x_k = f(x_{k-1}, imu_k) on position, velocity and attitude (the IMU logged at step k drives
    k-1 -> k, the EKF's convention); the biases and the barometer offset random-walk with the
    model's own process noise."""
    model, sim = get_model("ins"), flight
    x, u = sim.x_true, sim.u_act
    worst, moving = 0.0, 0
    for k in range(sim.n_steps - 1):
        d = model.boxminus(model.f(x[k], u[k + 1], sim.dt), x[k + 1])
        worst = max(worst, float(np.abs(d[:9]).max()))
        moving += bool(np.abs(x[k, 3:6]).max() > 0.5)
    assert worst < 1e-9
    assert moving > 100  # it did fly: the check covers accelerations, tilts and turns
    assert np.degrees(np.abs(x[:, 6:8]).max()) > 5.0
    walk = np.diff(x[:, 9:16], axis=0).std(axis=0) / np.sqrt(sim.dt)
    p = model.p
    expected = [p["gyro_bias_rw"]] * 3 + [p["accel_bias_rw"]] * 3 + [p["baro_offset_rw"]]
    np.testing.assert_allclose(walk, expected, rtol=0.05)


def test_vectorised_so3_log_matches_the_models():
    rng = np.random.default_rng(0)
    w = np.concatenate([rng.normal(0, 1.0, (20, 3)), rng.normal(0, 1e-6, (5, 3)), np.zeros((1, 3))])
    R = Rotation.from_rotvec(w).as_matrix()  # Exp(w)
    got = so3_log_batch(R)
    np.testing.assert_allclose(got, w, atol=1e-12)
    np.testing.assert_allclose(got, np.stack([so3_log(r) for r in R]), atol=1e-9)


def test_logged_imu_has_the_models_noise_and_params_override_it(flight):
    p = get_model("ins").p
    std = (flight.u_cmd - flight.u_act).std(axis=0)
    np.testing.assert_allclose(std, [p["gyro_noise"]] * 3 + [p["accel_noise"]] * 3, rtol=0.10)
    quiet = simulate("ins", duration=10, seed=1, params={"accel_noise": 0.1, "gyro_noise": 0.005})
    np.testing.assert_allclose((quiet.u_cmd - quiet.u_act).std(axis=0), [0.005] * 3 + [0.1] * 3, rtol=0.10)
    assert quiet.profile_dict()["vehicle"]["params"] == {"accel_noise": 0.1, "gyro_noise": 0.005}


def test_healthy_log_analyses_clean_and_consistent(tmp_path, cli):
    out = tmp_path / "ins.mcap"
    assert cli("simulate", "ins", "--duration", "120", "--seed", "3", "-q", "-o", out).exit_code == 0
    result = cli("analyze", out, "--no-report")
    assert result.exit_code == 0, result.stdout
    assert "no alarms" in result.stdout
    log = read_log(out)
    profile = resolve_profile(log)
    profile.check_channels(log)
    trace = run_ekf(get_model("ins"), align(log, profile), store_gain=False, store_S=False)
    assert set(trace.group_names) == {"gnss_position", "gnss_velocity", "baro", "heading", "attitude"}
    for g, name in enumerate(trace.group_names):
        used = trace.updated[:, g]
        size = int(trace.group_sizes[g])
        assert used.sum() > 1000  # 10 Hz and faster for 120 s
        mean = float(np.mean(trace.nis_group[used, g]))
        assert abs(mean / size - 1.0) < 0.30, (name, mean, size)
    assert not trace.rejected.any() and not trace.diverged.any()


def test_log_layout_profile_and_truth(tmp_path, cli):
    out = tmp_path / "ins.mcap"
    assert cli("simulate", "ins", "--duration", "30", "--seed", "2", "-q", "-o", out).exit_code == 0
    log = read_log(out)
    assert set(IMU) | {
        "/gnss/position.north",
        "/gnss/velocity.down",
        "/baro/altitude",
        "/mag/heading",
        "/mocap/roll",
        "/flight_mode/mode",
        "/setpoint/position.north",
        "/setpoint/position.down",
        "/setpoint/yaw",
        "/ekf/state/baro_offset",
        "/ekf/variance/yaw",
        "/truth/state/accel_bias_x",
    } <= set(log.channels)
    assert not any(ch.startswith("/cmd") or "odometry" in ch for ch in log.channels)
    prof = resolve_profile(log)
    assert prof.vehicle.model == "ins" and prof.vehicle.rate_hz == 250.0
    sim = simulate("ins", duration=30, seed=2)
    doc = sim.profile_dict()
    assert doc["inputs"] == dict(zip(get_model("ins").input_names, IMU))
    rates = {name: m["rate_hz"] for name, m in doc["measurements"].items()}
    assert rates == {"gnss_position": 10.0, "gnss_velocity": 10.0, "baro": 25.0, "heading": 10.0, "attitude": 50.0}
    assert doc["measurements"]["baro"]["noise_std"] == [1.0] and doc["measurements"]["heading"]["stale_s"] == 0.25
    assert doc["mode"] == {"channel": "/flight_mode/mode"}
    assert doc["onboard"] == {"state": "/ekf/state", "variance": "/ekf/variance"}
    assert log.truth["controller_input"] == "none (open-loop reference trajectory)"
    assert log.truth["model"] == "ins" and log.truth["events"] == []
    assert log.channel("/flight_mode/mode").values.size == 301  # 10 Hz
    # mode 1 only while moving: the first move starts after the 25 s hover
    assert np.all(sim.scenario.mode_values[sim.t < 25.0] == 0.0)
    assert sim.scenario.mode_values[(sim.t > 25.0) & (sim.t < 28.0)].min() == 1.0
    heading = sim.z[:, sim.group_slices()["heading"]]
    assert np.nanmax(np.abs(heading)) <= np.pi


def test_imu_bias_fault_corrupts_only_the_logged_imu(tmp_path, cli):
    out = tmp_path / "bias.mcap"
    args = ("simulate", "ins", "--duration", "120", "--seed", "3", "-q", "-o", out)
    result = cli(*args, "--fault", "imu-bias:accel.x:60:70:1.0")
    assert result.exit_code == 0, result.output
    (event,) = read_log(out).truth["events"]
    assert event == {
        "kind": "bias",
        "target": "accel.x",
        "start": 60.0,
        "end": 70.0,
        "magnitude": 1.0,
        "channels": ["/imu/accel.x"],
    }
    healthy = simulate("ins", duration=120, seed=3)
    faulty = simulate("ins", [parse_fault("imu-bias:accel.x:60:70:1.0")], duration=120, seed=3)
    np.testing.assert_array_equal(faulty.x_true, healthy.x_true)  # open loop: the flight is the same
    step = faulty.u_cmd - healthy.u_cmd
    window = (faulty.t >= 60.0) & (faulty.t < 70.0)
    np.testing.assert_allclose(step[window, 3], 1.0, atol=1e-12)
    assert np.abs(step[~window]).max() == 0.0 and np.abs(step[:, [0, 1, 2, 4, 5]]).max() == 0.0
    assert np.abs(faulty.x_hat[window, 12] - healthy.x_hat[window, 12]).max() > 0.2  # the EKF saw it
    result = cli("analyze", out, "--no-report")
    assert result.exit_code == 1 and "nis.gnss_velocity" in result.stdout


def test_sensor_faults_on_aiding_sensors_and_glitches():
    specs = [parse_fault("stuck:baro:10:12"), parse_fault("bias:heading:5:6:0.5"), parse_fault("bias:accel_z:3:4:2")]
    sim = simulate("ins", specs, duration=20, seed=4, glitches_per_min=6)
    z = sim.z[:, sim.group_slices()["baro"]][:, 0]
    stuck = z[(sim.t >= 10.0) & (sim.t < 12.0)]
    stuck = stuck[np.isfinite(stuck)]
    assert stuck.size == 50 and np.all(stuck == stuck[0])
    assert [e.target for e in sim.events] == ["baro", "heading", "accel.z"]
    assert sim.transients and all(e.kind == "bias" for e in sim.transients)
    assert not any(ch.startswith("/imu") for e in sim.transients for ch in e.channels)  # on aiding sensors


@pytest.mark.parametrize(
    "fault, kind",
    [("motor-offset", "actuator-offset"), ("lost-actuator", "lost-actuator"), ("state-corruption", "state-corruption")],
)
def test_actuator_and_estimator_faults_are_refused(fault, kind, cli, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = cli("simulate", "ins", "--fault", fault, "-o", "x.mcap")
    assert result.exit_code == 2
    assert len(result.stderr.strip().splitlines()) == 1
    assert kind in result.stderr and "ins" in result.stderr and "bias" in result.stderr
    assert not (tmp_path / "x.mcap").exists()


def test_same_seed_same_bytes_other_seed_other_bytes(tmp_path, cli):
    paths = [tmp_path / name for name in ("a.mcap", "b.mcap", "c.mcap")]
    for path, seed in zip(paths, ("7", "7", "8")):
        args = ("simulate", "ins", "--duration", "25", "--seed", seed, "--fault", "imu-bitflip", "--at", "21")
        assert cli(*args, "--glitches", "4", "-q", "-o", path).exit_code == 0
    a, b, c = (p.read_bytes() for p in paths)
    assert a == b and a != c


def test_help_mentions_ins(cli):
    out = cli("simulate", "--help").output
    assert "ins" in out and "ins 250" in out.replace("\n", " ").replace("  ", " ")
