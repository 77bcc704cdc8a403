"""The model contract, checked on every registered model (like the detector contract test).

Parametrised over `logscan.models.MODEL_NAMES` (a model without example parameters here is built
with none): shapes of states, inputs, groups and defaults; F against central differences of f and
H against central differences of h per group, both through the model's box-plus / box-minus (plain
differences unless the state holds a rotation); the in-place kernels the EKF runs against the
allocating ones; box-plus and box-minus inverse to each other; directly observed states;
parameters round-tripping through `describe()`; the model id known to the dispatch, and an unknown
id raising a clear error at both levels.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from logscan.align import AlignedGroup, AlignedRun
from logscan.errors import ModelError
from logscan.filters import run_ekf
from logscan.models import MODEL_NAMES, dispatch, get_model, model_class

LINEAR_PARAMS = {
    "A": [[0.0, 1.0], [-2.0, -0.5]],
    "B": [[0.0], [1.0]],
    "C": {"pos": [[1.0, 0.0]], "mix": [[1.0, 1.0], [0.0, 2.0]]},
    "D": {"mix": [[0.5], [0.0]]},
    "Q": [[1e-4, 0.0], [0.0, 1e-3]],
}
# a model without inputs, as `logscan init-profile` writes one for a CSV (B with zero columns)
ZERO_INPUT_PARAMS = {
    "states": ["level", "drift"],
    "A": [[-0.5, 1.0], [0.0, -0.1]],
    "B": [[], []],
    "C": {"level": [[1.0, 0.0]], "both": [[1.0, 1.0]]},
    "Q": [[1e-4, 0.0], [0.0, 1e-3]],
}
# registered name -> parameter sets the contract is checked with (default: one set, None)
EXAMPLE_PARAMS = {
    "quadcopter": [None, {"inputs": "motors"}],
    "linear": [LINEAR_PARAMS, ZERO_INPUT_PARAMS],
}
CASES = [
    pytest.param(name, params, id=f"{name}-{i}")
    for name in MODEL_NAMES
    for i, params in enumerate(EXAMPLE_PARAMS.get(name, [None]))
]
UNKNOWN_ID = 99


def random_point(model, rng):
    """A state twice the model's typical scale and an input around its nominal one (the hover
    input of a flying model, scattered by 20 %; otherwise zero, scattered by 5)."""
    x = rng.normal(size=model.n_states) * model.state_scale() * 2.0
    if hasattr(model, "hover_input"):
        nominal = model.hover_input()
        spread = np.where(nominal == 0.0, 0.05, 0.0)
        return x, nominal * (1.0 + 0.2 * rng.normal(size=nominal.size)) + spread * rng.normal(size=nominal.size)
    return x, rng.normal(size=model.n_inputs) * 5.0


def central_jacobian(fun, x, eps=1e-6):
    cols = [(fun(x + eps * e) - fun(x - eps * e)) / (2 * eps) for e in np.eye(x.size)]
    return np.column_stack(cols)


def healthy_run(model, N):
    """N steps at the default state with every group fresh and exact."""
    x, u = model.default_x0(), np.zeros(model.n_inputs)
    groups = {
        name: AlignedGroup(name, list(spec.outputs), np.tile(model.h(name, x, u), (N, 1)), np.ones(N, bool))
        for name, spec in model.groups.items()
    }
    return AlignedRun(
        t=np.arange(N) * 0.01,
        dt=0.01,
        start_ns=0,
        u=np.zeros((N, model.n_inputs)),
        u_fresh=np.ones(N, bool),
        input_channels=list(model.input_names),
        groups=groups,
    )


def work_arrays(n):
    """predict_into's work arrays kv, xs (n,) and A, J, Jn (n, n), NaN-filled: nothing stale
    may be read."""
    return (
        np.full(n, np.nan),
        np.full(n, np.nan),
        np.full((n, n), np.nan),
        np.full((n, n), np.nan),
        np.full((n, n), np.nan),
    )


@pytest.mark.parametrize(("name", "params"), CASES)
def test_model_id_is_dispatched_under_the_registered_name(name, params):
    model = get_model(name, params)
    assert model.name == name
    assert dispatch.MODEL_IDS[model.model_id] == name


@pytest.mark.parametrize(("name", "params"), CASES)
def test_states_inputs_groups_and_defaults_have_consistent_shapes(name, params):
    model = get_model(name, params)
    n, nu = model.n_states, model.n_inputs
    # a model may have no input (a profile's linear model with B of zero columns): only states
    assert n == len(model.state_names) > 0 and nu == len(model.input_names) >= 0
    assert sorted(g.group_id for g in model.groups.values()) == list(range(len(model.groups)))
    for group_name, spec in model.groups.items():
        assert spec.name == group_name
        assert len(spec.noise_std) == len(spec.range_lo) == len(spec.range_hi) == spec.size
        assert all(lo < hi for lo, hi in zip(spec.range_lo, spec.range_hi))
        assert 1e20 > max(spec.range_hi)  # a bit-flipped 1e20 is outside every range
        idx, gain = spec.direct_map()
        assert idx.shape == gain.shape == spec.wrap_mask().shape == (spec.size,)
        R = model.default_R(group_name)
        assert R.shape == (spec.size, spec.size)
        np.linalg.cholesky(R)
    Q = model.default_Q(0.01)
    assert Q.shape == (n, n)
    np.testing.assert_allclose(Q, Q.T)
    np.linalg.cholesky(Q)
    assert model.default_x0().shape == (n,) and model.state_scale().shape == (n,)
    assert np.all(model.state_scale() > 0)
    np.linalg.cholesky(model.default_P0())
    p = model.param_vector(0.01)
    assert p.dtype == np.float64 and p.ndim == 1 and np.all(np.isfinite(p))
    x, u = random_point(model, np.random.default_rng(0))
    assert model.f(x, u, 0.01).shape == (n,) and model.F(x, u, 0.01).shape == (n, n)
    for group_name, spec in model.groups.items():
        assert model.h(group_name, x, u).shape == (spec.size,)
        assert model.H(group_name, x, u).shape == (spec.size, n)


@pytest.mark.parametrize(("name", "params"), CASES)
@pytest.mark.parametrize("dt", [0.002, 0.01, 0.05])
def test_discrete_jacobian_F_matches_central_differences_of_f(name, params, dt):
    model = get_model(name, params)
    rng = np.random.default_rng(7)
    for _ in range(10):
        x, u = random_point(model, rng)
        F = model.F(x, u, dt)
        fx = model.f(x, u, dt)
        # F is the Jacobian in the model's own chart: d (f(x (+) d) (-) f(x)) / d d at d = 0
        # (plain differences for an additive state; ins rotates its attitude)
        F_num = central_jacobian(lambda d: model.boxminus(model.f(model.boxplus(x, d), u, dt), fx), np.zeros(x.size))
        scale = max(1.0, np.abs(F).max())
        np.testing.assert_allclose(F, F_num, atol=1e-6 * scale, rtol=1e-6)


@pytest.mark.parametrize(("name", "params"), CASES)
def test_measurement_jacobian_H_matches_central_differences_of_h_per_group(name, params):
    model = get_model(name, params)
    rng = np.random.default_rng(11)
    for group in model.groups:
        for _ in range(10):
            x, u = random_point(model, rng)
            H = model.H(group, x, u)
            hx = model.h(group, x, u)
            wrap = model.groups[group].wrap_mask()

            def change(d, group=group, hx=hx, wrap=wrap):  # h(x (+) d) - h(x), angles wrapped
                diff = model.h(group, model.boxplus(x, d), u) - hx
                return np.where(wrap, (diff + np.pi) % (2 * np.pi) - np.pi, diff)

            H_num = central_jacobian(change, np.zeros(x.size))
            np.testing.assert_allclose(H, H_num, atol=1e-6, rtol=1e-6)


@pytest.mark.parametrize(("name", "params"), CASES)
def test_in_place_kernels_equal_the_allocating_ones(name, params):
    """The EKF kernel calls predict_into/meas_into; the simulator and the reference filter call
    predict/h_meas/H_meas: same f, F, h, H (bit for bit where the arithmetic is shared), and
    meas_into writes only its group's rows."""
    model = get_model(name, params)
    rng = np.random.default_rng(4)
    n, dt = model.n_states, 0.01
    p = model.param_vector(dt)
    m_total = sum(g.size for g in model.groups.values())
    for _ in range(20):
        x, u = random_point(model, rng)
        x_next, F = np.full(n, np.nan), np.full((n, n), np.nan)
        dispatch.predict_into(model.model_id, p, x, u, dt, x_next, F, *work_arrays(n))
        f_ref, F_ref = dispatch.predict(model.model_id, p, x, u, dt)
        np.testing.assert_allclose(x_next, f_ref, rtol=1e-13, atol=1e-13)
        np.testing.assert_array_equal(F, F_ref)
        np.testing.assert_array_equal(f_ref, model.f(x, u, dt))
        hx, Hs = np.full(m_total + 1, np.nan), np.full((m_total + 1, n), np.nan)
        r = 1
        for g in model.groups.values():
            dispatch.meas_into(model.model_id, g.group_id, p, x, u, r, hx, Hs, np.empty((3, 3)), np.empty((3, 3, 3)))
            H_ref = dispatch.H_meas(model.model_id, g.group_id, p, x, u)
            h_ref = dispatch.h_meas(model.model_id, g.group_id, p, x, u)
            np.testing.assert_array_equal(Hs[r : r + g.size], H_ref)
            np.testing.assert_allclose(hx[r : r + g.size], h_ref, rtol=1e-13, atol=1e-13)
            r += g.size
        assert np.isnan(hx[0]) and np.all(np.isnan(Hs[0]))  # rows outside the groups untouched


@pytest.mark.parametrize(("name", "params"), CASES)
def test_boxplus_and_boxminus_are_inverse_and_the_kernel_applies_the_same(name, params):
    model = get_model(name, params)
    rng = np.random.default_rng(9)
    p = model.param_vector(0.01)
    boxplus = dispatch.REGISTRY[model.model_id].boxplus_into
    for _ in range(20):
        x, _u = random_point(model, rng)
        dx = rng.normal(size=x.size) * model.state_scale() * 0.5
        moved = model.boxplus(x, dx)
        np.testing.assert_allclose(model.boxminus(moved, x), dx, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(model.boxplus(x, np.zeros(x.size)), x, atol=1e-12)
        out = np.full(x.size, np.nan)
        boxplus.py_func(p, x, dx, out, np.empty((3, 3)), np.empty((3, 3, 3)))  # R3, D3: work
        np.testing.assert_allclose(out, moved, rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize(("name", "params"), CASES)
def test_direct_groups_really_observe_their_states(name, params):
    model = get_model(name, params)
    rng = np.random.default_rng(3)
    for spec in model.groups.values():
        idx, gain = spec.direct_map()
        x, u = random_point(model, rng)
        z = model.h(spec.name, x, u)
        for j in np.flatnonzero(idx >= 0):
            assert z[j] == pytest.approx(gain[j] * x[idx[j]], abs=1e-12)


@pytest.mark.parametrize(("name", "params"), CASES)
def test_parameters_round_trip_through_describe_and_json(name, params):
    model = get_model(name, params)
    described = json.loads(json.dumps(model.describe()))
    assert described["name"] == name and described["params"]
    rebuilt = get_model(name, described["params"])
    for dt in (None, 0.01):
        np.testing.assert_array_equal(rebuilt.param_vector(dt), model.param_vector(dt))
    np.testing.assert_array_equal(rebuilt.default_Q(0.01), model.default_Q(0.01))
    assert json.loads(json.dumps(rebuilt.describe())) == described


@pytest.mark.parametrize(("name", "params"), CASES)
def test_unknown_model_id_is_a_clear_model_error_before_any_kernel_runs(name, params):
    unknown = type("Unregistered", (model_class(name),), {"model_id": UNKNOWN_ID})
    with pytest.raises(ModelError, match=f"model_id {UNKNOWN_ID}") as err:
        unknown(params)
    assert "known model ids: 0 (quadcopter)" in err.value.one_line()
    model = get_model(name, params)
    run = healthy_run(model, N=5)
    trace = run_ekf(model, run)
    assert trace.updated[-1].all() and not trace.diverged.any()  # a sound run
    model.model_id = UNKNOWN_ID  # changed after creation: run_ekf checks again
    with pytest.raises(ModelError, match="no numba kernel dispatches"):
        run_ekf(model, run)


@pytest.mark.parametrize(("name", "params"), CASES)
def test_every_dispatcher_raises_on_an_unknown_model_id(name, params):
    """Inside numba: no dispatcher falls through to another model's functions."""
    model = get_model(name, params)
    n, dt = model.n_states, 0.01
    p = model.param_vector(dt)
    x, u = random_point(model, np.random.default_rng(5))
    m = max(g.size for g in model.groups.values())
    calls = {
        "predict": lambda: dispatch.predict(UNKNOWN_ID, p, x, u, dt),
        "predict_into": lambda: dispatch.predict_into(
            UNKNOWN_ID, p, x, u, dt, np.empty(n), np.empty((n, n)), *work_arrays(n)
        ),
        "f_disc": lambda: dispatch.f_disc(UNKNOWN_ID, p, x, u, dt),
        "h_meas": lambda: dispatch.h_meas(UNKNOWN_ID, 0, p, x, u),
        "H_meas": lambda: dispatch.H_meas(UNKNOWN_ID, 0, p, x, u),
        "meas_into": lambda: dispatch.meas_into(
            UNKNOWN_ID, 0, p, x, u, 0, np.empty(m), np.empty((m, n)), np.empty((3, 3)), np.empty((3, 3, 3))
        ),
    }
    for label, call in calls.items():
        with pytest.raises(ValueError, match=f"{label}: "):
            call()
