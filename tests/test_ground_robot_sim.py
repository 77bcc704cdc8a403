"""`logscan simulate ground_robot`: the checkpointing / roll-forward-recovery paper's hierarchical
robot (unicycle outer loop at 10 Hz, two DC-motor loops at 100 Hz): seeded reproducibility, circle
tracking, attacks exactly in the truth intervals, the on-board EKF's failure under the attack, the
input timing convention, the unicycle model, the hierarchical profile and the sample logs."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from logscan.models import get_model
from logscan.profiles import dumps_toml, parse_profile
from logscan.readers import read_log
from logscan.simulate import simulate, write_simulation
from logscan.simulate.ground_robot_kernels import RobotParams, body_speeds, wheel_references
from logscan.simulate.ground_robot_sim import (
    MOTORS,
    motor_matrices,
    paper_attacks,
    random_attacks,
    simulate_ground_robot,
)

SAMPLES = ("ground_robot_attack.mcap", "ground_robot_healthy.mcap")


@pytest.fixture(scope="module")
def paper():
    return simulate_ground_robot("paper", seed=1)


@pytest.fixture(scope="module")
def logged(tmp_path_factory):
    """The paper scenario without process noise, written and read back as a log."""
    path = tmp_path_factory.mktemp("robot") / "robot.mcap"
    sim = simulate_ground_robot("paper", seed=2, process_noise=False)
    write_simulation(sim, path)
    return sim, read_log(path)


def attacked(t: np.ndarray, events, target: str) -> np.ndarray:
    on = np.zeros(t.size, dtype=bool)
    for e in events:
        if e.target == target:
            on |= (t >= e.t_start - 1e-9) & (t < e.t_end - 1e-9)
    return on


def test_same_seed_same_run_and_another_seed_another():
    a = simulate_ground_robot("random", seed=5)
    b = simulate_ground_robot("random", seed=5)
    c = simulate_ground_robot("random", seed=6)
    for name in ("x_true", "m_true", "u_outer", "voltage", "z_mocap", "z_enc", "x_hat", "m_hat"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert a.events == b.events and a.truth() == b.truth()
    assert a.events != c.events and not np.array_equal(a.z_enc, c.z_enc)


def test_same_seed_gives_the_same_bytes(tmp_path):
    for name in ("one.mcap", "two.mcap"):
        write_simulation(simulate("ground_robot", duration=3.0, seed=4, scenario="healthy"), tmp_path / name)
    assert (tmp_path / "one.mcap").read_bytes() == (tmp_path / "two.mcap").read_bytes()


def test_healthy_robot_tracks_the_circle():
    """RMS distance to x_ref = [2 cos t, 2 sin t] over 15 s: ~0.3 m (the process noise is 0.1 m per
    outer step). The motors follow their references on average (~1 %); not sample by sample: the
    references jump every 0.1 s by the outer controller's reaction to the noisy estimate (std
    ~13 rad/s about means of ~40 and ~50 rad/s) and the paper's PID is slow (RMS error ~16 rad/s)."""
    sim = simulate_ground_robot("healthy", seed=3)
    t = sim.t_outer
    ref = np.column_stack([2.0 * np.cos(t), 2.0 * np.sin(t)])
    rms = np.sqrt(np.mean(np.sum((sim.x_true[:, :2] - ref) ** 2, axis=1)))
    assert rms < 0.5
    w_ref = np.repeat(sim.w_ref, sim.ratio, axis=0)
    speed_error = sim.m_true[:, :, 1] - w_ref
    np.testing.assert_allclose(sim.m_true[200:, :, 1].mean(axis=0), w_ref[200:].mean(axis=0), rtol=0.03)
    assert np.sqrt(np.mean(speed_error[200:] ** 2)) < 25.0
    assert sim.events == [] and sim.truth()["events"] == []


def test_attack_is_in_the_logged_measurements_exactly_in_the_truth_intervals(logged):
    sim, log = logged
    events = sim.events
    # the mocap's attack names the profile group it moves: position (x, y); theta is not attacked
    assert {e.target for e in events} == {"position", "left_motor.encoder", "right_motor.encoder"}
    assert [(e.t_start, e.t_end) for e in events if e.target == "position"] == [(3.25, 5.0), (8.25, 10.0)]
    t_o = log.channels["/mocap/x"].t / 1e9
    truth_x = log.channels["/truth/state/x"].values
    offset = log.channels["/mocap/x"].values - truth_x  # noise 0.1 m, attack +-5 m
    on = attacked(t_o, events, "position")
    np.testing.assert_array_equal(np.abs(offset) > 2.5, on)
    assert np.all(np.sign(offset[on][t_o[on] < 6.0]) > 0) and np.all(np.sign(offset[on][t_o[on] > 6.0]) < 0)
    theta_error = np.angle(
        np.exp(1j * (log.channels["/mocap/theta"].values - log.channels["/truth/state/theta"].values))
    )
    assert np.abs(theta_error).max() < 0.6  # theta is not attacked ([5, 5, 0])
    for motor, side in zip(MOTORS, ("left", "right")):
        enc = log.channels[f"/enc/{side}.w"]
        error = enc.values - log.channels[f"/truth/motors/{motor}.w"].values
        on = attacked(enc.t / 1e9, events, f"{motor}.encoder")
        np.testing.assert_array_equal(np.abs(error) > 1000.0, on)
        assert on.sum() == 350  # 1.75 s twice at 100 Hz


def test_onboard_ekf_error_grows_during_the_attack(paper):
    """The paper's EKF failure: the outer EKF follows the biased mocap (RMS x error ~4.85 m during
    the attacks, against ~0.05 m before)."""
    t = paper.t_outer
    error = paper.x_hat[:, 0] - paper.x_true[:, 0]
    during = attacked(t, paper.events, "position")
    before = t < 3.25
    rms_during = np.sqrt(np.mean(error[during] ** 2))
    rms_before = np.sqrt(np.mean(error[before] ** 2))
    assert rms_during > 3.0 and rms_before < 0.3
    # the motors' KFs follow the 20000 rad/s encoder offset: the applied voltages go wild
    before_inner = np.arange(paper.n_steps) * paper.dt < 3.25
    assert np.abs(paper.voltage).max() > 50 * np.abs(paper.voltage[before_inner]).max()


def test_input_logged_at_t_k_drives_the_step_from_t_k(logged):
    """x_{k+1} = f(x_k, u_k) with u_k logged at t_k: without process noise, u_k reproduces the next
    true state up to the log's 7-digit rounding; u_{k-1} and u_{k+1} do not."""
    _sim, log = logged
    model = get_model("unicycle")
    x = np.column_stack([log.channels[f"/truth/state/{s}"].values for s in ("x", "y", "theta")])
    u = np.column_stack([log.channels["/cmd/outer.v"].values, log.channels["/cmd/outer.w"].values])
    np.testing.assert_array_equal(log.channels["/cmd/outer.v"].t, log.channels["/truth/state/x"].t)

    def miss(shift: int) -> float:
        k = np.arange(1, x.shape[0] - 2)
        pred = np.array([model.f(x[i], u[i + shift], 0.1) for i in k])
        return float(np.abs(pred - x[k + 1]).max())

    assert miss(0) < 1e-4
    assert miss(-1) > 100 * miss(0) and miss(1) > 100 * miss(0)
    # the motors likewise: m_{k+1} = A_d m_k + B_d V_k, V_k logged at t_k
    Ad, Bd = motor_matrices()
    m = np.column_stack([log.channels[f"/truth/motors/left_motor.{s}"].values for s in ("i", "w")])
    V = log.channels["/motor_cmd/left.voltage"].values
    errors = {
        shift: np.abs(m[1:-2] @ Ad.T + np.outer(V[1 + shift : -2 + shift or None], Bd) - m[2:-1]).max()
        for shift in (-1, 0, 1)
    }
    assert errors[0] < 1e-3 * np.abs(m).max() and errors[-1] > 100 * errors[0] and errors[1] > 100 * errors[0]


def test_wheel_references_invert_to_the_body_speeds():
    """Eq. 39 and v = Rw (w_r + w_l) / 2, w = Rw (w_r - w_l) / Lw are inverse; the right wheel is
    the faster one in a left (positive) turn."""
    p = RobotParams(0.01, 10.0, 2.0, 0.5, 3.3, 4.4, 0.05, 0.5, 13.2, 1.525, 0.275, np.inf, 0.1, 1.0, 0.0)
    for v, w in ((2.0, 1.0), (-0.5, 3.0), (0.0, -2.0)):
        left, right = wheel_references(v, w, p)
        assert body_speeds(left, right, p) == pytest.approx((v, w))
    left, right = wheel_references(2.0, 1.0, p)
    assert (left, right) == pytest.approx((35.0, 45.0))


def test_unicycle_step_and_jacobian():
    model = get_model("unicycle")
    x, u, dt = np.array([1.0, -2.0, 0.7]), np.array([1.5, -0.4]), 0.1
    np.testing.assert_allclose(model.f(x, u, dt), x + np.array([1.5 * np.cos(0.7), 1.5 * np.sin(0.7), -0.4]) * dt)
    F = model.F(x, u, dt)
    eps = 1e-6
    F_num = np.column_stack(
        [(model.f(x + eps * e, u, dt) - model.f(x - eps * e, u, dt)) / (2 * eps) for e in np.eye(3)]
    )
    np.testing.assert_allclose(F, F_num, atol=1e-8)
    np.testing.assert_allclose(model.default_Q(0.1), 0.01 * np.eye(3), atol=1e-11)  # the paper's 0.1^2 I at 10 Hz
    np.testing.assert_allclose(model.default_R("mocap"), 0.01 * np.eye(3))
    assert model.groups["mocap"].wrap == (False, False, True)


def test_random_scenarios_draw_one_to_three_anomalies_on_the_three_groups():
    counts = set()
    for seed in range(40):
        attacks = random_attacks(15.0, np.random.default_rng([seed, 2]))
        counts.add(len(attacks))
        for a, b in zip(attacks, attacks[1:]):
            assert b.start >= a.end
        for a in attacks:
            assert 0.5 - 0.01 <= a.end - a.start <= 2.5 + 0.01 and 1.0 <= a.start and a.end <= 15.0
            assert a.offsets and set(a.offsets) <= {"mocap", "left_motor.encoder", "right_motor.encoder"}
            if "mocap" in a.offsets:
                assert all(2.0 <= abs(v) <= 8.0 for v in a.offsets["mocap"][:2]) and a.offsets["mocap"][2] == 0.0
    assert counts == {1, 2, 3}
    assert [a.offsets["mocap"] for a in paper_attacks()] == [(5.0, 5.0, 0.0), (-5.0, -5.0, -0.0)]


def test_profile_has_the_hierarchical_shape_and_each_loop_parses_alone(logged):
    sim, log = logged
    profile = tomllib.loads(sim.profile_toml())
    assert profile["vehicle"] == {"model": "unicycle", "rate_hz": 10.0, "loop": "outer"}
    assert profile["inputs"] == {"v": "/cmd/outer.v", "w": "/cmd/outer.w", "stamp": "start"}
    assert set(profile["loops"]) == set(MOTORS)
    outer = {k: v for k, v in profile.items() if k not in ("loops", "recovery")}
    outer["vehicle"] = {k: v for k, v in outer["vehicle"].items() if k != "loop"}
    parts = [outer] + [{"name": name, **loop} for name, loop in profile["loops"].items()]
    for part in parts:
        parsed = parse_profile(dumps_toml(part))
        parsed.check_channels(log)
    motor = get_model("linear", profile["loops"]["left_motor"]["vehicle"]["params"])
    Ad, Bd = motor_matrices()
    np.testing.assert_allclose(motor.f([1.0, 2.0], [3.0], 0.01), Ad @ [1.0, 2.0] + Bd * 3.0)
    np.testing.assert_allclose(motor.default_Q(0.01), np.diag([0.01, 0.25]))
    assert log.truth["events"] == [e.to_truth() for e in sim.events]


def test_options_that_do_not_apply_are_usage_errors(cli, tmp_path):
    out = tmp_path / "r.mcap"
    result = cli("simulate", "ground_robot", "--fault", "bias", "-o", out)
    assert result.exit_code == 2 and "--fault does not apply to ground_robot" in result.stderr
    result = cli("simulate", "dc_motor", "--scenario", "paper", "-o", out)
    assert result.exit_code == 2 and "--scenario is for ground_robot" in result.stderr
    assert not out.exists()


def test_cli_writes_the_paper_run(cli, tmp_path):
    out = tmp_path / "r.mcap"
    result = cli("simulate", "ground_robot", "--duration", "6", "-o", out)
    assert result.exit_code == 0, result.stderr
    log = read_log(out)
    assert log.truth["scenario"] == "paper" and len(log.truth["events"]) == 3  # the first anomaly only
    assert log.duration_s == pytest.approx(5.99)


@pytest.mark.parametrize("name", SAMPLES)
def test_sample_logs_are_small_and_inspect_reads_them(name, cli, sample):
    path = sample(name)
    assert path.stat().st_size < 300_000
    result = cli("inspect", path)
    assert result.exit_code == 0, result.stderr
    assert "/mocap" in result.stdout and "/enc" in result.stdout and "ground truth: yes" in result.stdout
    log = read_log(path)
    assert log.truth["model"] == "ground_robot"
    assert len(log.truth["events"]) == (6 if "attack" in name else 0)


def test_wheels_coupling_moves_the_robot_with_the_motors_wheel_speeds():
    """The coupled plant kept for study: each 10 ms Euler step of the unicycle uses the motors'
    true wheel speeds (v = Rw (w_r + w_l) / 2, w = Rw (w_r - w_l) / Lw), not the commands."""
    sim = simulate_ground_robot("healthy", seed=1, duration=2.0, coupling="wheels", process_noise=False)
    p = RobotParams(0.01, 10.0, 2.0, 0.5, 3.3, 4.4, 0.05, 0.5, 13.2, 1.525, 0.275, np.inf, 0.1, 1.0, 1.0)
    x = sim.x_true[0].copy()
    for k in range(sim.ratio):
        v, w = body_speeds(sim.m_true[k, 0, 1], sim.m_true[k, 1, 1], p)
        x += np.array([v * np.cos(x[2]), v * np.sin(x[2]), w]) * 0.01
    np.testing.assert_allclose(x, sim.x_true[1], rtol=1e-12, atol=1e-12)
    commanded = get_model("unicycle").f(sim.x_true[0], sim.u_outer[0], 0.1)
    assert np.abs(commanded - sim.x_true[1]).max() > 1e-3
