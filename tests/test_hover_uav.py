"""The hover_uav model (the UBIKF paper's linearised hover quadcopter with interval parameters) and
`logscan simulate hover_uav` with the paper's two fault scenarios."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from logscan.models import get_model
from logscan.models.hover_uav import INTERVAL_PARAMS
from logscan.readers import read_log
from logscan.simulate import FaultSpec, simulate
from logscan.simulate.faults import PAPER_SETTLE_S

DT = 0.01
G = 9.81


def test_continuous_matrices_at_nominal_parameters_follow_the_quadcopter_conventions():
    model = get_model("hover_uav")
    A, B = model._A, model._B
    expected_A = np.zeros((12, 12))
    for i in range(3):
        expected_A[i, 3 + i] = 1.0
        expected_A[6 + i, 9 + i] = 1.0
    expected_A[3, 7] = G  # vx' = g pitch
    expected_A[4, 6] = -G  # vy' = -g roll
    for i in (3, 4, 5):
        expected_A[i, i] = -0.25 / 1.2  # linear drag / mass
    np.testing.assert_array_equal(A, expected_A)
    m, Ixx, Iyy, Izz, arm, k = 1.2, 0.0212, 0.0212, 0.0392, 0.3, 0.0245
    expected_B = np.zeros((12, 4))
    expected_B[5] = 1.0 / m
    expected_B[9] = np.array([-1, 1, 1, -1]) * arm / Ixx
    expected_B[10] = np.array([-1, -1, 1, 1]) * arm / Iyy
    expected_B[11] = np.array([1, -1, 1, -1]) * k / Izz
    np.testing.assert_allclose(B, expected_B, rtol=1e-15)


def test_hover_is_an_equilibrium_and_each_rotor_pushes_the_right_way():
    model = get_model("hover_uav")
    x0, u0 = np.zeros(12), np.zeros(4)
    np.testing.assert_array_equal(model.f(x0, u0, DT), x0)  # zero deviations: it stays
    # more thrust on every rotor: climbs, no rotation
    up = model.f(x0, np.full(4, 0.1), DT)
    assert up[5] > 0 and up[2] > 0 and np.abs(up[6:12]).max() < 1e-15
    # rotor 2 (front left) alone lifts the left side (+roll, tau_x > 0) and the nose (-pitch,
    # tau_y < 0); its reaction torque is -z
    x = model.f(x0, np.array([0.0, 1.0, 0.0, 0.0]), DT)
    assert x[9] > 0 and x[10] < 0 and x[11] < 0
    # the quadcopter's small-angle signs: +pitch accelerates towards +x, +roll towards -y
    tilted = np.zeros(12)
    tilted[7] = 0.1
    a = 0.25 / 1.2  # drag / mass: the velocity integrates the tilt through e^{-a t}
    assert model.f(tilted, u0, DT)[3] == pytest.approx(G * 0.1 * (1 - np.exp(-a * DT)) / a, rel=1e-9)
    tilted = np.zeros(12)
    tilted[6] = 0.1
    assert model.f(tilted, u0, DT)[4] == pytest.approx(-G * 0.1 * (1 - np.exp(-a * DT)) / a, rel=1e-9)
    # the same signs as the quadcopter model's nonlinear dynamics near hover: the wrench of a
    # thrust step on rotor i (through the hover_uav's mixer), and a small tilt at hover thrust
    quad = get_model("quadcopter", {"drag": 0.0})
    hover = quad.hover_input()
    for i in range(4):
        du = np.zeros(4)
        du[i] = 0.1
        q_next = quad.f(np.zeros(12), hover + model.mixer_matrix() @ du, DT)
        h_next = model.f(np.zeros(12), du, DT)
        np.testing.assert_allclose(h_next[[5, 9, 10, 11]], q_next[[5, 9, 10, 11]], rtol=0.02, atol=1e-12)
    for angle in (6, 7):
        tilted = np.zeros(12)
        tilted[angle] = 0.01
        np.testing.assert_allclose(model.f(tilted, u0, DT)[3:5], quad.f(tilted, hover, DT)[3:5], rtol=0.02, atol=1e-9)


def _box_corners(model):
    box = model.parameter_box()
    names = list(box)
    return [dict(zip(names, c)) for c in itertools.product(*(box[k] for k in names))]


def _inside(M, mid, rad):
    tol = 1e-9 * (np.abs(mid) + rad) + 1e-12
    return np.all(np.abs(M - mid) <= rad + tol)


def test_interval_model_encloses_the_vertices_and_random_parameter_sets():
    model = get_model("hover_uav")
    im = model.interval_model(DT)
    im.check()
    assert set(INTERVAL_PARAMS) == set(model.parameter_box())
    # drag / mass moves A, vel_scale C, and mass, inertias, arm and k_yaw B
    assert im.A_r.max() > 0 and im.B_r.max() > 0 and im.C_r.max() > 0
    assert np.flatnonzero(im.C_r.max(axis=1)).tolist() == [3, 4, 5]  # the velocity rows
    assert not model.interval_widened  # every entry monotone: the vertices enclose the box
    for corner in _box_corners(model):
        Ad, Bd, C = model.point_system(DT, **corner)
        assert _inside(Ad, im.A_m, im.A_r) and _inside(Bd, im.B_m, im.B_r) and _inside(C, im.C_m, im.C_r), corner
    rng = np.random.default_rng(7)
    box = model.parameter_box()
    for _ in range(300):
        values = {k: rng.uniform(lo, hi) for k, (lo, hi) in box.items()}
        Ad, Bd, C = model.point_system(DT, **values)
        assert _inside(Ad, im.A_m, im.A_r) and _inside(Bd, im.B_m, im.B_r) and _inside(C, im.C_m, im.C_r), values
    # the enclosure is tight: every entry's bounds are reached at some vertex
    corners = [model.discrete_AB(DT, **c)[1] for c in _box_corners(model)]
    np.testing.assert_allclose(np.max(corners, axis=0), im.B_m + im.B_r, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(np.min(corners, axis=0), im.B_m - im.B_r, rtol=1e-12, atol=1e-18)


def test_interval_model_outside_the_box_is_not_enclosed_and_widths_follow_the_profile():
    """The enclosure test can fail: a parameter set outside the box leaves the interval."""
    model = get_model("hover_uav")
    im = model.interval_model(DT)
    Ad, Bd = model.discrete_AB(DT, mass=1.2 * 0.8)
    assert not _inside(Bd, im.B_m, im.B_r)
    wider = get_model("hover_uav", {"mass_rel": 0.2}).interval_model(DT)
    assert _inside(Bd, wider.B_m, wider.B_r)
    exact = get_model("hover_uav", dict.fromkeys(set(INTERVAL_PARAMS.values()), 0.0)).interval_model(DT)
    assert exact.B_r.max() == 0.0
    np.testing.assert_allclose(exact.B_m, model.discrete_AB(DT)[1], rtol=1e-14)


def test_interval_model_noise_and_measurement_rows_are_the_point_models():
    model = get_model("hover_uav")
    im = model.interval_model(DT)
    assert im.group_names == ("position", "velocity", "attitude")
    assert im.group_offsets.tolist() == [0, 3, 6] and im.group_sizes.tolist() == [3, 3, 3]
    np.testing.assert_allclose(im.C_m, np.eye(12)[:9], rtol=1e-15)
    np.testing.assert_allclose(im.C_r, 0.05 * np.eye(12)[:9] * (np.arange(9) // 3 == 1)[:, None], rtol=1e-12)
    assert im.Q_r.max() == 0 and im.R_r.max() == 0
    np.testing.assert_array_equal(im.Q_m, model.default_Q(DT))
    np.testing.assert_allclose(np.diag(im.R_m), [0.25] * 3 + [0.01] * 3 + [0.0004] * 3, rtol=1e-12)
    assert np.count_nonzero(im.R_m - np.diag(np.diag(im.R_m))) == 0
    np.linalg.cholesky(im.P0)
    assert im.x0.shape == (12,)


def _unobservable_modes(A, C, stable_below=1.0 - 1e-9):
    """Eigenvalues |lambda| >= 1 of A failing the PBH test rank [lambda I - A; C] = n."""
    n = A.shape[0]
    bad = []
    for lam in np.linalg.eigvals(A):
        if abs(lam) < stable_below:
            continue
        M = np.vstack([lam * np.eye(n) - A, C])
        if np.linalg.matrix_rank(M, tol=1e-9) < n:
            bad.append(lam)
    return bad


def test_mid_model_is_detectable_with_the_default_groups_and_position_and_attitude_alone():
    im = get_model("hover_uav").interval_model(DT)
    assert _unobservable_modes(im.A_m, im.C_m) == []
    assert _unobservable_modes(im.A_m, np.vstack([im.C_m[0:3], im.C_m[6:9]])) == []
    # the check itself can fail: attitude alone cannot see position
    assert _unobservable_modes(im.A_m, im.C_m[6:9])
    # and the UBIKF's own check agrees (it refuses an undetectable model)
    from logscan.filters.detectability import unobservable_unstable_states

    assert unobservable_unstable_states(im) == []


def test_parameter_problems_are_model_errors():
    from logscan.errors import ModelError

    with pytest.raises(ModelError, match="mass must be > 0"):
        get_model("hover_uav", {"mass": 0.0})
    with pytest.raises(ModelError, match="inertia_rel must be < 1"):
        get_model("hover_uav", {"inertia_rel": 1.0})
    with pytest.raises(ModelError, match="unknown parameter"):
        get_model("hover_uav", {"mas": 1.0})


# --- `logscan simulate hover_uav` ---------------------------------------------------------------


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_healthy_hover_analyses_without_alarm(seed, tmp_path, cli):
    out = tmp_path / "h.mcap"
    assert cli("simulate", "hover_uav", "--seed", str(seed), "--duration", "40", "-q", "-o", out).exit_code == 0
    profile = read_log(out).source.metadata["logscan.profile"]["toml"]
    assert "mass_rel" in profile and "inertia_rel" in profile and "arm_rel" in profile
    result = cli("analyze", out, "--no-report")
    assert result.exit_code == 0, result.output
    assert "no alarms" in result.output


def test_hover_flies_level_and_the_attitude_is_excited_after_the_settle_time():
    sim = simulate("hover_uav", duration=30, seed=4)
    t = sim.t
    settle = t < PAPER_SETTLE_S
    assert np.abs(sim.x_true[settle, 6:8]).max() < 0.03  # hover: level
    excited = t > PAPER_SETTLE_S + 2.0
    assert np.abs(sim.x_true[excited, 6]).max() > 0.08 and np.abs(sim.x_true[excited, 7]).max() > 0.08
    assert np.abs(sim.x_true[:, :3]).max() < 1.0  # it holds its position
    assert np.sqrt(np.mean((sim.x_hat - sim.x_true)[:, 6:9] ** 2)) < 0.02
    assert {g.rate_hz for g in sim.scenario.groups} == {100.0}


def _alarms(path, detector=None):
    from logscan.pipeline import analyze_log

    return [a for a in analyze_log(path).alarms if detector is None or a.detector == detector]


def _nis_alarms(path):
    return _alarms(path, "nis")


def _paper_run(tmp_path, cli, fault, seed=2):
    out = tmp_path / f"{fault}.mcap"
    result = cli("simulate", "hover_uav", "--fault", fault, "--seed", str(seed), "--duration", "20", "-o", out)
    assert result.exit_code == 0, result.output
    truth = json.loads(read_log(out).source.metadata["logscan.truth"]["json"])
    return out, result, truth


def test_roll_bias_scenario_is_samples_30_to_70_after_the_settle_time_and_raises_nis(tmp_path, cli):
    out, result, truth = _paper_run(tmp_path, cli, "roll-bias")
    (event,) = truth["events"]
    assert event["kind"] == "bias" and event["target"] == "attitude.roll" and event["magnitude"] == 0.1
    assert event["start"] == pytest.approx(PAPER_SETTLE_S + 0.30)
    assert event["end"] == pytest.approx(PAPER_SETTLE_S + 0.71)
    sim = simulate("hover_uav", [FaultSpec("roll-bias")], duration=20, seed=2)
    roll = sim.group_slices()["attitude"].start
    clean = simulate("hover_uav", duration=20, seed=2)
    k0 = int(round(PAPER_SETTLE_S / DT))
    biased = np.flatnonzero(np.abs(sim.z[:, roll] - clean.z[:, roll]) > 1e-12)
    assert biased[0] == k0 + 30 and biased.max() >= k0 + 70 and sim.faults.end[0] == k0 + 71
    alarms = _nis_alarms(out)
    assert alarms and min(a.start for a in alarms) <= PAPER_SETTLE_S + 0.71
    assert all(PAPER_SETTLE_S + 0.30 <= a.start for a in alarms)


def test_rotor_loss_scenario_stops_rotor1_from_sample_31_and_raises_nis(tmp_path, cli):
    out, result, truth = _paper_run(tmp_path, cli, "rotor-loss")
    (event,) = truth["events"]
    assert event["kind"] == "lost-actuator" and event["target"] == "rotor1"
    assert event["start"] == pytest.approx(PAPER_SETTLE_S + 0.31) and event["end"] == 20.0
    sim = simulate("hover_uav", [FaultSpec("rotor-loss")], duration=20, seed=2)
    k = int(round(PAPER_SETTLE_S / DT)) + 31
    hover = sim.scenario.model.hover_thrust()
    assert sim.u_act[k - 1, 0] > -hover + 0.5
    # total thrust 0 from k = 31 on (the fault ends with the log: its last step, at t = end, is out)
    np.testing.assert_allclose(sim.u_act[k:-1, 0], -hover)
    alarms = _nis_alarms(out)
    first = min(a.start for a in alarms)
    assert PAPER_SETTLE_S + 0.31 <= first <= PAPER_SETTLE_S + 0.5


@pytest.mark.parametrize(
    "fault",
    [
        "bias:position.x:10:15:2.0",
        "drift:velocity.y:10:20:0.5",
        "random:attitude.yaw:10:15:0.3",
        "bitflip:/mocap/position.z:10:11.2",
        "stuck:attitude.roll:10:11",
        "actuator-offset:rotor2:10:15:-0.3",
        "lost-actuator:rotor3:10:11",
        "motor-offset",
    ],
)
def test_generic_fault_kinds_act_on_its_sensors_and_rotors(fault, tmp_path, cli):
    out = tmp_path / "f.mcap"
    result = cli("simulate", "hover_uav", "--fault", fault, "--duration", "20", "--seed", "3", "-q", "-o", out)
    assert result.exit_code == 0, result.output
    truth = json.loads(read_log(out).source.metadata["logscan.truth"]["json"])
    (event,) = truth["events"]
    assert event["kind"] == fault.split(":")[0].replace("motor-offset", "actuator-offset")
    start = event["start"]
    # bit flips mostly give impossible values: the rejected-sample check catches them, not NIS; a
    # stuck sensor is the frozen-sensor check's (NIS's 100-hour thresholds no longer see this one)
    alarms = _alarms(out) if event["kind"] in ("bitflip", "stuck") else _nis_alarms(out)
    assert any(start <= a.start <= event["end"] + 1.0 for a in alarms), (fault, alarms)


def test_actuator_faults_act_on_the_total_rotor_thrust():
    sim = simulate("hover_uav", [FaultSpec("actuator-offset", "rotor2", 10.0, 15.0, -0.5)], duration=20, seed=3)
    hover = sim.scenario.model.hover_thrust()
    k = int(round(12.0 / DT))
    assert sim.u_act[k, 1] == pytest.approx((hover + sim.u_cmd[k, 1]) * 0.5 - hover)


def test_a_non_monotone_entry_is_found_and_its_interval_widened():
    from logscan.models.interval_model import enclose_over_box

    (pair,), widened = enclose_over_box(lambda a: (np.array([a * (1.0 - a), a]),), {"a": (0.0, 1.0)})
    mid, rad = pair
    assert widened  # both vertices give 0 for a (1 - a), the inside up to 0.25
    assert mid[0] - rad[0] <= 0.0 and mid[0] + rad[0] >= 0.25
    np.testing.assert_allclose([mid[1], rad[1]], [0.5, 0.5])  # a monotone entry keeps the vertex hull


def test_plant_draw_flies_an_off_nominal_plant_inside_the_intervals():
    from logscan.errors import UsageError

    sim = simulate("hover_uav", duration=20, seed=6, plant_draw=True)
    drawn = sim.truth()["plant_params"]
    box = sim.scenario.model.parameter_box()
    assert set(drawn) == set(box) and all(box[k][0] <= v <= box[k][1] for k, v in drawn.items())
    assert sim.profile_dict()["vehicle"]["params"]["mass"] == 1.2  # the profile stays nominal
    # the velocity sensor reads through the drawn scale factor: z = vel_scale v + noise
    vel = sim.group_slices()["velocity"]
    v, z = sim.x_true[:, 3:6].ravel(), sim.z[:, vel].ravel()
    scale = float(v @ z / (v @ v))
    assert abs(scale - drawn["vel_scale"]) < 0.2 * abs(drawn["vel_scale"] - 1.0)
    # and the truth's dynamics are the drawn plant's, not the nominal one's
    nominal = simulate("hover_uav", duration=20, seed=6)
    assert np.abs(nominal.x_true - sim.x_true).max() > 1e-3
    with pytest.raises(UsageError, match="--plant-draw needs a model with interval parameters"):
        simulate("quadcopter", duration=5, seed=1, plant_draw=True)
