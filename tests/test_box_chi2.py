"""The chi-square statistic over an innovation box (logscan.filters.box_chi2) against independent
references: scipy's bounded least squares (bvls) for the minimum, every vertex for the maximum."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import lsq_linear

from logscan.filters.box_chi2 import (
    MAX_VERTEX_DIM,
    box_chi2_bounds,
    box_max_vertex,
    box_qp_argmin,
    box_qp_min,
)

SETTINGS = settings(max_examples=150, deadline=None)


def random_spd(rng: np.random.Generator, m: int, log_cond: float) -> np.ndarray:
    """Q diag(lambda) Q^T with eigenvalues spread log-uniformly over 10^log_cond, times a random scale."""
    Q, _ = np.linalg.qr(rng.normal(size=(m, m)))
    lam = np.logspace(0.0, log_cond, m) * 10.0 ** rng.uniform(-2.0, 2.0)
    S = (Q * lam) @ Q.T
    return 0.5 * (S + S.T)


def inverse(S: np.ndarray) -> np.ndarray:
    H = np.linalg.inv(S)
    return 0.5 * (H + H.T)


@st.composite
def problems(draw, m_min=1, m_max=10, max_log_cond=6.0, zero_radius=True):
    """(r_mid, r_rad, S, H): random SPD S with condition number up to 10^max_log_cond, a box whose
    centre is from near 0 to far from it, some radii possibly 0."""
    m = draw(st.integers(m_min, m_max))
    seed = draw(st.integers(0, 2**32 - 1))
    log_cond = draw(st.floats(0.0, max_log_cond))
    centre = 10.0 ** draw(st.floats(-2.0, 1.5))
    radius = 10.0 ** draw(st.floats(-4.0, 1.0))
    rng = np.random.default_rng(seed)
    S = random_spd(rng, m, log_cond)
    scale = np.sqrt(np.diag(S))
    r_mid = rng.normal(size=m) * centre * scale
    r_rad = np.abs(rng.normal(size=m)) * radius * scale
    if zero_radius and draw(st.booleans()):
        r_rad[rng.random(m) < 0.3] = 0.0
    return r_mid, r_rad, S, inverse(S)


def bvls_min(r_mid, r_rad, H) -> float:
    """min ||L^T r||^2 (H = L L^T) over the box by scipy's bvls; zero-radius coordinates are
    substituted (bvls wants lower < upper)."""
    A = np.linalg.cholesky(H).T
    free = r_rad > 0
    x = r_mid.copy()
    if free.any():
        res = lsq_linear(
            A[:, free],
            -A[:, ~free] @ r_mid[~free],
            bounds=(r_mid[free] - r_rad[free], r_mid[free] + r_rad[free]),
            method="bvls",
            tol=1e-15,
        )
        x[free] = res.x
    return float(x @ H @ x)


def vertex_max(r_mid, r_rad, H) -> float:
    vertices = r_mid + np.array(list(itertools.product((-1.0, 1.0), repeat=len(r_mid)))) * r_rad
    return float(np.max(np.einsum("vi,ij,vj->v", vertices, H, vertices)))


def points_in_box(rng, r_mid, r_rad, n=200) -> np.ndarray:
    """Uniform points of the box, its centre, and random vertices."""
    inner = r_mid + rng.uniform(-1.0, 1.0, size=(n, len(r_mid))) * r_rad
    corners = r_mid + rng.choice((-1.0, 1.0), size=(n, len(r_mid))) * r_rad
    return np.vstack([r_mid[None, :], inner, corners])


def form(points, H) -> np.ndarray:
    return np.einsum("vi,ij,vj->v", points, H, points)


def scale_of(r_mid, r_rad, H) -> float:
    """|r|^T |H| |r| at the box's far corner: the size of the terms the forms are summed from."""
    a = np.abs(r_mid) + r_rad
    return float(a @ np.abs(H) @ a)


# --- minimum ------------------------------------------------------------------------------------


@SETTINGS
@given(problems())
def test_min_equals_scipy_bvls(problem):
    r_mid, r_rad, _, H = problem
    got = box_qp_min(r_mid, r_rad, H)
    want = bvls_min(r_mid, r_rad, H)
    assert got == pytest.approx(want, rel=1e-9, abs=1e-14 * scale_of(r_mid, r_rad, H))


@SETTINGS
@given(problems())
def test_argmin_is_in_the_box_and_satisfies_the_optimality_conditions(problem):
    """KKT of min x^T H x on the box: gradient H x is 0 on free coordinates, >= 0 at a lower bound,
    <= 0 at an upper bound (up to rounding of the terms of H x)."""
    r_mid, r_rad, _, H = problem
    value, x = box_qp_argmin(r_mid, r_rad, H)
    lo, hi = r_mid - r_rad, r_mid + r_rad
    assert np.all(x >= lo - 1e-12 * np.abs(lo)) and np.all(x <= hi + 1e-12 * np.abs(hi))
    assert value == pytest.approx(x @ H @ x, rel=1e-12, abs=1e-14 * (np.abs(x) @ np.abs(H) @ np.abs(x)))
    g = H @ x
    tol = 1e-7 * (np.abs(H) @ np.abs(x)) + 1e-300
    at_lo = (x <= lo) & (r_rad > 0)
    at_hi = (x >= hi) & (r_rad > 0)
    free = (x > lo) & (x < hi)
    assert np.all(g[at_lo & ~at_hi] >= -tol[at_lo & ~at_hi])
    assert np.all(g[at_hi & ~at_lo] <= tol[at_hi & ~at_lo])
    assert np.all(np.abs(g[free]) <= tol[free])


@SETTINGS
@given(problems(), st.floats(0.0, 0.99))
def test_a_box_holding_zero_gives_zero(problem, shrink):
    r_mid, r_rad, _, H = problem
    r_rad = np.maximum(r_rad, np.abs(r_mid)) + 1e-9
    r_mid = r_mid * shrink
    value, x = box_qp_argmin(r_mid, r_rad, H)
    assert value == 0.0
    assert np.all(x == 0.0)


@SETTINGS
@given(problems())
def test_a_degenerate_box_gives_the_point_value(problem):
    r_mid, _, _, H = problem
    zero = np.zeros_like(r_mid)
    point = float(r_mid @ H @ r_mid)
    # rounding of a quadratic form grows with |r|^T |H| |r|, not with its value: an ill-conditioned
    # H (terms of 1e12 cancelling to 5.7) differs in the 12th digit by the order of summation alone
    rounding = 1e-14 * float(np.abs(r_mid) @ np.abs(H) @ np.abs(r_mid))
    assert box_qp_min(r_mid, zero, H) == pytest.approx(point, rel=1e-12, abs=rounding)
    assert box_max_vertex(r_mid, zero, H) == pytest.approx(point, rel=1e-12, abs=rounding)


def test_min_in_one_dimension_is_the_square_of_the_distance_to_zero():
    H = np.array([[4.0]])
    assert box_qp_min(np.array([3.0]), np.array([1.0]), H) == pytest.approx(16.0)
    assert box_qp_min(np.array([-3.0]), np.array([1.0]), H) == pytest.approx(16.0)
    assert box_qp_min(np.array([0.5]), np.array([1.0]), H) == 0.0


def test_min_with_correlation_is_not_at_a_vertex():
    """S strongly correlated: the minimiser moves along the free coordinate into the box's interior."""
    H = inverse(np.array([[1.0, 0.9], [0.9, 1.0]]))
    value, x = box_qp_argmin(np.array([2.0, 0.0]), np.array([1.0, 5.0]), H)
    assert x[0] == pytest.approx(1.0)
    assert x[1] == pytest.approx(0.9)  # argmin of [1, y] H [1, y]^T: y = -H01 / H11 = 0.9
    assert value == pytest.approx(1.0)  # min over y of [1, y] S^-1 [1, y]^T = 1^2 / S00 (the marginal)


# --- maximum ------------------------------------------------------------------------------------


@SETTINGS
@given(problems())
def test_max_equals_the_best_of_every_vertex(problem):
    r_mid, r_rad, _, H = problem
    got = box_max_vertex(r_mid, r_rad, H)
    assert got == pytest.approx(vertex_max(r_mid, r_rad, H), rel=1e-10, abs=1e-13 * scale_of(r_mid, r_rad, H))


@settings(max_examples=20, deadline=None)
@given(st.integers(MAX_VERTEX_DIM + 1, 16), st.integers(0, 2**32 - 1))
def test_max_enumerates_only_the_coordinates_of_nonzero_radius(m, seed):
    rng = np.random.default_rng(seed)
    H = inverse(random_spd(rng, m, 3.0))
    r_mid = rng.normal(size=m)
    r_rad = np.zeros(m)
    active = rng.choice(m, size=MAX_VERTEX_DIM, replace=False)
    r_rad[active] = rng.uniform(0.1, 2.0, size=MAX_VERTEX_DIM)
    assert box_max_vertex(r_mid, r_rad, H) == pytest.approx(vertex_max(r_mid, r_rad, H), rel=1e-10)


@settings(max_examples=60, deadline=None)
@given(problems(m_min=MAX_VERTEX_DIM + 1, m_max=20, max_log_cond=4.0, zero_radius=False))
def test_above_the_vertex_limit_the_bound_is_above_every_point_of_the_box(problem):
    r_mid, r_rad, _, H = problem
    rng = np.random.default_rng(len(r_mid))
    bound = box_max_vertex(r_mid, r_rad, H)
    a = np.abs(r_mid) + r_rad
    assert bound == pytest.approx(a @ np.abs(H) @ a, rel=1e-12)
    assert np.all(form(points_in_box(rng, r_mid, r_rad, n=2000), H) <= bound * (1 + 1e-12))


# --- both ---------------------------------------------------------------------------------------


@SETTINGS
@given(problems(m_max=14), st.integers(0, 2**32 - 1))
def test_the_centre_and_every_point_of_the_box_lie_between_lo_and_hi(problem, seed):
    r_mid, r_rad, _, H = problem
    lo = box_qp_min(r_mid, r_rad, H)
    hi = box_max_vertex(r_mid, r_rad, H)
    values = form(points_in_box(np.random.default_rng(seed), r_mid, r_rad), H)
    slack = 1e-12 * scale_of(r_mid, r_rad, H)
    assert 0.0 <= lo <= hi
    assert np.all(values >= lo - slack)
    assert np.all(values <= hi + slack)


# --- vectorised over steps ----------------------------------------------------------------------


def padded_steps(rng, N, M, log_cond=4.0):
    """N steps over M rows, each with a random subset of rows updated (some steps none): r_mid NaN
    and S NaN outside the subset, r_rad set everywhere (the mask comes from r_mid)."""
    r_mid = np.full((N, M), np.nan)
    r_rad = np.abs(rng.normal(size=(N, M))) * 0.5
    S = np.full((N, M, M), np.nan)
    subsets = []
    for k in range(N):
        J = np.flatnonzero(rng.random(M) < rng.uniform(0.0, 1.0))
        subsets.append(J)
        if len(J):
            r_mid[k, J] = rng.normal(size=len(J)) * 2.0
            S[k][np.ix_(J, J)] = random_spd(rng, len(J), log_cond)
    return r_mid, r_rad, S, subsets


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 40), st.integers(1, 9))
def test_bounds_over_steps_equal_the_per_step_kernels(seed, N, M):
    rng = np.random.default_rng(seed)
    r_mid, r_rad, S, subsets = padded_steps(rng, N, M)
    lo, hi = box_chi2_bounds(r_mid, r_rad, S)
    assert lo.shape == hi.shape == (N,)
    for k, J in enumerate(subsets):
        if len(J) == 0:
            assert np.isnan(lo[k]) and np.isnan(hi[k])
            continue
        H = inverse(S[k][np.ix_(J, J)])
        assert lo[k] == pytest.approx(box_qp_min(r_mid[k, J], r_rad[k, J], H), rel=1e-8, abs=1e-12)
        assert hi[k] == pytest.approx(box_max_vertex(r_mid[k, J], r_rad[k, J], H), rel=1e-8)


def test_rows_narrow_the_updated_rows():
    rng = np.random.default_rng(3)
    r_mid, r_rad, S, _ = padded_steps(rng, 30, 6)
    r_mid = rng.normal(size=r_mid.shape)
    S = np.stack([random_spd(rng, 6, 2.0) for _ in range(30)])
    rows = rng.random(r_mid.shape) < 0.5
    lo, hi = box_chi2_bounds(r_mid, r_rad, S, rows)
    masked = np.where(rows, r_mid, np.nan)
    lo_masked, hi_masked = box_chi2_bounds(masked, r_rad, S)
    np.testing.assert_array_equal(lo, lo_masked)
    np.testing.assert_array_equal(hi, hi_masked)
    assert np.isnan(lo[~rows.any(axis=1)]).all()
    assert np.isfinite(lo[rows.any(axis=1)]).all()


def test_bounds_over_steps_use_the_documented_bound_above_the_vertex_limit():
    rng = np.random.default_rng(5)
    M = MAX_VERTEX_DIM + 2
    S = random_spd(rng, M, 2.0)
    r_mid = rng.normal(size=M)
    r_rad = np.full(M, 0.3)
    lo, hi = box_chi2_bounds(r_mid[None], r_rad[None], S[None])
    H = inverse(S)
    a = np.abs(r_mid) + r_rad
    assert hi[0] == pytest.approx(a @ np.abs(H) @ a, rel=1e-9)
    assert lo[0] == pytest.approx(bvls_min(r_mid, r_rad, H), rel=1e-9)


def test_a_step_with_bad_numbers_is_nan_and_leaves_the_others_alone():
    S = np.stack([np.eye(2), np.array([[1.0, 2.0], [2.0, 1.0]]), np.eye(2), np.eye(2)])  # step 1 indefinite
    r_mid = np.array([[1.0, 2.0], [1.0, 2.0], [1.0, 2.0], [1.0, 2.0]])
    r_rad = np.array([[0.5, 0.5], [0.5, 0.5], [np.nan, 0.5], [-0.1, 0.5]])
    lo, hi = box_chi2_bounds(r_mid, r_rad, S)
    assert lo[0] == pytest.approx(0.5**2 + 1.5**2) and hi[0] == pytest.approx(1.5**2 + 2.5**2)
    assert np.isnan(lo[1:]).all() and np.isnan(hi[1:]).all()


def test_shapes_are_checked():
    with pytest.raises(ValueError, match="r_mid, r_rad"):
        box_chi2_bounds(np.zeros((3, 2)), np.zeros((3, 2)), np.zeros((3, 2, 3)))
    with pytest.raises(ValueError, match="rows"):
        box_chi2_bounds(np.zeros((3, 2)), np.zeros((3, 2)), np.zeros((3, 2, 2)), np.ones((3, 3), bool))
