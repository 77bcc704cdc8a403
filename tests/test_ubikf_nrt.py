"""The UBIKF's step loop runs without numba's reference counting: the private NRT-free copies of the
shared helpers compute what the originals do, are the UBIKF's own (the shared function keeps its
own compiled versions), refuse to compile an allocation, and the allocation-free box_columns and
copy agree with the shared ones."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit
from numba.core.errors import NumbaError

from logscan.filters import intervals, linalg
from logscan.filters.ubikf_kernel import box_columns_into, copy_into, sparse_mm
from logscan.filters.ubikf_nrt import nrt_free


def test_a_private_copy_computes_what_the_shared_function_does_and_leaves_it_alone():
    rng = np.random.default_rng(1)
    M, B = rng.normal(size=(4, 4)), rng.normal(size=(4, 30))
    M[M < 0.3] = 0.0
    cols, nnz = np.empty((4, 4), dtype=np.int64), np.empty(4, dtype=np.int64)
    linalg.sparse_rows(M, 4, 4, cols, nnz)
    shared, private = np.empty((4, 30)), np.empty((4, 30))
    linalg.sparse_mm(M, cols, nnz, 4, B, 30, shared)
    sparse_mm(M, cols, nnz, 4, B, 30, private)
    np.testing.assert_array_equal(private, shared)
    np.testing.assert_allclose(private, M @ B, rtol=1e-12, atol=1e-12)
    assert sparse_mm is not linalg.sparse_mm and sparse_mm.py_func.__code__ is linalg.sparse_mm.py_func.__code__
    assert nrt_free(linalg.sparse_mm) is sparse_mm  # one copy per function


def test_a_copys_callees_are_private_copies_too():
    posterior_bound = nrt_free(intervals.posterior_bound)
    assert posterior_bound.py_func.__globals__["joseph"] is nrt_free(linalg.joseph)
    assert intervals.posterior_bound.py_func.__globals__["joseph"] is linalg.joseph


def test_an_allocation_does_not_compile_without_the_nrt():
    @njit
    def allocates(n):
        return np.zeros(n).sum()

    with pytest.raises(NumbaError):  # "NRT required but not enabled", or no typing for it
        nrt_free(allocates)(3)


@pytest.mark.parametrize(("p", "q0", "q1"), [(40, 10, 30), (40, 0, 22), (12, 3, 5), (12, 4, 4), (9, 0, 9)])
def test_box_columns_into_is_box_columns(p, q0, q1):
    rng = np.random.default_rng(p + q0 + q1)
    G = np.zeros((3, 60))
    G[:, :p] = rng.normal(size=(3, p))
    expected = G.copy()
    p_expected = intervals.box_columns(expected, p, q0, q1)
    p_new = box_columns_into(G, p, q0, q1, np.empty(3))
    assert p_new == p_expected
    np.testing.assert_array_equal(G[:, :p_new], expected[:, :p_expected])


def test_copy_into_copies_vectors_and_matrices():
    src, dst = np.arange(6.0).reshape(2, 3), np.zeros((2, 3))
    copy_into(src, dst)
    np.testing.assert_array_equal(dst, src)
    v = np.zeros(3)
    copy_into(src[1], v)
    np.testing.assert_array_equal(v, [3.0, 4.0, 5.0])
