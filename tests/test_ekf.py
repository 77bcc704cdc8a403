"""The shared EKF core: agreement with the numpy reference, P stays SPD, bad samples are
skipped and flagged, divergence is reported and recovered, the filter is consistent (NIS)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_model_contract import LINEAR_PARAMS as _LINEAR_BASE

from logscan.align import AlignedGroup, AlignedRun
from logscan.errors import ModelError
from logscan.filters import EkfTrace, run_ekf
from logscan.filters.ekf import pack_run
from logscan.filters.reference import reference_ekf
from logscan.models import get_model

LINEAR_PARAMS = dict(_LINEAR_BASE, Q=[[1e-3, 0.0], [0.0, 1e-2]], R={"pos": [0.05], "mix": [0.1, 0.1]})
# group -> period in steps (multi-rate)
RATES = {
    "quadcopter": {"accel": 1, "gyro": 1, "position": 10, "attitude": 5},
    "steer_by_wire": {"steering_angle": 1, "yaw_rate": 2, "lateral_accel": 1},
    "dc_motor": {"encoder": 5, "gps_speed": 10, "current": 1},
    "linear": {"pos": 1, "mix": 3},
}


def _inputs(model, N, dt, rng):
    t = np.arange(N) * dt
    if model.name == "quadcopter":
        u = np.tile(model.hover_input(), (N, 1))
        u[:, 0] *= 1.0 + 0.05 * np.sin(0.7 * t)
        u[:, 1] = 0.002 * np.sin(1.3 * t)
        u[:, 2] = 0.002 * np.cos(0.9 * t)
        u[:, 3] = 0.001 * np.sin(0.5 * t)
        return u
    if model.name == "steer_by_wire":
        return (20.0 * np.sin(0.8 * t))[:, None]
    if model.name == "dc_motor":
        return np.where(t < N * dt / 2, 10.0, 18.0)[:, None]
    return np.sin(t)[:, None] + 0.1 * rng.normal(size=(N, 1))


def simulate(name, params=None, N=300, dt=0.01, seed=0, noise=1.0, rates=None):
    """Truth with process noise w ~ N(0, Q) and measurements with noise ~ N(0, R), multi-rate."""
    model = get_model(name, params)
    rng = np.random.default_rng(seed)
    u = _inputs(model, N, dt, rng)
    Q = model.default_Q(dt)
    Lq = np.linalg.cholesky(Q)
    n = model.n_states
    x = np.zeros(n)
    truth = np.zeros((N, n))
    rates = rates or RATES[name]
    zs = {g: np.full((N, model.groups[g].size), np.nan) for g in rates}
    fresh = {g: np.arange(N) % period == 0 for g, period in rates.items()}
    for k in range(N):
        if k > 0:
            x = model.f(x, u[k], dt) + noise * (Lq @ rng.normal(size=n))
        truth[k] = x
        for g in rates:
            if fresh[g][k]:
                Lr = np.linalg.cholesky(model.default_R(g))
                v = Lr @ rng.normal(size=model.groups[g].size)
                zs[g][k] = model.h(g, x, u[k]) + noise * v
    groups = {g: AlignedGroup(g, list(model.groups[g].outputs), zs[g], fresh[g]) for g in rates}
    run = AlignedRun(
        t=np.arange(N) * dt,
        dt=dt,
        start_ns=0,
        u=u,
        u_fresh=np.ones(N, bool),
        input_channels=list(model.input_names),
        groups=groups,
    )
    return model, run, truth


CASES = [("quadcopter", None), ("steer_by_wire", None), ("dc_motor", None), ("linear", LINEAR_PARAMS)]


@pytest.mark.parametrize(("name", "params"), CASES)
def test_kernel_matches_numpy_reference_on_every_model(name, params):
    model, run, truth = simulate(name, params, N=300)
    # one NaN and one bit-flipped value to exercise the rejection path in both
    first = next(iter(run.groups.values()))
    first.z[40, 0] = np.nan
    first.z[80, 0] = 1e20
    first.fresh[40] = first.fresh[80] = True
    trace = run_ekf(model, run, full_P=True)
    ref = reference_ekf(model, pack_run(model, run))
    for key in ("x_prior", "x_post"):
        assert np.max(np.abs(getattr(trace, key) - ref[key])) < 1e-9
    assert np.max(np.abs(trace.P_prior - ref["P_prior"])) < 1e-9
    assert np.max(np.abs(trace.P_post - ref["P_post"])) < 1e-9
    np.testing.assert_allclose(trace.y, ref["y"].astype(np.float32), rtol=1e-6, atol=1e-9)  # kept as float32
    np.testing.assert_allclose(trace.nis, ref["nis"], rtol=1e-7, atol=1e-9)
    for key in ("updated", "rejected", "seeded", "diverged"):
        np.testing.assert_array_equal(getattr(trace, key), ref[key])
    assert trace.rejected[40, 0] and trace.rejected[80, 0]
    assert trace.updated.any()


def test_kernel_matches_reference_through_a_divergence_and_reseeding():
    model, run, truth = simulate("quadcopter", N=200, seed=3)
    run.u[100, 1] = 1e200  # absurd roll torque: the covariance overflows
    trace = run_ekf(model, run, full_P=True)
    ref = reference_ekf(model, pack_run(model, run))
    assert trace.diverged[100] and ref["diverged"][100]
    assert np.max(np.abs(trace.x_post - ref["x_post"])) < 1e-9
    assert np.max(np.abs(trace.P_post - ref["P_post"])) < 1e-9
    np.testing.assert_array_equal(trace.seeded, ref["seeded"])


def test_trace_fields_have_documented_shapes():
    model, run, _ = simulate("quadcopter", N=120)
    trace = run_ekf(model, run, full_P=True)
    N, n, G, m = 120, 12, 4, 12
    assert isinstance(trace, EkfTrace)
    for key in ("x_prior", "x_post", "P_prior_diag", "P_post_diag"):
        assert getattr(trace, key).shape == (N, n)
    assert trace.P_prior.shape == trace.P_post.shape == (N, n, n)
    assert trace.y.shape == trace.S_diag.shape == (N, m)
    assert trace.S.shape == (N, m, m) and trace.K.shape == (N, n, m)
    assert trace.nis.shape == trace.gain_norm.shape == trace.m_k.shape == (N,)
    for key in ("nis_group", "updated", "rejected", "seeded"):
        assert getattr(trace, key).shape == (N, G)
    assert trace.group_names == ["accel", "gyro", "position", "attitude"]
    assert trace.group_slice("position") == slice(6, 9)
    # y, S, K are NaN exactly where the group did not update
    pos = trace.group_slice("position")
    upd = trace.updated[:, trace.group_index("position")]
    assert np.all(np.isnan(trace.y[~upd, pos])) and np.all(np.isfinite(trace.y[upd, pos]))
    assert np.all(np.isnan(trace.K[~upd][:, :, pos]))
    assert np.all(trace.m_k == (trace.updated * trace.group_sizes).sum(axis=1))
    light = run_ekf(model, run, store_gain=False, store_S=False)
    assert light.K is None and light.S is None and light.P_prior is None
    np.testing.assert_array_equal(light.x_post, trace.x_post)
    with pytest.raises(ModelError, match="no group"):
        trace.group_slice("gps")


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**31 - 1),
    noise=st.floats(0.0, 5.0),
    torque=st.floats(-0.05, 0.05),
    thrust_scale=st.floats(0.5, 1.5),
)
def test_covariance_stays_symmetric_positive_definite(seed, noise, torque, thrust_scale):
    model, run, _ = simulate("quadcopter", N=150, seed=seed, noise=noise)
    run.u[:, 0] *= thrust_scale
    run.u[:, 1:] += torque
    trace = run_ekf(model, run, full_P=True, store_gain=False, store_S=False)
    assert not trace.diverged.any()
    for P in (trace.P_prior, trace.P_post):
        np.testing.assert_allclose(P, np.swapaxes(P, 1, 2), rtol=0, atol=1e-12 * np.abs(P).max())
        assert np.linalg.eigvalsh(P).min() > 0.0


def test_nan_and_bit_flipped_samples_are_skipped_flagged_and_harmless():
    model, run, truth = simulate("quadcopter", N=400, seed=5)
    clean = run_ekf(model, run)
    accel = run.groups["accel"]
    bad = {50: np.nan, 51: 1e20, 52: -3e38, 53: np.inf}
    for k, value in bad.items():
        accel.z[k, 1] = value
    run.groups["position"].z[100, 2] = 1e20
    trace = run_ekf(model, run)
    g_acc = trace.group_index("accel")
    assert sorted(np.flatnonzero(trace.rejected[:, g_acc])) == sorted(bad)
    assert trace.rejected[100, trace.group_index("position")]
    assert trace.summary()["rejected"] == {"accel": 4, "gyro": 0, "position": 1, "attitude": 0}
    assert not trace.updated[list(bad), g_acc].any()
    assert np.all(np.isfinite(trace.x_post)) and not trace.diverged.any()
    # skipping five samples barely moves the estimate
    assert np.max(np.abs(trace.x_post[-1] - clean.x_post[-1])) < 0.05


def test_forced_divergence_is_reported_once_and_the_filter_recovers():
    model, run, truth = simulate("quadcopter", N=600, seed=9)
    run.u[300, 1] = 1e200
    trace = run_ekf(model, run)
    assert trace.diverged[300]
    assert len(trace.divergence_episodes) == 1
    episode = trace.divergence_episodes[0]
    assert episode.start_step == 300 and episode.n_steps == trace.diverged.sum()
    assert np.all(np.isfinite(trace.x_post)) and np.all(np.isfinite(trace.P_post_diag))
    # re-seeded from the next valid direct measurements (position arrives every 10 steps)
    seeded_steps = np.flatnonzero(trace.seeded.any(axis=1))
    assert np.any((seeded_steps >= 300) & (seeded_steps <= 310))
    assert np.max(np.abs(trace.x_post[-1, :3] - truth[-1, :3])) < 1.0
    assert np.max(np.abs(trace.x_post[-1, 6:9] - truth[-1, 6:9])) < 0.1


def test_non_positive_definite_S_is_divergence():
    model, run, _ = simulate("linear", LINEAR_PARAMS, N=50)
    trace = run_ekf(
        model, run, R={"pos": [[-1.0]], "mix": np.diag([0.01, 0.01])}, P0=np.diag([1e-6, 1e-6]), Q=np.diag([1e-9, 1e-9])
    )
    assert trace.diverged.any()
    assert trace.summary()["divergence_episodes"] >= 1
    assert np.all(np.isfinite(trace.x_post))


def test_start_without_x0_seeds_directly_observed_states():
    model, run, truth = simulate("quadcopter", N=50, seed=2)
    trace = run_ekf(model, run)
    assert trace.seeded[0].all() == False  # accel observes no state directly  # noqa: E712
    assert trace.seeded[0, trace.group_index("position")]
    np.testing.assert_allclose(trace.x_post[0, :3], run.groups["position"].z[0], atol=1e-12)
    trace_x0 = run_ekf(model, run, x0=np.zeros(12))
    assert not trace_x0.seeded.any()


def test_filter_is_consistent_with_the_simulated_noise():
    model, run, _ = simulate("quadcopter", N=3000, seed=11)
    trace = run_ekf(model, run, x0=np.zeros(12), P0=np.eye(12) * 1e-4, store_gain=False)
    burn = 100
    for g, name in enumerate(trace.group_names):
        upd = trace.updated[burn:, g]
        mean_nis = np.mean(trace.nis_group[burn:, g][upd])
        assert abs(mean_nis / model.groups[name].size - 1.0) < 0.1, (name, mean_nis)
    assert abs(np.nanmean(trace.nis[burn:] / trace.m_k[burn:]) - 1.0) < 0.1


def test_input_gaps_hold_the_last_input_and_bad_shapes_are_rejected():
    model, run, _ = simulate("steer_by_wire", N=100)
    run.u[10:20] = np.nan
    trace = run_ekf(model, run)
    assert trace.input_held[10:20].all() and trace.input_held.sum() == 10
    assert np.all(np.isfinite(trace.x_post))
    bad = AlignedRun(
        t=run.t,
        dt=run.dt,
        start_ns=0,
        u=np.zeros((100, 2)),
        u_fresh=run.u_fresh,
        input_channels=["a", "b"],
        groups=run.groups,
    )
    with pytest.raises(ModelError, match="takes 1 inputs"):
        run_ekf(model, bad)
    run.groups["nope"] = AlignedGroup("nope", ["c"], np.zeros((100, 1)), np.ones(100, bool))
    with pytest.raises(ModelError, match="no measurement group 'nope'"):
        run_ekf(model, run)


def test_kernel_matches_reference_with_correlated_measurement_noise():
    """A full (non-diagonal) R block exercises the sparse K R product of the Joseph update."""
    model, run, _ = simulate("quadcopter", N=200, seed=7)
    R_acc = np.diag(np.square(model.groups["accel"].noise_std))
    R_acc[0, 1] = R_acc[1, 0] = 0.3 * np.sqrt(R_acc[0, 0] * R_acc[1, 1])
    R_gyro = np.diag(np.square(model.groups["gyro"].noise_std))
    R_gyro[1, 2] = R_gyro[2, 1] = -0.2 * np.sqrt(R_gyro[1, 1] * R_gyro[2, 2])
    R = {"accel": R_acc, "gyro": R_gyro}
    trace = run_ekf(model, run, R=R, full_P=True)
    ref = reference_ekf(model, pack_run(model, run, R=R))
    assert np.max(np.abs(trace.x_post - ref["x_post"])) < 1e-9
    assert np.max(np.abs(trace.P_post - ref["P_post"])) < 1e-9
    assert np.max(np.abs(trace.P_prior - ref["P_prior"])) < 1e-9
    np.testing.assert_allclose(trace.nis, ref["nis"], rtol=1e-7, atol=1e-9)
    # the kernel's covariances are exactly symmetric
    np.testing.assert_array_equal(trace.P_post, np.swapaxes(trace.P_post, 1, 2))
    np.testing.assert_array_equal(trace.P_prior[1:], np.swapaxes(trace.P_prior[1:], 1, 2))
