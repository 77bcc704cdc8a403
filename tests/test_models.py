"""Vehicle models, their own physics: hover, mixer, DC-motor time constants, exact
discretisation, the quadcopter's block RK4 Jacobian, registry errors. The checks every model
passes (Jacobians, shapes, h/H consistency, parameter round trip) are in test_model_contract.py."""

from __future__ import annotations

import numpy as np
import pytest
from test_model_contract import central_jacobian, random_point, work_arrays

from logscan.errors import ModelError
from logscan.models import MODEL_NAMES, dispatch, get_model, rk4


def test_quadcopter_hovers_and_accel_reads_gravity_reaction():
    model = get_model("quadcopter")
    x = np.zeros(12)
    u = model.hover_input()
    np.testing.assert_allclose(model.f(x, u, 0.01), x, atol=1e-12)
    np.testing.assert_allclose(model.h("accel", x, u), [0.0, 0.0, 9.81], atol=1e-12)
    # free fall: thrust 0 -> specific force 0 at rest
    np.testing.assert_allclose(model.h("accel", x, np.zeros(4)), 0.0, atol=1e-12)
    # free fall with linear drag: vz(t) = -(g m / kD) (1 - exp(-kD t / m))
    tau = model.p["mass"] / model.p["drag"]
    vz = -9.81 * tau * (1.0 - np.exp(-0.1 / tau))
    assert model.f(x, np.zeros(4), 0.1)[5] == pytest.approx(vz, rel=1e-8)


def test_quadcopter_mixer_round_trip_and_motor_inputs_match_wrench_inputs():
    wrench_model = get_model("quadcopter")
    motor_model = get_model("quadcopter", {"inputs": "motors"})
    assert motor_model.input_names == ("w1", "w2", "w3", "w4")
    wrench = np.array([12.0, 0.05, -0.03, 0.01])
    omega = motor_model.wrench_to_motors(wrench)
    np.testing.assert_allclose(motor_model.motors_to_wrench(omega), wrench, rtol=1e-12)
    rng = np.random.default_rng(0)
    x = rng.normal(size=12) * 0.2
    np.testing.assert_allclose(motor_model.f(x, omega, 0.01), wrench_model.f(x, wrench, 0.01))
    np.testing.assert_allclose(motor_model.h("accel", x, omega), wrench_model.h("accel", x, wrench))
    # a weaker motor 1 (on +x) pitches the nose: tau_y = L (T3 - T1) > 0
    weak = omega.copy()
    weak[0] *= 0.9
    assert motor_model.motors_to_wrench(weak)[2] > wrench[2]


def test_dc_motor_time_constant_and_top_speed_are_physical():
    model = get_model("dc_motor")
    slow = -max(np.linalg.eigvals(model._A).real)
    assert 0.1 < 1.0 / slow < 0.5  # a few tenths of a second with the reflected inertia
    i_a, w_v = model.steady_state(24.0)
    assert 1.8 < w_v * model.p["wheel_radius"] < 2.3  # Jackal top speed ~2 m/s
    # exact discretisation: stable at 10 Hz although La/Ra = 0.44 ms
    F = model.F(np.zeros(2), np.zeros(1), 0.1)
    assert max(abs(np.linalg.eigvals(F))) < 1.0


def test_linear_discrete_matrices_are_used_as_given_and_dt_must_match():
    params = {"A": [[1.0, 0.1], [0.0, 1.0]], "B": [[0.0], [0.1]], "C": [[1.0, 0.0]], "continuous": False, "dt": 0.1}
    model = get_model("linear", params)
    np.testing.assert_allclose(model.f([1.0, 2.0], [3.0], 0.1), [1.2, 2.3])
    with pytest.raises(ModelError, match="discrete at dt"):
        model.f([1.0, 2.0], [3.0], 0.01)


def test_registry_lists_models_and_rejects_unknown_names_and_params():
    assert set(MODEL_NAMES) == {"quadcopter", "steer_by_wire", "dc_motor", "linear"}
    with pytest.raises(ModelError, match="unknown vehicle model 'hexacopter'") as err:
        get_model("hexacopter")
    assert "known models: quadcopter, steer_by_wire, dc_motor, linear" in err.value.one_line()
    with pytest.raises(ModelError, match="unknown parameter"):
        get_model("quadcopter", {"mas": 1.0})
    with pytest.raises(ModelError, match="not a number"):
        get_model("steer_by_wire", {"V": "fast"})
    with pytest.raises(ModelError, match="must be > 0"):
        get_model("dc_motor", {"La": 0.0})
    with pytest.raises(ModelError, match="inputs"):
        get_model("quadcopter", {"inputs": "rotors"})
    with pytest.raises(ModelError, match="has no measurement group"):
        get_model("quadcopter").h("gps", np.zeros(12), np.zeros(4))
    with pytest.raises(ModelError, match="B has"):
        get_model("linear", {"A": [[0.0]], "B": [[1.0], [2.0]], "C": [[1.0]]})
    with pytest.raises(ModelError, match="C is missing"):
        get_model("linear", {"A": [[0.0]], "B": [[1.0]]})


def test_exact_discretisation_of_Q_matches_quadrature_on_a_stiff_model():
    from scipy.integrate import quad_vec
    from scipy.linalg import expm

    model = get_model("dc_motor")
    dt = 0.01
    p = model.p
    Qc = np.diag([(p["q_voltage"] / p["La"]) ** 2, (p["q_torque"] / model.Jv) ** 2])
    A = model._A
    Q_ref = quad_vec(lambda s: expm(A * s) @ Qc @ expm(A * s).T, 0.0, dt, epsabs=1e-14)[0]
    np.testing.assert_allclose(model.default_Q(dt), Q_ref, rtol=1e-6)


@pytest.mark.parametrize("params", [None, {"inputs": "motors"}])
def test_quadcopter_block_rk4_jacobian_equals_generic_path_and_finite_differences(params):
    """predict_into's quadcopter branch (3x3-block RK4 Jacobian) gives the generic RK4 path's
    x_next and F to the last bit (work arrays filled with NaN: nothing stale is read), and F
    matches central differences of the RK4 step."""
    model = get_model("quadcopter", params)
    p = model.param_vector()
    rng = np.random.default_rng(11)
    n = 12
    for k in range(30):
        x, u = random_point(model, rng)
        dt = (0.002, 0.01, 0.05)[k % 3]
        x_gen, F_gen = np.full(n, np.nan), np.full((n, n), np.nan)
        x_blk, F_blk = np.full(n, np.nan), np.full((n, n), np.nan)
        rk4.rk4_predict_into(model.model_id, p, x, u, dt, x_gen, F_gen, *work_arrays(n))
        dispatch.predict_into(model.model_id, p, x, u, dt, x_blk, F_blk, *work_arrays(n))
        np.testing.assert_array_equal(x_blk, x_gen)
        np.testing.assert_array_equal(F_blk, F_gen)
        assert np.abs(F_blk - np.eye(n)).max() > 0.0
        F_num = central_jacobian(lambda xx: dispatch.f_disc(model.model_id, p, xx, u, dt), x)
        scale = max(1.0, np.abs(F_blk).max())
        np.testing.assert_allclose(F_blk, F_num, atol=1e-6 * scale, rtol=1e-6)
