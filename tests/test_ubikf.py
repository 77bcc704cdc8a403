"""The UBIKF's envelopes are sound: for point systems drawn inside the interval model, the point
filter that uses the UBIKF's gains keeps its covariance below P+ and its estimate inside the
zonotope's hull (docs/algorithms.md section 2); trace(P+) settles; an undetectable model is refused
by name; divergence is flagged and followed by a finite restart."""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg

from logscan.align import AlignedGroup, AlignedRun
from logscan.errors import ModelError
from logscan.filters.ubikf import run_ubikf
from logscan.models.interval_model import IntervalModel

GRAVITY = 9.81
HOVER_STATES = ("x", "y", "z", "vx", "vy", "vz", "roll", "pitch", "yaw", "p", "q", "r")


# ------------------------------------------------------------------------------------------------
# interval systems and the point systems inside them
# ------------------------------------------------------------------------------------------------
def interval_model(A_m, A_r, B_m, B_r, C_m, C_r, Q_m, Q_r, R_m, R_r, group_sizes, dt=0.01, state_names=None):
    sizes = np.asarray(group_sizes, dtype=np.int64)
    n = A_m.shape[0]
    return IntervalModel(
        A_m=A_m, A_r=A_r, B_m=B_m, B_r=B_r, C_m=C_m, C_r=C_r, Q_m=Q_m, Q_r=Q_r, R_m=R_m, R_r=R_r, dt=dt,
        state_names=tuple(state_names or (f"s{i}" for i in range(n))),
        group_names=tuple(f"g{g}" for g in range(sizes.size)),
        group_offsets=np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64),
        group_sizes=sizes,
        x0=np.zeros(n),
        P0=np.eye(n),
    )  # fmt: skip


def random_interval_model(rng, n, m, nu=2):
    """A stable random system with radii 1-10 % of the entries, small interval noise covariances."""
    U, _ = np.linalg.qr(rng.normal(size=(n, n)))
    A_m = U @ np.diag(rng.uniform(0.3, 0.9, size=n)) @ U.T + 0.1 * rng.normal(size=(n, n))
    B_m, C_m = rng.normal(size=(n, nu)), rng.normal(size=(m, n))

    def radius(M):
        return np.abs(M) * rng.uniform(0.01, 0.1, size=M.shape)

    q, r = rng.uniform(0.001, 0.05, size=n), rng.uniform(0.01, 0.5, size=m)
    Q_r = 0.05 * np.sqrt(np.outer(q, q)) * (1 - np.eye(n)) + np.diag(0.1 * q)
    R_r = 0.05 * np.sqrt(np.outer(r, r)) * (1 - np.eye(m)) + np.diag(0.1 * r)
    sizes = [1, m - 1]
    return interval_model(A_m, radius(A_m), B_m, radius(B_m), C_m, radius(C_m), np.diag(q), Q_r, np.diag(r), R_r, sizes)


def hover_matrices(mass, Jx, Jy, Jz, drag, dt):
    """The linearised hover quadcopter (inputs: thrust deviation, three torques), discretised exactly."""
    a = drag / mass
    Ac, Bc = np.zeros((12, 12)), np.zeros((12, 4))
    for i in range(3):
        Ac[i, 3 + i] = 1.0  # position <- velocity
        Ac[3 + i, 3 + i] = -a  # drag
        Ac[6 + i, 9 + i] = 1.0  # attitude <- body rate
    Ac[3, 7], Ac[4, 6] = GRAVITY, -GRAVITY  # vx <- pitch, vy <- roll
    Bc[5, 0], Bc[9, 1], Bc[10, 2], Bc[11, 3] = 1.0 / mass, 1.0 / Jx, 1.0 / Jy, 1.0 / Jz
    E = scipy.linalg.expm(np.block([[Ac, Bc], [np.zeros((4, 16))]]) * dt)
    return E[:12, :12], E[:12, 12:]


HOVER_PARAMETERS = np.array([1.2, 0.0123, 0.0123, 0.0224, 0.1])  # mass, Jx, Jy, Jz, drag
HOVER_SPREAD = np.array([0.05, 0.1, 0.1, 0.1, 0.1])  # +- fraction


def hover_parameter_sets(rng, count):
    """Vertices of the parameter box first, then random parameter sets inside it."""
    corners = np.array(np.meshgrid(*[[-1.0, 1.0]] * 5)).reshape(5, -1).T
    unit = np.concatenate([corners, rng.uniform(-1.0, 1.0, size=(count, 5))])
    return HOVER_PARAMETERS * (1.0 + unit * HOVER_SPREAD)


def hover_interval_model(rng, dt=0.01):
    """[A_d], [B_d] from the discretisation at the parameter box's vertices and inside it
    (elementwise min/max, widened by 5 % of the radius), position at 10 Hz and attitude at 100 Hz."""
    A, B = zip(*(hover_matrices(*theta, dt) for theta in hover_parameter_sets(rng, 200)))
    A, B = np.array(A), np.array(B)
    A_m, A_r = (A.max(0) + A.min(0)) / 2, (A.max(0) - A.min(0)) / 2 * 1.05
    B_m, B_r = (B.max(0) + B.min(0)) / 2, (B.max(0) - B.min(0)) / 2 * 1.05
    C_m = np.zeros((6, 12))
    C_m[:3, :3] = C_m[3:, 6:9] = np.eye(3)
    q = np.array([1e-6] * 3 + [1e-4] * 3 + [1e-6] * 3 + [1e-3] * 3)
    r = np.array([0.05**2] * 3 + [0.01**2] * 3)
    model = interval_model(
        A_m, A_r, B_m, B_r, C_m, np.zeros((6, 12)), np.diag(q), np.diag(0.1 * q), np.diag(r), np.diag(0.1 * r),
        [3, 3], dt, HOVER_STATES,
    )  # fmt: skip
    model = replace(model, P0=np.diag([1.0] * 3 + [0.1] * 6 + [0.01] * 3))
    return model, (A, B), stabilising_feedback(model)


def inside_draws(rng, mid, rad, count):
    """count matrices inside [mid +- rad]: vertices of the entries' box, then entrywise uniform draws."""
    unit = rng.choice([-1.0, 1.0], size=(count, *mid.shape))
    unit[count // 2 :] = rng.uniform(-1.0, 1.0, size=(count - count // 2, *mid.shape))
    return mid + unit * rad


def symmetric_draws(rng, mid, rad, count):
    D = inside_draws(rng, np.zeros_like(mid), rad, count)
    upper = np.triu(D)
    return mid + upper + np.transpose(np.triu(D, 1), (0, 2, 1))


def point_systems(rng, model, count, A_params=None):
    """(A, B, C, Q, R) stacks of point systems inside the model; A_params (A, B stacks of physical
    parameter sets) take the first places when given."""
    A = inside_draws(rng, model.A_m, model.A_r, count)
    B = inside_draws(rng, model.B_m, model.B_r, count)
    if A_params is not None:
        k = min(count // 2, len(A_params[0]))
        A[:k], B[:k] = A_params[0][:k], A_params[1][:k]
    C = inside_draws(rng, model.C_m, model.C_r, count)
    Q = symmetric_draws(rng, model.Q_m, model.Q_r, count)
    R = symmetric_draws(rng, model.R_m, model.R_r, count)
    return A, B, C, Q, R


def stabilising_feedback(model):
    """A discrete LQR gain F of the mid model (u = -F x keeps a hovering vehicle near hover)."""
    A, B = model.A_m, model.B_m
    X = scipy.linalg.solve_discrete_are(A, B, np.eye(model.n), np.eye(B.shape[1]))
    return np.linalg.solve(B.T @ X @ B + np.eye(B.shape[1]), B.T @ X @ A)


def simulated_run(rng, model, N, rates=None, input_scale=1.0, feedback=None):
    """Measurements of the mid system (process and measurement noise) under smooth random inputs
    (plus -feedback x when given: the logged inputs of a closed loop); group g is fresh every
    rates[g] steps."""
    n, nu, m = model.n, model.B_m.shape[1], model.m
    t = np.arange(N) * model.dt
    freq, phase = rng.uniform(0.2, 2.0, size=nu), rng.uniform(0, 2 * np.pi, size=nu)
    u = input_scale * np.sin(2 * np.pi * freq * t[:, None] + phase)
    F = np.zeros((nu, n)) if feedback is None else feedback
    Lq = np.linalg.cholesky(model.Q_m + 1e-15 * np.eye(n))
    Lr = np.linalg.cholesky(model.R_m)
    x = rng.normal(size=n) * np.sqrt(np.diag(model.P0))
    z = np.empty((N, m))
    for k in range(N):  # a test oracle: the reference simulation, not log processing
        if k:
            u[k] -= F @ x
            x = model.A_m @ x + model.B_m @ u[k] + Lq @ rng.normal(size=n)
        z[k] = model.C_m @ x + Lr @ rng.normal(size=m)
    rates = rates or [1] * len(model.group_names)
    groups = {}
    for g, name in enumerate(model.group_names):
        o, size = model.group_offsets[g], model.group_sizes[g]
        fresh = np.arange(N) % rates[g] == 0
        groups[name] = AlignedGroup(name, [f"{name}.{j}" for j in range(size)], z[:, o : o + size], fresh)
    return AlignedRun(t=t, dt=model.dt, start_ns=0, u=u, u_fresh=np.ones(N, bool), input_channels=[], groups=groups)


# ------------------------------------------------------------------------------------------------
# the point filters that use the UBIKF's gains
# ------------------------------------------------------------------------------------------------
def envelope_violations(model, run, trace, systems):
    """Run every point system's filter with the UBIKF's gain sequence (Joseph form with its own
    matrices); count the steps where P+ - P is not PSD or the estimate leaves the hull, and return
    (covariance violations, box violations, envelope fill per state over all steps and after step 100):
    the largest |x - x_mid| / radius seen."""
    A, B, C, Q, R = systems
    S, n = A.shape[0], model.n
    z = np.concatenate([run.groups[name].z for name in model.group_names], axis=1)
    x = np.tile(model.x0, (S, 1))
    P = np.tile(model.P0, (S, 1, 1))
    eye = np.eye(n)
    cov_bad = box_bad = 0
    fill, late_fill = np.zeros(n), np.zeros(n)
    for k in range(run.n_steps):  # test oracle: S point filters side by side
        if k:
            x = np.einsum("sij,sj->si", A, x) + np.einsum("sij,j->si", B, run.u[k])
            P = A @ P @ np.transpose(A, (0, 2, 1)) + Q
        rows = np.flatnonzero(np.isfinite(trace.r_mid[k]))
        if rows.size:
            K = trace.K[k][:, rows]
            Cr = C[:, rows]
            x = x + np.einsum("ia,sa->si", K, z[k, rows] - np.einsum("saj,sj->sa", Cr, x))
            M = eye - np.einsum("ia,saj->sij", K, Cr)
            P = M @ P @ np.transpose(M, (0, 2, 1)) + K @ R[:, rows][:, :, rows] @ K.T
        P_plus = trace.P[k]
        lam = np.linalg.eigvalsh(P_plus - P).min(axis=1)
        cov_bad += int(np.sum(lam < -1e-9 * np.abs(P_plus).max()))
        mid = trace.x_mid[k]
        rad = (trace.x_hi[k] - trace.x_lo[k]) / 2
        dev = np.abs(x - mid)
        box_bad += int(np.sum(np.any(dev > rad + 1e-9 * (np.abs(mid) + rad) + 1e-12, axis=1)))
        fill_k = np.where(rad > 0, dev.max(axis=0) / np.where(rad > 0, rad, 1.0), 0.0)
        fill = np.maximum(fill, fill_k)
        late_fill = np.maximum(late_fill, fill_k) if k >= 100 else late_fill
    return cov_bad, box_bad, fill, late_fill


def test_point_filters_inside_random_interval_systems_stay_inside_the_envelope():
    rng = np.random.default_rng(20261124)
    total = 0
    for n, m in [(4, 2), (5, 3), (6, 2), (6, 3), (5, 2)]:
        model = random_interval_model(rng, n, m)
        run = simulated_run(rng, model, 300, rates=[1, 3])
        trace = run_ubikf(model, run, store_gain=True, store_P=True)
        assert not trace.diverged.any()
        systems = point_systems(rng, model, 48)
        cov_bad, box_bad, fill, late = envelope_violations(model, run, trace, systems)
        assert (cov_bad, box_bad) == (0, 0), f"n={n} m={m}: {cov_bad} covariance, {box_bad} box violations"
        assert fill.max() > 0.05  # the point estimates do spread inside the envelope
        print(
            f"n={n} m={m}: 48 systems x 300 steps, 0 violations, envelope fill {fill.min():.2f}-{fill.max():.2f}"
            f" (after step 100: {late.min():.2f}-{late.max():.2f})"
        )
        total += 48
    assert total >= 200


def test_point_filters_inside_the_hover_quadcopter_interval_model_stay_inside_the_envelope():
    rng = np.random.default_rng(7)
    model, (A_params, B_params), F = hover_interval_model(rng)
    assert model.A_r.max() > 0 and model.B_r.max() > 0
    run = simulated_run(rng, model, 400, rates=[10, 1], input_scale=0.05, feedback=F)
    trace = run_ubikf(model, run, store_gain=True, store_P=True)
    assert not trace.diverged.any()
    # physical parameter sets (box vertices and random ones) first, then entrywise draws
    systems = point_systems(rng, model, 96, A_params=(A_params, B_params))
    cov_bad, box_bad, fill, late = envelope_violations(model, run, trace, systems)
    assert (cov_bad, box_bad) == (0, 0)
    print(
        f"hover: 96 systems x 400 steps, 0 violations, envelope fill {fill.min():.2f}-{fill.max():.2f}"
        f" (after step 100: {late.min():.2f}-{late.max():.2f})"
    )


def test_the_covariance_bound_is_the_kalman_filter_for_a_point_model():
    rng = np.random.default_rng(3)
    model = random_interval_model(rng, 4, 2)
    zero = {name: np.zeros_like(getattr(model, name)) for name in ("A_r", "B_r", "C_r", "Q_r", "R_r")}
    point = replace(model, **zero)
    run = simulated_run(rng, point, 200)
    trace = run_ubikf(point, run, store_gain=True, store_P=True)
    # the envelope of a point model is a point, P+ the Riccati recursion
    assert np.all(trace.x_hi - trace.x_lo < 1e-200)
    P = point.P0.copy()
    for k in range(run.n_steps):
        if k:
            P = point.A_m @ P @ point.A_m.T + point.Q_m
        S = point.C_m @ P @ point.C_m.T + point.R_m
        K = P @ point.C_m.T @ np.linalg.inv(S)
        P = (np.eye(4) - K @ point.C_m) @ P @ (np.eye(4) - K @ point.C_m).T + K @ point.R_m @ K.T
        np.testing.assert_allclose(trace.K[k], K, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(trace.P[k], P, rtol=1e-9, atol=1e-12)


# ------------------------------------------------------------------------------------------------
# behaviour over a long run
# ------------------------------------------------------------------------------------------------
def test_trace_of_P_settles_on_a_stable_detectable_system():
    rng = np.random.default_rng(11)
    model, _, F = hover_interval_model(rng)
    run = simulated_run(rng, model, 6000, rates=[10, 1], input_scale=0.05, feedback=F)
    trace = run_ubikf(model, run)
    assert not trace.diverged.any()
    # settled: the peaks of the 10 Hz saw-tooth are the same over the second and third 2000 steps,
    # far below the start
    middle, late = trace.P_trace[2000:4000], trace.P_trace[4000:]
    assert abs(late.max() - middle.max()) < 1e-6 * late.max()
    assert late.max() < 0.1 * np.trace(model.P0)
    # the envelope stays small too (order reduction keeps the generator count bounded)
    width = (trace.x_hi - trace.x_lo)[3000:]
    assert np.all(width[-1] < 2.0 * width[0] + 1e-12)
    assert trace.n_generators.max() <= 12 + 2 * 60 * (12 + 6)


def test_innovation_box_holds_the_point_nis_and_S():
    rng = np.random.default_rng(5)
    model = random_interval_model(rng, 5, 3)
    run = simulated_run(rng, model, 500, rates=[1, 4])
    trace = run_ubikf(model, run)
    assert np.array_equal(trace.m_k, trace.updated @ model.group_sizes)
    assert np.all(trace.r_rad[0, np.isfinite(trace.r_rad[0])] == 0.0)  # every point filter starts at x0
    for k in (0, 1, 4, 5, 499):
        rows = np.flatnonzero(np.isfinite(trace.r_mid[k]))
        assert rows.size == trace.m_k[k]
        S = trace.S[k][np.ix_(rows, rows)]
        assert np.all(np.isfinite(S)) and np.isnan(trace.S[k]).sum() == model.m**2 - rows.size**2
        r = trace.r_mid[k, rows]
        np.testing.assert_allclose(trace.nis[k], r @ np.linalg.solve(S, r), rtol=1e-10)
        assert k == 0 or np.all(trace.r_rad[k, rows] > 0)
    assert np.isnan(trace.nis[trace.m_k == 0]).all()


def test_an_undetectable_model_is_refused_naming_the_states():
    rng = np.random.default_rng(1)
    model, _, _ = hover_interval_model(rng)
    # attitude only: position and velocity (integrators) are unobservable
    C_m = model.C_m[3:]
    blind = replace(
        model, C_m=C_m, C_r=np.zeros_like(C_m), R_m=model.R_m[3:, 3:], R_r=model.R_r[3:, 3:],
        group_names=("attitude",), group_offsets=np.array([0]), group_sizes=np.array([3]),
    )  # fmt: skip
    run = simulated_run(rng, blind, 10)
    with pytest.raises(ModelError, match="not detectable") as info:
        run_ubikf(blind, run)
    named = info.value.message.split("observe ")[1].split(", ")
    assert set(named) >= {"x", "y", "z"} and not {"roll", "pitch", "yaw", "p", "q", "r"} & set(named)


def test_a_stable_unobserved_state_is_detectable():
    A_m = np.diag([0.9, 0.5])
    model = interval_model(
        A_m, 0.01 * A_m, np.ones((2, 1)), np.zeros((2, 1)), np.array([[1.0, 0.0]]), np.zeros((1, 2)),
        np.eye(2) * 0.01, np.zeros((2, 2)), np.eye(1), np.zeros((1, 1)), [1],
    )  # fmt: skip
    trace = run_ubikf(model, simulated_run(np.random.default_rng(0), model, 50))
    assert np.isfinite(trace.P_trace).all()


def test_divergence_is_flagged_and_the_filter_restarts_with_finite_values():
    rng = np.random.default_rng(2)
    model = random_interval_model(rng, 4, 2)
    run = simulated_run(rng, model, 400)
    run.u[200] = 1e200  # a bit-flipped input
    trace = run_ubikf(model, run)
    assert trace.diverged[200] and trace.diverged.sum() == 1
    assert not trace.updated[200].any() and np.isnan(trace.nis[200])
    np.testing.assert_array_equal(trace.x_mid[200], model.x0)
    after = slice(201, None)
    for values in (trace.x_mid, trace.x_lo, trace.x_hi, trace.P_trace):
        assert np.isfinite(values[after]).all()
    assert np.isfinite(trace.nis[after][trace.m_k[after] > 0]).all()
    # the restart converges back to the healthy filter's statistics
    healthy = run_ubikf(model, simulated_run(np.random.default_rng(2), model, 400))
    np.testing.assert_allclose(trace.P_trace[-1], healthy.P_trace[-1], rtol=1e-6)


def test_non_finite_samples_skip_their_group():
    rng = np.random.default_rng(4)
    model = random_interval_model(rng, 4, 3)
    run = simulated_run(rng, model, 50)
    run.groups["g1"].z[10, 0] = np.nan
    trace = run_ubikf(model, run)
    assert trace.updated[10].tolist() == [True, False] and trace.m_k[10] == 1
    assert not trace.diverged.any()


def test_a_100000_step_12_state_6_measurement_run_stays_bounded():
    """The long run completes without diverging; its speed is measured by bench/bench_timed_checks.py."""
    rng = np.random.default_rng(9)
    model, _, F = hover_interval_model(rng)
    N = 100_000
    run = simulated_run(rng, model, 1000, input_scale=0.05, feedback=F)
    every = np.ones(N, bool)
    groups = {name: replace(g, z=np.tile(g.z, (N // 1000, 1)), fresh=every) for name, g in run.groups.items()}
    run = replace(run, t=np.arange(N) * model.dt, u=np.tile(run.u, (N // 1000, 1)), u_fresh=every, groups=groups)
    run_ubikf(model, simulated_run(rng, model, 20))  # compiled (or loaded from the cache) first
    trace = run_ubikf(model, run)
    assert len(trace.diverged) == N and not trace.diverged.any()


def hover_uav_systems(rng, hover, model, count):
    """(A, B, C, Q, R) stacks inside hover_uav's intervals: vertices of its parameter box (the
    all-low and all-high ones and random others), random parameter sets inside it, then matrices
    drawn entry by entry inside [A], [B], [C] (`point_systems`)."""
    box = hover.parameter_box()
    corners = np.array(list(itertools.product(*box.values())))
    picked = np.concatenate([corners[[0, -1]], corners[rng.choice(len(corners), count - 2, replace=False)]])
    inside = np.array([[rng.uniform(lo, hi) for lo, hi in box.values()] for _ in range(count)])
    physical = [hover.point_system(model.dt, **dict(zip(box, values))) for values in np.concatenate([picked, inside])]
    A, B, C = (np.array(part) for part in zip(*physical))
    drawn = point_systems(rng, model, count)
    stack = [np.concatenate([A, drawn[0]]), np.concatenate([B, drawn[1]]), np.concatenate([C, drawn[2]])]
    Q = np.concatenate([np.tile(model.Q_m, (2 * count, 1, 1)), drawn[3]])
    R = np.concatenate([np.tile(model.R_m, (2 * count, 1, 1)), drawn[4]])
    return (*stack, Q, R)


def test_point_filters_inside_hover_uavs_own_intervals_stay_inside_the_envelope_and_below_the_bound():
    """The shipped model's intervals (drag and mass in A, vel_scale in C, mass, inertias, arm and
    k_yaw in B): 32 vertex systems, 32 random parameter sets and 32 entrywise draws."""
    from logscan.models import get_model

    hover = get_model("hover_uav")
    model = hover.interval_model(0.01)
    assert model.A_r.max() > 0 and model.C_r.max() > 0
    rng = np.random.default_rng(28)
    run = simulated_run(rng, model, 400, input_scale=0.05, feedback=stabilising_feedback(model))
    trace = run_ubikf(model, run, store_gain=True, store_P=True)
    assert not trace.diverged.any()
    systems = hover_uav_systems(rng, hover, model, 32)
    cov_bad, box_bad, fill, late = envelope_violations(model, run, trace, systems)
    assert (cov_bad, box_bad) == (0, 0)
    assert fill.max() > 0.05
    # the bound lies strictly above the point Kalman filter of the mid model (same gains' optimum)
    P = model.P0.copy()
    ratios = []
    for k in range(run.n_steps):
        if k:
            P = model.A_m @ P @ model.A_m.T + model.Q_m
        S = model.C_m @ P @ model.C_m.T + model.R_m
        K = np.linalg.solve(S, model.C_m @ P).T
        P = (np.eye(12) - K @ model.C_m) @ P @ (np.eye(12) - K @ model.C_m).T + K @ model.R_m @ K.T
        if k >= 100:
            assert np.linalg.eigvalsh(trace.P[k] - P).min() > -1e-9 * np.abs(trace.P[k]).max()
            ratios.append(trace.P_trace[k] / np.trace(P))
    assert min(ratios) > 1.0 + 1e-6
    print(
        f"hover_uav: 96 systems x 400 steps, 0 violations, envelope fill {fill.min():.2f}-{fill.max():.2f}; "
        f"trace(P+) / trace(P) {min(ratios):.4f}-{max(ratios):.4f}"
    )
