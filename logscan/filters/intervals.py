"""Midpoint-radius interval arithmetic and zonotopes: the set arithmetic of the UBIKF (docs/algorithms.md section 2).

Interval vectors and matrices are a midpoint and a radius, [x] = x_m +- x_r (x_r >= 0 elementwise).
The product of an interval matrix and an interval vector (Rump's midpoint-radius product)

    mid = A_m x_m,   rad = |A_m| x_r + A_r (|x_m| + x_r) + gamma |A_m| |x_m|

encloses A x for every A in [A], x in [x]; the last term covers the rounding of the midpoint
(gamma = (n + 2) eps for inner dimension n), and every radius is widened by (1 + 4 eps) plus the
smallest normal float (`widen`) to cover the rounding of the radius itself (a radius whose terms
are all exactly zero stays zero). A point vector or matrix is an interval of zero radius.

A zonotope is a centre and generators, Z = c + G [-1, 1]^p with G (n, p). Its interval hull is
c +- rowsum |G|; a linear map M Z has generators M G; adding a box [-a, a] appends the columns
diag(a); order reduction replaces generators G_old by diag(rowsum |G_old|), a box that encloses
them. The kernels work on a generator array with room for more columns than are in use (the first
p are); they never allocate.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from logscan.filters.linalg import sparse_mm
from logscan.numba_cache import follow_dependencies

EPS = float(np.finfo(np.float64).eps)
OUTWARD = 1.0 + 4.0 * EPS  # radii are multiplied by this ...
TINY = float(np.finfo(np.float64).tiny)  # ... and this is added


@njit(cache=True, error_model="numpy")
def widen(r):
    """A radius rounded outward: r (1 + 4 eps) + tiny; an exact zero (every term zero) stays zero."""
    return r * OUTWARD + TINY if r != 0.0 else 0.0


@njit(cache=True, error_model="numpy")
def interval_matvec_into(A_m, A_r, x_m, x_r, out_m, out_r):
    """[A] [x] into (out_m, out_r): mid = A_m x_m, rad = |A_m| x_r + A_r (|x_m| + x_r) + gamma |A_m| |x_m|."""
    rows, n = A_m.shape
    gamma = (n + 2) * EPS
    for i in range(rows):
        mid = 0.0
        rad = 0.0
        for j in range(n):
            a = A_m[i, j]
            xa = abs(x_m[j])
            mid += a * x_m[j]
            rad += abs(a) * (x_r[j] + gamma * xa) + A_r[i, j] * (xa + x_r[j])
        out_m[i] = mid
        out_r[i] = widen(rad)


@njit(cache=True, error_model="numpy")
def interval_matmul_into(A_m, A_r, B_m, B_r, out_m, out_r):
    """[A] [B] into (out_m, out_r), column by column of [B] (the matrix-vector product per column)."""
    rows, n = A_m.shape
    cols = B_m.shape[1]
    gamma = (n + 2) * EPS
    for i in range(rows):
        for c in range(cols):
            mid = 0.0
            rad = 0.0
            for j in range(n):
                a = A_m[i, j]
                b = B_m[j, c]
                mid += a * b
                rad += abs(a) * (B_r[j, c] + gamma * abs(b)) + A_r[i, j] * (abs(b) + B_r[j, c])
            out_m[i, c] = mid
            out_r[i, c] = widen(rad)


@njit(cache=True, error_model="numpy")
def zonotope_hull_into(G, rows, p, out):
    """Radius of the interval hull of c + G[:rows, :p] [-1, 1]^p: out[i] = sum_j |G[i, j]| (widened)."""
    for i in range(rows):
        Gi = G[i]
        s = 0.0
        for j in range(p):
            s += abs(Gi[j])
        out[i] = widen(s)


@njit(cache=True, error_model="numpy")
def zonotope_map_into(M, cols, nnz, G, p, out):
    """Generators of the linear image M Z: out[:, :p] = M G[:, :p] (M row-sparse: the non-zeros
    of row i at cols[i, :nnz[i]], from `logscan.filters.linalg.sparse_rows`)."""
    sparse_mm(M, cols, nnz, M.shape[0], G, p, out)


@njit(cache=True, error_model="numpy")
def subtract_product(K, m, B, p, G):
    """G[:, :p] -= K[:, :m] B[:m, :p] in place (the correction step's map (I - K C) G = G - K (C G))."""
    n = G.shape[0]
    for i in range(n):
        Gi = G[i]
        for a in range(m):
            f = K[i, a]
            if f == 0.0:
                continue
            Ba = B[a]
            for j in range(p):
                Gi[j] -= f * Ba[j]


@njit(cache=True, error_model="numpy")
def append_box(G, p, a):
    """Z + [-a, a]: append the columns a_i e_i for a_i > 0 (zero radii add nothing); returns the new p."""
    n = G.shape[0]
    for i in range(a.size):
        if a[i] > 0.0:
            for r in range(n):
                G[r, p] = 0.0
            G[i, p] = a[i]
            p += 1
    return p


@njit(cache=True, error_model="numpy")
def append_scaled_columns(G, p, V, m, a):
    """Z + V[:, :m] diag(a) [-1, 1]^m: append the columns a_j V[:, j] for a_j > 0; returns the new p."""
    n = G.shape[0]
    for j in range(m):
        if a[j] > 0.0:
            for r in range(n):
                G[r, p] = a[j] * V[r, j]
            p += 1
    return p


@njit(cache=True, error_model="numpy")
def reduce_order(G, p, q):
    """Box the first q generators: replace G[:, :q] by diag(rowsum |G[:, :q]|) (n columns, an
    enclosure of what they span) followed by the remaining G[:, q:p]; returns the new p (q = 0:
    nothing to box)."""
    n = G.shape[0]
    if q <= 0:
        return p
    keep = p - q
    box = np.empty(n)
    zonotope_hull_into(G, n, q, box)
    for i in range(n):
        Gi = G[i]
        if n <= q:  # moving left: front to back
            for j in range(keep):
                Gi[n + j] = Gi[q + j]
        else:  # moving right: back to front
            for j in range(keep - 1, -1, -1):
                Gi[n + j] = Gi[q + j]
        for j in range(n):
            Gi[j] = 0.0
        Gi[i] = box[i]
    return n + keep


# ------------------------------------------------------------------------------------------------
# plain numpy entry points (tests, reports)
# ------------------------------------------------------------------------------------------------


def interval_product(A_m, A_r, B_m, B_r=None) -> tuple[np.ndarray, np.ndarray]:
    """[A] [B] for an interval matrix [A] and a point or interval vector or matrix [B] (B_r None:
    a point); returns (mid, rad) with the shape of A_m @ B_m."""
    A_m, A_r = np.ascontiguousarray(A_m, dtype=np.float64), np.ascontiguousarray(A_r, dtype=np.float64)
    B_m = np.asarray(B_m, dtype=np.float64)
    B_r = np.zeros_like(B_m) if B_r is None else np.asarray(B_r, dtype=np.float64)
    vector = B_m.ndim == 1
    B_m2, B_r2 = (B_m[:, None], B_r[:, None]) if vector else (B_m, B_r)
    out_m = np.empty((A_m.shape[0], B_m2.shape[1]))
    out_r = np.empty_like(out_m)
    interval_matmul_into(A_m, A_r, np.ascontiguousarray(B_m2), np.ascontiguousarray(B_r2), out_m, out_r)
    return (out_m[:, 0], out_r[:, 0]) if vector else (out_m, out_r)


def zonotope_hull(G) -> np.ndarray:
    """Radius of the interval hull of c + G [-1, 1]^p."""
    G = np.ascontiguousarray(G, dtype=np.float64)
    out = np.empty(G.shape[0])
    zonotope_hull_into(G, G.shape[0], G.shape[1], out)
    return out


def reduce_zonotope(G, q: int) -> np.ndarray:
    """The generators after boxing the first q of G (n, p): (n, n + p - q) when q > 0."""
    G = np.asarray(G, dtype=np.float64)
    n, p = G.shape
    work = np.zeros((n, n + p))
    work[:, :p] = G
    return work[:, : reduce_order(work, p, q)].copy()


follow_dependencies(__name__)
