"""Fault injection of `logscan simulate`: parsing, defaults, and each kind's effect on the run."""

from __future__ import annotations

import numpy as np
import pytest

from logscan.errors import UsageError
from logscan.simulate import parse_fault, simulate
from logscan.simulate.controllers import control
from logscan.simulate.faults import ALL_NAMES, FaultSpec
from logscan.simulate.runner import _bitflip

DURATION = 20.0
START, END = 8.0, 12.0


@pytest.fixture(scope="module")
def healthy():
    return simulate("quadcopter", duration=DURATION, seed=11)


def _run(*faults: str):
    return simulate("quadcopter", [parse_fault(f) for f in faults], duration=DURATION, seed=11)


def _window(sim, start=START, end=END):
    t = sim.t
    return (t >= start - 1e-9) & (t < end - 1e-9)


def _gyro_x(sim):
    """(steps where the gyro sampled, measured gyro x, true body rate p) of a run."""
    col = sim.group_slices()["gyro"].start
    steps = np.flatnonzero(np.isfinite(sim.z[:, col]))
    return steps, sim.z[steps, col], sim.x_true[steps, 9]


def test_parse_short_and_colon_forms():
    assert parse_fault("imu-bias") == FaultSpec("imu-bias")
    assert parse_fault("bias:gyro.x:30:40:0.5") == FaultSpec("bias", "gyro.x", 30.0, 40.0, 0.5)
    assert parse_fault("bitflip::12::") == FaultSpec("bitflip", None, 12.0, None, None)


@pytest.mark.parametrize("text", ["nosuchfault", "bias:a:b:c:d", "bias:x:1:2:3:4"])
def test_parse_rejects_bad_text_with_one_line(text):
    with pytest.raises(UsageError) as info:
        parse_fault(text)
    assert "\n" not in info.value.one_line()


def test_unknown_kind_lists_the_kinds():
    with pytest.raises(UsageError) as info:
        parse_fault("glitch")
    assert all(name in info.value.one_line() for name in ALL_NAMES)


@pytest.mark.parametrize(
    "fault, words",
    [
        ("bias:accel.x:25:30:1", "outside the log"),
        ("bias:accel.x:5:4:1", "not after its start"),
        ("bias:nosuch.x:5:6:1", "unknown sensor target"),
        ("actuator-offset:motor9:5:6:0.1", "unknown actuator"),
        ("state-corruption:speed:5:6:1", "unknown estimator state"),
    ],
)
def test_bad_fault_targets_and_times_are_usage_errors(fault, words):
    with pytest.raises(UsageError, match=words):
        _run(fault)


def test_defaults_imu_bias_is_one_on_accel_x_from_half_the_log():
    sim = simulate("quadcopter", [parse_fault("imu-bias")], duration=DURATION, seed=1)
    (event,) = sim.events
    assert (event.kind, event.target, event.magnitude) == ("bias", "accel.x", 1.0)
    assert event.t_start == DURATION / 2
    assert event.channels == ("/imu/accel.x",)


def test_defaults_bitflip_burst_and_motor_offset():
    sim = simulate("quadcopter", [parse_fault("imu-bitflip"), parse_fault("motor-offset")], duration=DURATION, seed=1)
    flips, motor = sim.events
    assert flips.kind == "bitflip" and flips.t_end - flips.t_start == pytest.approx(1.2)
    assert (motor.kind, motor.target, motor.magnitude) == ("actuator-offset", "motor1", -0.10)


def test_bitflip_flips_one_bit_of_the_float32():
    assert _bitflip(1.0, 31) == -1.0  # sign bit
    assert _bitflip(1.0, 23) == 0.5  # lowest exponent bit of 1.0 (exponent 127 -> 126)
    assert _bitflip(2.0, 29) == 2.0 ** (1 + 64)  # exponent 128 -> 192: the 1e20-like value
    assert not np.isfinite(_bitflip(1.0, 30))  # exponent 127 -> 255


def test_bias_is_added_only_inside_its_window():
    sim = _run(f"bias:gyro.x:{START}:{END}:0.5")
    steps, z, p = _gyro_x(sim)
    inside = _window(sim)[steps]
    residual = z - p
    assert abs(residual[inside].mean() - 0.5) < 0.01
    assert abs(residual[~inside].mean()) < 0.01


def test_drift_grows_linearly_from_its_start():
    sim = _run(f"drift:gyro.x:{START}:{END}:0.2")
    steps, z, p = _gyro_x(sim)
    inside = _window(sim)[steps]
    expected = 0.2 * (sim.t[steps][inside] - START)
    assert np.abs((z - p)[inside] - expected).max() < 0.06  # 6 sigma of the 0.01 gyro noise


def test_random_is_uniform_within_its_magnitude():
    sim = _run(f"random:gyro.x:{START}:{END}:0.3")
    steps, z, p = _gyro_x(sim)
    residual = (z - p)[_window(sim)[steps]]
    assert np.abs(residual).max() < 0.3 + 0.05
    assert residual.std() == pytest.approx(0.3 / np.sqrt(3.0), rel=0.15)


def test_stuck_holds_the_last_value_before_its_start():
    sim = _run(f"stuck:gyro.x:{START}:{END}:0")
    steps, z, _ = _gyro_x(sim)
    inside = _window(sim)[steps]
    before = z[np.flatnonzero(inside)[0] - 1]
    assert np.all(z[inside] == before)
    assert np.ptp(z[~inside]) > 0


def test_bitflip_burst_gives_impossible_values_that_the_onboard_ekf_rejects(healthy):
    sim = _run(f"bitflip:accel.x:{START}:{START + 1.2}:1.0")
    col = sim.group_slices()["accel"].start
    inside = _window(sim, START, START + 1.2)
    assert not np.all(np.isfinite(sim.z[inside, col]) & (np.abs(sim.z[inside, col]) < 160))
    assert sim.rejected > 0 and healthy.rejected == 0
    assert np.all(np.isfinite(sim.x_hat))  # the on-board filter survived
    outside = ~inside & np.isfinite(sim.z[:, col])
    assert np.all(np.abs(sim.z[outside, col]) < 160)


def test_actuator_offset_and_lost_actuator_change_delivered_not_commanded_thrust(healthy):
    M_inv = np.linalg.inv(healthy.scenario.M)
    for fault, expected in (
        (f"actuator-offset:motor2:{START}:{END}:-0.1", 0.9),
        (f"lost-actuator:motor2:{START}:{START + 0.5}:0", 0.0),
    ):
        sim = _run(fault)
        motors_cmd = sim.u_cmd @ M_inv.T
        motors_act = sim.u_act @ M_inv.T
        end = END if expected else START + 0.5
        inside = _window(sim, START, end)
        np.testing.assert_allclose(motors_act[inside, 1], expected * motors_cmd[inside, 1], atol=1e-9)
        np.testing.assert_allclose(motors_act[~inside], motors_cmd[~inside], atol=1e-9)


def _controller_outputs(sim) -> np.ndarray:
    """(N, inputs) the fault-free controller's output at every step, replayed on the run's own
    logged estimates (the controller reads the posterior of the step before)."""
    sc = sim.scenario
    cs, u = sc.ctrl_state.astype(np.float64).copy(), np.zeros(sim.u_cmd.shape[1])
    out = np.empty_like(sim.u_cmd)
    for k in range(sim.n_steps):
        xh = sc.x0.astype(np.float64) if k == 0 else sim.x_hat[k - 1]
        control(sc.ctrl_id, sc.ctrl_params.astype(np.float64), cs, sc.reference[k], xh, sc.dt, u)
        out[k] = u
    return out


@pytest.mark.parametrize("fault", [f"control-fault:tau_x:{START}:{END}:0.5", f"control-stuck:tau_x:{START}:{END}:"])
def test_a_control_fault_changes_the_controller_output_during_its_window_only(healthy, fault):
    sim = _run(fault)
    k0 = int(round(START / sim.dt))
    np.testing.assert_array_equal(sim.u_cmd[:k0], healthy.u_cmd[:k0])
    intended = _controller_outputs(sim)
    inside = _window(sim)
    expected = intended.copy()
    expected[inside, 1] = 1.5 * intended[inside, 1] if fault.startswith("control-fault") else intended[k0 - 1, 1]
    # the vehicle logs and flies the faulty output (no actuator limit reached here)
    np.testing.assert_allclose(sim.u_cmd, expected, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(sim.u_act, sim.u_cmd, rtol=1e-9, atol=1e-9)
    assert (
        np.abs(expected[inside, 1] - intended[inside, 1]).max() > 1e-3
    )  # the fault did act (torques near hover are small)
    event = sim.truth()["events"][0]
    assert (event["target"], event["channels"]) == ("tau_x", ["/cmd/tau.x"])


@pytest.mark.parametrize(
    "model, fault, words",
    [
        ("quadcopter", "control-fault:yaw", "unknown controller output"),
        ("ins", "control-stuck", "closed-loop controller"),
    ],
)
def test_a_control_fault_needs_a_controller_output(model, fault, words):
    with pytest.raises(UsageError) as info:
        simulate(model, [parse_fault(fault)], duration=DURATION, seed=1)
    assert words in info.value.one_line()


def test_cov_corruption_scales_only_the_logged_variance(healthy):
    sim = _run(f"cov-corruption:vx:{START}:{END}:100")
    inside = _window(sim)
    np.testing.assert_allclose(sim.P_diag[inside, 3], 100 * healthy.P_diag[inside, 3], rtol=1e-12)
    np.testing.assert_array_equal(sim.P_diag[~inside], healthy.P_diag[~inside])
    np.testing.assert_array_equal(sim.x_true, healthy.x_true)  # the vehicle did not notice


def test_state_corruption_shifts_the_estimate_once_and_the_vehicle_reacts(healthy):
    sim = _run(f"state-corruption:x:{START}:{END}:2.0")
    k = int(round(START / sim.dt))
    assert np.array_equal(sim.x_hat[:k], healthy.x_hat[:k])
    assert sim.x_hat[k, 0] - healthy.x_hat[k, 0] == pytest.approx(2.0, abs=1e-9)
    # the controller flew on the corrupted estimate: the true position moved away
    assert np.abs(sim.x_true[k:, 0] - healthy.x_true[k:, 0]).max() > 0.5


def test_glitches_are_healthy_transients_not_fault_events():
    sim = simulate("dc_motor", duration=120, seed=3, glitches_per_min=3.0)
    truth = sim.truth()
    assert truth["events"] == []
    assert len(truth["transients"]) >= 2
    redundant = set(sim.scenario.redundant["speed"].values())
    radius = sim.scenario.model.p["wheel_radius"]
    slices = sim.group_slices()
    for glitch in truth["transients"]:
        assert glitch["kind"] == "glitch" and glitch["channels"][0] in redundant
        assert 0 < glitch["end"] - glitch["start"] <= 0.2 + 1e-9
        group = "gps_speed" if glitch["target"] == "gps_speed" else "encoder"
        col = slices[group].start + (glitch["target"] == "encoder.v_right")
        k = int(np.ceil(glitch["start"] / sim.dt - 1e-9))
        k += -k % sim.scenario.groups[list(slices).index(group)].ratio  # first sample in the window
        residual = sim.z[k, col] - radius * sim.x_true[k, 1]
        std = sim.scenario.groups[list(slices).index(group)].noise_std[0]
        assert residual == pytest.approx(glitch["magnitude"], abs=4 * std)
