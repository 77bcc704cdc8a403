"""The EKF's covariance update: the short form P - V^T V where every variance keeps more than
SHORT_FORM_KEEP of its prior, the Joseph form otherwise (docs/algorithms.md 8.2), and the
linear-algebra helpers behind it."""

from __future__ import annotations

import numpy as np
from test_ekf import simulate

from logscan.filters import run_ekf
from logscan.filters.ekf import SHORT_FORM_KEEP, pack_run
from logscan.filters.linalg import cho_solve_rows, cholesky, gain_rows, short_update, sparse_rows
from logscan.filters.reference import reference_ekf


def _spd(n: int, rng: np.random.Generator) -> np.ndarray:
    A = rng.normal(size=(n, n))
    return A @ A.T + n * np.eye(n)


def _update_inputs(rng: np.random.Generator, n: int = 7, m: int = 3, r: float = 1.0, select: bool = False):
    P = _spd(n, rng)
    H = rng.normal(size=(m, n))
    H[H < -0.5] = 0.0  # sparse rows, as a Jacobian's
    if select:  # output a observes state a directly
        H = np.eye(m, n)
    HP = np.ascontiguousarray(H @ P)
    S = HP @ H.T + r * np.eye(m)
    L = np.zeros((m, m))
    assert cholesky(S, np.int64(0), m, L)
    return P, H, HP, S, L


def test_gain_rows_is_cho_solve_rows_and_keeps_the_half_solve():
    rng = np.random.default_rng(1)
    P, H, HP, S, L = _update_inputs(rng)
    m, n = HP.shape
    V, KT = np.empty((m, n)), np.empty((m, n))
    gain_rows(L, m, HP, V, KT, n)
    expected = HP.copy()
    cho_solve_rows(L, m, expected, n)
    np.testing.assert_array_equal(KT, expected)  # the same operations in the same order
    np.testing.assert_allclose(V, np.linalg.solve(L, HP), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(KT.T, P @ H.T @ np.linalg.inv(S), rtol=1e-10, atol=1e-12)


def test_short_update_is_P_minus_K_S_K_T_and_exactly_symmetric():
    rng = np.random.default_rng(2)
    P, H, HP, S, L = _update_inputs(rng)
    m, n = HP.shape
    V, KT = np.empty((m, n)), np.empty((m, n))
    gain_rows(L, m, HP, V, KT, n)
    out = np.empty((n, n))
    assert short_update(P, V, m, n, SHORT_FORM_KEEP, out)
    K = KT.T
    np.testing.assert_allclose(out, P - K @ S @ K.T, rtol=1e-10, atol=1e-12)
    # equal to the Joseph form for the optimal gain
    IKH = np.eye(n) - K @ H
    np.testing.assert_allclose(out, IKH @ P @ IKH.T + K @ K.T, rtol=1e-10, atol=1e-12)  # R = I
    np.testing.assert_array_equal(out, out.T)


def test_short_update_refuses_a_collapsing_variance_and_a_non_finite_one():
    rng = np.random.default_rng(3)
    P, H, HP, S, L = _update_inputs(rng, r=1e-12, select=True)  # states 0-2 measured far sharper than known
    m, n = HP.shape
    V, KT = np.empty((m, n)), np.empty((m, n))
    gain_rows(L, m, HP, V, KT, n)
    out = np.empty((n, n))
    assert not short_update(P, V, m, n, SHORT_FORM_KEEP, out)
    assert short_update(P, V, m, n, 0.0, out) or np.min(np.diag(out)) <= 0.0  # only the share refused it
    _, _, HP, _, L = _update_inputs(np.random.default_rng(4))
    gain_rows(L, m, HP, V, KT, n)
    V[1, 2] = np.nan
    assert not short_update(P, V, m, n, SHORT_FORM_KEEP, out)


def test_sparse_rows_lists_each_rows_non_zeros():
    rng = np.random.default_rng(5)
    M = rng.normal(size=(6, 9))
    M[rng.random(M.shape) < 0.6] = 0.0
    M[2] = 0.0
    M[4] = 1.0
    cols, nnz = np.full((6, 9), -1, dtype=np.int64), np.empty(6, dtype=np.int64)
    sparse_rows(M, 6, 9, cols, nnz)
    for a in range(6):
        expected = np.flatnonzero(M[a])
        assert nnz[a] == expected.size
        np.testing.assert_array_equal(cols[a, : nnz[a]], expected)


def test_a_collapsing_prior_takes_the_joseph_form_and_matches_the_reference():
    """Position far sharper than a wide prior: the first updates shrink its variance by ~1e-10
    (below SHORT_FORM_KEEP), so those steps take the Joseph form; the run still agrees with the
    numpy reference (explicit Joseph product) and P stays symmetric positive definite."""
    model, run, _ = simulate("quadcopter", N=150, seed=11)
    R = {"position": np.full(3, 1e-4)}
    P0 = np.diag(np.square(model.state_scale())) * 1e4
    x0 = np.zeros(model.n_states)
    assert np.min(1e-8 / np.diag(P0)[:3]) < SHORT_FORM_KEEP  # the first position update collapses
    trace = run_ekf(model, run, R=R, x0=x0, P0=P0, full_P=True)
    ref = reference_ekf(model, pack_run(model, run, R=R, x0=x0, P0=P0))
    assert not trace.diverged.any()
    scale = np.abs(ref["P_post"]).max(axis=(1, 2))[:, None, None]
    assert np.max(np.abs(trace.P_post - ref["P_post"]) / scale) < 1e-9
    assert np.max(np.abs(trace.x_post - ref["x_post"])) < 1e-6
    np.testing.assert_array_equal(trace.P_post, np.swapaxes(trace.P_post, 1, 2))
    assert min(np.linalg.eigvalsh(P).min() for P in trace.P_post) > 0.0
