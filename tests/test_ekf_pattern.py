"""F's non-zero pattern, kept from step to step by the EKF (linalg.pattern_holds / grow_pattern):
the check sees every new non-zero, and a kept pattern wider than F's non-zeros leaves
F P F^T + Q unchanged."""

from __future__ import annotations

import numpy as np

from logscan.filters.linalg import fpft_q, grow_pattern, pattern_holds, sparse_rows


def _kept(n: int):
    return np.full(n * n, -1, dtype=np.int64), np.empty((n, n), dtype=np.int64), np.zeros(n, dtype=np.int64)


def _bits(F: np.ndarray) -> np.ndarray:
    return F.reshape(-1).view(np.int64)


def test_the_check_sees_a_new_non_zero_nan_and_inf_but_not_a_negative_zero():
    n = 4
    F = np.zeros((n, n))
    F[0, 1] = 2.0
    outside, cols, nnz = _kept(n)
    assert not pattern_holds(_bits(F), outside)
    grow_pattern(F, n, outside, cols, nnz)
    assert pattern_holds(_bits(F), outside)
    assert nnz.tolist() == [1, 0, 0, 0] and cols[0, 0] == 1
    F[3, 3] = -0.0  # a zero of either sign is no new entry
    assert pattern_holds(_bits(F), outside)
    for value in (1e-300, np.nan, np.inf, -5.0):
        G = F.copy()
        G[2, 0] = value
        assert not pattern_holds(_bits(G), outside), value


def test_the_pattern_only_grows_and_lists_its_columns_in_order():
    n = 3
    outside, cols, nnz = _kept(n)
    F = np.zeros((n, n))
    F[1, 2] = 1.0
    grow_pattern(F, n, outside, cols, nnz)
    F[1, 2] = 0.0
    F[1, 0] = 3.0
    grow_pattern(F, n, outside, cols, nnz)
    assert nnz.tolist() == [0, 2, 0]
    assert cols[1, :2].tolist() == [0, 2]


def test_a_wider_kept_pattern_gives_the_same_prediction():
    rng = np.random.default_rng(3)
    n = 9
    A = rng.normal(size=(n, n))
    P = A @ A.T + n * np.eye(n)
    Q = np.diag(rng.uniform(0.1, 1.0, n))
    F = rng.normal(size=(n, n))
    F[rng.random((n, n)) < 0.5] = 0.0
    outside, wide_cols, wide_nnz = _kept(n)
    grow_pattern(np.ones((n, n)), n, outside, wide_cols, wide_nnz)  # every entry kept
    cols, nnz = np.empty((n, n), dtype=np.int64), np.empty(n, dtype=np.int64)
    sparse_rows(F, n, n, cols, nnz)
    exact, wide = np.empty((n, n)), np.empty((n, n))
    fpft_q(F, P, Q, n, cols, nnz, np.empty((n, n)), np.empty((n, n)), exact)
    fpft_q(F, P, Q, n, wide_cols, wide_nnz, np.empty((n, n)), np.empty((n, n)), wide)
    assert np.array_equal(exact, wide)
    np.testing.assert_allclose(exact, F @ P @ F.T + Q, rtol=1e-12)
