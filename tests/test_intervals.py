"""Interval products, zonotope hulls and order reduction enclose every point they stand for; the
Loewner bound of an interval covariance lies above every symmetric matrix inside it."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.filters.intervals import congruence_bound, interval_product, reduce_zonotope, zonotope_hull
from logscan.models.interval_model import loewner_upper

SAMPLES = 200


def inside(values, mid, rad) -> bool:
    """Every value within mid +- rad, up to the relative tolerance 1e-9 (|mid| + rad) + 1e-12."""
    tol = 1e-9 * (np.abs(mid) + rad) + 1e-12
    return bool(np.all(np.abs(values - mid) <= rad + tol))


def draws(rng, mid, rad, count):
    """count points of [mid +- rad]: the two all-vertex corners, random vertices, random interior points."""
    signs = rng.choice([-1.0, 1.0], size=(count, *mid.shape))
    signs[0], signs[1] = 1.0, -1.0
    half = count // 2
    signs[half:] = rng.uniform(-1.0, 1.0, size=(count - half, *mid.shape))
    return mid + signs * rad


@st.composite
def interval_problems(draw):
    rows = draw(st.integers(1, 6))
    inner = draw(st.integers(1, 6))
    cols = draw(st.integers(1, 4))
    seed = draw(st.integers(0, 2**32 - 1))
    scale = draw(st.sampled_from([1e-6, 1.0, 1e3, 1e8]))
    relative = draw(st.sampled_from([0.0, 0.01, 0.1, 1.0]))
    rng = np.random.default_rng(seed)
    A_m = rng.normal(size=(rows, inner)) * scale
    A_r = np.abs(A_m) * relative * rng.uniform(size=(rows, inner))
    B_m = rng.normal(size=(inner, cols)) * rng.choice([1e-3, 1.0, 1e4])
    B_r = np.abs(B_m) * relative * rng.uniform(size=(inner, cols))
    return rng, A_m, A_r, B_m, B_r


@settings(max_examples=60, deadline=None)
@given(interval_problems())
def test_interval_matrix_times_interval_vector_encloses_every_point_product(problem):
    rng, A_m, A_r, B_m, B_r = problem
    x_m, x_r = B_m[:, 0], B_r[:, 0]
    mid, rad = interval_product(A_m, A_r, x_m, x_r)
    assert np.all(rad >= 0)
    for A, x in zip(draws(rng, A_m, A_r, SAMPLES), draws(rng, x_m, x_r, SAMPLES)):
        assert inside(A @ x, mid, rad)


@settings(max_examples=60, deadline=None)
@given(interval_problems())
def test_interval_matrix_times_point_vector_and_point_matrix_encloses_every_point_product(problem):
    rng, A_m, A_r, B_m, _ = problem
    mid_v, rad_v = interval_product(A_m, A_r, B_m[:, 0])
    mid_M, rad_M = interval_product(A_m, A_r, B_m)
    assert mid_M.shape == (A_m.shape[0], B_m.shape[1])
    for A in draws(rng, A_m, A_r, SAMPLES):
        assert inside(A @ B_m[:, 0], mid_v, rad_v)
        assert inside(A @ B_m, mid_M, rad_M)


def test_interval_product_is_not_wider_than_needed_for_a_point_matrix():
    A_m = np.array([[1.0, 2.0], [3.0, -4.0]])
    mid, rad = interval_product(A_m, np.zeros((2, 2)), np.array([1.0, 1.0]), np.array([0.5, 0.0]))
    np.testing.assert_allclose(mid, [3.0, -1.0])
    np.testing.assert_allclose(rad, [0.5, 1.5], rtol=1e-14)


@st.composite
def zonotopes(draw):
    n = draw(st.integers(1, 6))
    p = draw(st.integers(0, 12))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    G = rng.normal(size=(n, p)) * draw(st.sampled_from([1e-5, 1.0, 1e6]))
    G[:, rng.uniform(size=p) < 0.2] = 0.0  # some zero generators
    return rng, rng.normal(size=n), G


def zonotope_points(rng, c, G, count):
    """c + G xi for xi at vertices of [-1, 1]^p and inside it."""
    p = G.shape[1]
    xi = rng.choice([-1.0, 1.0], size=(count, p))
    xi[count // 2 :] = rng.uniform(-1.0, 1.0, size=(count - count // 2, p))
    return c + xi @ G.T


@settings(max_examples=80, deadline=None)
@given(zonotopes())
def test_zonotope_hull_encloses_its_points_and_is_tight(zonotope):
    rng, c, G = zonotope
    rad = zonotope_hull(G)
    assert inside(zonotope_points(rng, c, G, SAMPLES), c, rad)
    # the hull is the smallest box: the vertex xi = sign(G[i]) reaches it in row i
    for i in range(G.shape[0]):
        np.testing.assert_allclose(np.sign(G[i]) @ G[i], rad[i], rtol=1e-12, atol=1e-300)


@settings(max_examples=80, deadline=None)
@given(zonotopes(), st.data())
def test_order_reduction_encloses_the_original_zonotope(zonotope, data):
    rng, c, G = zonotope
    n, p = G.shape
    q = data.draw(st.integers(0, p))
    reduced = reduce_zonotope(G, q)
    assert reduced.shape[1] == (p if q == 0 else n + p - q)
    # the kept generators are the last p - q, unchanged
    np.testing.assert_array_equal(reduced[:, reduced.shape[1] - (p - q) :], G[:, q:])
    # every point of the original is a point of the reduced zonotope: c + G_old xi_old + G_new xi_new,
    # and G_old xi_old lies in the box diag(rowsum |G_old|) [-1, 1]^n
    xi = rng.choice([-1.0, 1.0], size=(SAMPLES, p))
    xi[SAMPLES // 2 :] = rng.uniform(-1.0, 1.0, size=(SAMPLES - SAMPLES // 2, p))
    if q:
        box = np.diag(reduced[:, :n])
        assert np.all(reduced[:, :n] == np.diag(box))
        assert inside(xi[:, :q] @ G[:, :q].T, np.zeros(n), box)
    assert inside(zonotope_points(rng, c, G, SAMPLES), c, zonotope_hull(reduced))


@st.composite
def interval_covariances(draw):
    n = draw(st.integers(1, 7))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    X = rng.normal(size=(n, n))
    M_m = X @ X.T + draw(st.sampled_from([0.0, 0.1, 10.0])) * np.eye(n)
    M_r = np.abs(rng.normal(size=(n, n))) * draw(st.sampled_from([0.001, 0.1, 1.0]))
    M_r = 0.5 * (M_r + M_r.T)
    return rng, M_m, M_r


@settings(max_examples=80, deadline=None)
@given(interval_covariances())
def test_loewner_upper_bound_lies_above_every_symmetric_matrix_inside(problem):
    rng, M_m, M_r = problem
    U = loewner_upper(M_m, M_r)
    scale = np.max(np.abs(U))
    for signs in draws(rng, np.zeros_like(M_m), np.ones_like(M_m), SAMPLES):
        E = np.triu(signs * M_r)
        M = M_m + E + np.triu(E, 1).T  # symmetric, inside [M_m +- M_r]
        assert np.linalg.eigvalsh(U - M).min() >= -1e-9 * scale


@settings(max_examples=60, deadline=None)
@given(interval_covariances(), st.sampled_from([0.0, 0.01, 0.1, 0.5]))
def test_weighted_congruence_bound_lies_above_M_P_MT_for_every_M_inside(problem, relative):
    rng, P, _ = problem
    n = P.shape[0]
    M_m = rng.normal(size=(n, n))
    M_m[rng.uniform(size=(n, n)) < 0.3] = 0.0  # row-sparse, as a discretised model
    M_r = relative * np.abs(rng.normal(size=(n, n)))
    bound = congruence_bound(M_m, M_r, P)
    scale = np.max(np.abs(bound))
    for M in draws(rng, M_m, M_r, SAMPLES):
        assert np.linalg.eigvalsh(bound - M @ P @ M.T).min() >= -1e-9 * scale
    if relative == 0.0:  # a point matrix: the bound is M P M^T itself
        np.testing.assert_allclose(bound, M_m @ P @ M_m.T, rtol=1e-12, atol=1e-12 * scale)
