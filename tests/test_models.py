"""Vehicle models, their own physics: hover, mixer, DC-motor time constants, exact
discretisation, the quadcopter's block RK4 Jacobian, registry errors, parameter checks (every
problem at once; Q positive semi-definite, R positive definite). The checks every model
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
    assert set(MODEL_NAMES) == {
        "quadcopter",
        "steer_by_wire",
        "dc_motor",
        "linear",
        "hover_uav",
        "ins",
        "unicycle",
        "wheeled",
    }
    with pytest.raises(ModelError, match="unknown vehicle model 'hexacopter'") as err:
        get_model("hexacopter")
    assert "known models: quadcopter, steer_by_wire, dc_motor, linear, hover_uav" in err.value.one_line()
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


# ------------------------------------------------------------------------------------------------
# Parameter checks: every problem at once, covariances positive (semi-)definite
# ------------------------------------------------------------------------------------------------

LINEAR_OK = {
    "A": [[0.0, 1.0], [0.0, -0.5]],
    "B": [[0.0], [1.0]],
    "C": {"pos": [[1.0, 0.0]], "both": [[1.0, 0.0], [0.0, 1.0]]},
}

BAD_LINEAR = [
    ({"R": {"pos": float("nan")}}, "R[pos] standard deviations must be > 0 and finite, got nan"),
    ({"R": {"pos": [0.0]}}, "R[pos] standard deviations must be > 0 and finite, got 0"),
    ({"R": {"pos": [[-1.0]]}}, "R[pos] is not positive definite (smallest eigenvalue -1)"),
    ({"R": {"both": [[1.0, 2.0], [2.0, 1.0]]}}, "R[both] is not positive definite (smallest eigenvalue -1)"),
    ({"R": {"both": [[1.0, 0.5], [0.0, 1.0]]}}, "R[both] is not symmetric"),
    ({"R": {"both": [[1.0]]}}, "R[both] is not 2 x 2"),
    ({"R": {"both": [0.1, 0.1, 0.1]}}, "R[both] gives 3 standard deviations for 2 outputs"),
    ({"R": {"gps": [0.1]}}, "R given for group 'gps' but C has no such group (groups: pos, both)"),
    ({"R": [[0.1]]}, "R must be a table group -> value (groups: pos, both)"),
    ({"Q": [[1.0, 0.0], [0.0, -1e-3]]}, "Q is not positive semi-definite (smallest eigenvalue -0.001)"),
    ({"Q": [[1.0, 1.0], [0.0, 1.0]]}, "Q is not symmetric"),
    ({"Q": [[1.0, 0.0], [0.0, float("inf")]]}, "Q has non-finite entries"),
    ({"Q": [[1.0]]}, "Q has 1 rows, expected 2"),
    ({"D": {"vel": [[1.0]]}}, "D given for group 'vel' but C has no such group (groups: pos, both)"),
    ({"range": {"pos": [1.0, -1.0]}}, "range[pos] needs finite lo < hi, got [1.0, -1.0]"),
    ({"range": {"pos": [float("-inf"), 1.0]}}, "range[pos] needs finite lo < hi"),
    ({"range": {"pos": 5.0}}, "range[pos] must be [lo, hi], each a number or 1 numbers"),
    ({"states": ["p", "p"]}, "states names 'p' twice"),
    ({"states": ["p"]}, "states has 1 names for 2 columns of the matrices"),
    ({"inputs": ["f", 3]}, "inputs must be an array of names"),
    ({"outputs": {"both": ["a", "a"]}}, "outputs[both] names 'a' twice"),
    ({"dt": float("nan")}, "dt must be a finite number > 0 (seconds), got nan"),
    ({"dt": 0}, "dt must be a finite number > 0 (seconds), got 0"),
    ({"continuous": "yes"}, "continuous must be true or false, got 'yes'"),
    ({"continuous": False}, "discrete matrices need `dt` (their period in s)"),
    ({"A": [[0.0, 1.0]]}, "A must be square, got 1 x 2"),
    ({"C": {}}, "C has no group"),
    ({"C": {"pos": [[1.0, 0.0, 0.0]]}}, "C[pos] has 3 columns, expected 2"),
]


@pytest.mark.parametrize("change, message", BAD_LINEAR, ids=[m[:40] for _, m in BAD_LINEAR])
def test_linear_model_refuses_a_bad_parameter(change, message):
    with pytest.raises(ModelError) as err:
        get_model("linear", {**LINEAR_OK, **change})
    assert err.value.problems[0].startswith(f"linear model: {message}")


def test_linear_model_lists_every_problem_at_once():
    params = {**LINEAR_OK, "Q": [[1.0, 0.0], [0.0, -1.0]], "dt": -1, "R": {"pos": [[-1.0]]}, "inputs": ["a", "b"]}
    with pytest.raises(ModelError) as err:
        get_model("linear", params)
    assert len(err.value.problems) == 4
    assert err.value.message.endswith("(3 more)")


def test_linear_model_accepts_a_positive_definite_covariance_and_std():
    model = get_model("linear", {**LINEAR_OK, "R": {"both": [[0.04, 0.01], [0.01, 0.09]], "pos": 0.3}})
    np.testing.assert_allclose(model.default_R("both"), [[0.04, 0.01], [0.01, 0.09]])
    np.testing.assert_allclose(model.default_R("pos"), [[0.09]])
    assert model.covariance_problems(0.01) == []


def test_covariance_tolerances_are_relative_to_the_matrix_scale():
    from logscan.models.base import covariance_problem

    tiny = 1e-20 * np.array([[1.0, 1.0], [1.0, 1.0 + 1e-15]])  # PSD up to rounding, at any scale
    assert covariance_problem(tiny, "Q", definite=False) is None
    assert covariance_problem(1e20 * tiny, "Q", definite=False) is None
    assert "not positive definite" in covariance_problem(tiny, "R", definite=True)
    assert covariance_problem(np.diag([1e-20, 2e-20]), "R", definite=True) is None
    assert "not positive semi-definite" in covariance_problem(np.diag([1e-20, -1e-25]), "Q", definite=False)
    assert "not positive definite" in covariance_problem(np.zeros((2, 2)), "R", definite=True)
    assert "square" in covariance_problem(np.zeros((2, 3)), "Q", definite=False)


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_default_noise_of_every_model_is_a_valid_covariance(name):
    params = LINEAR_OK if name == "linear" else None
    assert get_model(name, params).covariance_problems(0.01) == []


def test_physical_parameters_are_checked_together():
    with pytest.raises(ModelError) as err:
        get_model("quadcopter", {"mass": 0.0, "drag": -0.1, "q_accel": float("nan"), "Izz": "heavy"})
    assert err.value.problems == [
        "model 'quadcopter': parameter q_accel = nan is not finite",
        "model 'quadcopter': parameter Izz = 'heavy' is not a number",
    ]
    with pytest.raises(ModelError) as err:
        get_model("quadcopter", {"mass": 0.0, "drag": -0.1})
    assert err.value.problems == [
        "quadcopter: parameter mass must be > 0 (got 0.0)",
        "quadcopter: parameter drag must be >= 0 (got -0.1)",
    ]
    with pytest.raises(ModelError, match="q_gamma must be >= 0"):
        get_model("steer_by_wire", {"q_gamma": -1.0})
    with pytest.raises(ModelError, match="q_torque must be >= 0"):
        get_model("dc_motor", {"q_torque": -1.0})
    # finite but absurd: the process noise overflows, the covariance check names it
    assert get_model("quadcopter", {"q_accel": 1e200}).covariance_problems(0.01) == [
        "model 'quadcopter': process noise Q at dt = 0.01 s has non-finite entries"
    ]
