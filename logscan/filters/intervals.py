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

from logscan.filters.linalg import fpft_q, joseph, sparse_mm, sparse_rows
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
    return box_columns(G, p, 0, q)


@njit(cache=True, error_model="numpy")
def box_columns(G, p, q0, q1):
    """Box the generators q0 .. q1 - 1: replace G[:, q0:q1] by diag(rowsum |G[:, q0:q1]|) (n
    columns, an enclosure of what they span) followed by the remaining G[:, q1:p]; returns the new
    p (q1 <= q0: nothing to box)."""
    return box_columns_into(G, p, q0, q1, np.empty(G.shape[0]))


@njit(cache=True, error_model="numpy")
def box_columns_into(G, p, q0, q1, box):
    """`box_columns` with its (n,) work vector given (``box``): the UBIKF's step loop allocates
    nothing (`logscan.filters.ubikf_nrt`)."""
    n = G.shape[0]
    if q1 <= q0:
        return p
    keep = p - q1
    for i in range(n):
        s = 0.0
        for j in range(q0, q1):
            s += abs(G[i, j])
        box[i] = widen(s)
    for i in range(n):
        if q0 + n <= q1:  # moving left: front to back
            for j in range(keep):
                G[i, q0 + n + j] = G[i, q1 + j]
        else:  # moving right: back to front
            for j in range(keep - 1, -1, -1):
                G[i, q0 + n + j] = G[i, q1 + j]
        for j in range(q0, q0 + n):
            G[i, j] = 0.0
        G[i, q0 + i] = box[i]
    return q0 + n + keep


# ================================================================================================
# covariance bounds: Loewner upper bounds of [M] P [M]^T (the UBIKF's weighted bound)
# ================================================================================================
@njit(cache=True, error_model="numpy")
def weighted_ratio(trace, size_sum):
    """(sigma / sigma0, sigma) of the weighted bound: sigma0 = sqrt(trace) (the point term's
    size), sigma = sigma0 + the interval terms' sizes. A zero point term is dropped (ratio 0)."""
    s0 = np.sqrt(max(trace, 0.0))
    s = s0 + size_sum
    if s0 > 0.0:
        return widen(s / s0), widen(s)
    return 0.0, widen(s)


@njit(cache=True, error_model="numpy")
def sqrt_diag(P, out):
    for i in range(P.shape[0]):
        out[i] = np.sqrt(max(P[i, i], 0.0))


@njit(cache=True, error_model="numpy")
def radius_times(M_r, rows, rc, v, out):
    """out[a] = sum_j M_r[rows[a], j] v[j] for a < rc (widened): an interval matrix's radius
    applied to a non-negative vector. Returns the sum of out."""
    total = 0.0
    for a in range(rc):
        s = 0.0
        Ma = M_r[rows[a]]
        for j in range(v.size):
            s += Ma[j] * v[j]
        out[a] = widen(s)
        total += out[a]
    return total


@njit(cache=True, error_model="numpy")
def predict_bound(A_m, acols, annz, A_r, all_rows, Q, P, sigma, rho, Z, FP, W, APA, out):
    """P+_prior = (s/s0) A_m P A_m^T + s diag(A_r sqrt(diag P)) + Q+ into out."""
    n = P.shape[0]
    sqrt_diag(P, sigma)
    size = radius_times(A_r, all_rows, n, sigma, rho)
    # A_m P A_m^T (Z: zeros)
    fpft_q(A_m, P, Z, n, acols, annz, FP, W, APA)
    tr = 0.0
    for i in range(n):
        tr += APA[i, i]
    ratio, s = weighted_ratio(tr, size)
    for i in range(n):
        for j in range(n):
            out[i, j] = ratio * APA[i, j] + Q[i, j]
        out[i, i] += s * rho[i]


@njit(cache=True, error_model="numpy")
def innovation_bound(Cs, hcols, hnnz, m, P, HP, rho, Rs, S):
    """S+ = (c/c0) C P C^T + c diag(rho) + R+ for the m stacked rows; returns c/c0. HP = C P on
    entry (C row-sparse), rho = C_r sqrt(diag P) for those rows."""
    size = 0.0
    tr = 0.0
    for a in range(m):
        size += rho[a]
        for b in range(a, m):
            t = 0.0
            for s in range(hnnz[b]):
                c = hcols[b, s]
                t += HP[a, c] * Cs[b, c]
            S[a, b] = t
        tr += S[a, a]
    ratio, c = weighted_ratio(tr, size)
    for a in range(m):
        for b in range(a, m):
            S[a, b] = ratio * S[a, b] + Rs[a, b]
            S[b, a] = S[a, b]
        S[a, a] += c * rho[a]
    return ratio


@njit(cache=True, error_model="numpy")
def add_gain_noise(K, Rs, m, KR, out):
    """out += K R+ K^T (K (n, m))."""
    n = K.shape[0]
    for i in range(n):
        for b in range(m):
            t = 0.0
            for a in range(m):
                t += K[i, a] * Rs[a, b]
            KR[i, b] = t
    for i in range(n):
        for j in range(n):
            t = 0.0
            for b in range(m):
                t += KR[i, b] * K[j, b]
            out[i, j] += t


@njit(cache=True, error_model="numpy")
def column_norm(KT, a):
    """|k_a|, the norm of column a of K (row a of K^T)."""
    t = 0.0
    for v in KT[a]:
        t += v * v
    return np.sqrt(t)


@njit(cache=True, error_model="numpy")
def posterior_bound(P, Cs, hcols, hnnz, HP, KT, Rs, m, rho, w, out):
    """P+_post = (d/d0) M P M^T + d sum_a (rho_a / |k_a|) k_a k_a^T + K R+ K^T, M = I - K C.
    w: work arrays (all_cols, m_cnt, no_cols, no_cnt, AT, DT, K, KR); K is left in w's K."""
    all_cols, m_cnt, no_cols, no_cnt, AT, DT, K, KR = w
    n = P.shape[0]
    m_cnt[:] = m
    # M P M^T: the Joseph form with no R term (no_cnt = 0)
    joseph(P, Cs, hcols, hnnz, HP, KT, Rs, no_cols, no_cnt, m, n, all_cols, m_cnt, AT, DT, K, out)
    tr = 0.0
    for i in range(n):
        tr += out[i, i]
    size = 0.0
    for a in range(m):
        size += widen(rho[a] * column_norm(KT, a))
    ratio, d = weighted_ratio(tr, size)
    for i in range(n):
        for j in range(n):
            out[i, j] *= ratio
    for a in range(m):
        knorm = column_norm(KT, a)
        if knorm > 0.0 and rho[a] > 0.0:
            f = widen(d * rho[a] / knorm)
            for i in range(n):
                for j in range(n):
                    out[i, j] += f * KT[a, i] * KT[a, j]
    add_gain_noise(K, Rs, m, KR, out)


# ------------------------------------------------------------------------------------------------
# plain numpy entry points (tests, reports)
# ------------------------------------------------------------------------------------------------


def interval_product(A_m, A_r, B_m, B_r=None) -> tuple[np.ndarray, np.ndarray]:
    """[A] [B] for an interval matrix [A] and a point or interval vector or matrix [B] (B_r None:
    a point); returns (mid, rad) with the shape of A_m @ B_m."""
    A_m, A_r = np.ascontiguousarray(A_m, dtype=np.float64), np.ascontiguousarray(A_r, dtype=np.float64)
    B_m = np.asarray(B_m, dtype=np.float64)
    B_r = np.zeros_like(B_m) if B_r is None else np.asarray(B_r, dtype=np.float64)
    B_m, B_r = np.ascontiguousarray(B_m), np.ascontiguousarray(B_r)
    out_m = np.empty((A_m.shape[0], *B_m.shape[1:]))
    out_r = np.empty_like(out_m)
    if B_m.ndim == 1:
        interval_matvec_into(A_m, A_r, B_m, B_r, out_m, out_r)
    else:
        interval_matmul_into(A_m, A_r, B_m, B_r, out_m, out_r)
    return out_m, out_r


def zonotope_hull(G) -> np.ndarray:
    """Radius of the interval hull of c + G [-1, 1]^p."""
    G = np.ascontiguousarray(G, dtype=np.float64)
    out = np.empty(G.shape[0])
    zonotope_hull_into(G, G.shape[0], G.shape[1], out)
    return out


def congruence_bound(M_m, M_r, P) -> np.ndarray:
    """The weighted Loewner upper bound of M P M^T over every square M in [M_m +- M_r] (`predict_bound`
    with no noise term)."""
    M_m, M_r = np.ascontiguousarray(M_m, dtype=np.float64), np.ascontiguousarray(M_r, dtype=np.float64)
    P = np.ascontiguousarray(P, dtype=np.float64)
    n = P.shape[0]
    cols, nnz = np.empty((n, n), dtype=np.int64), np.empty(n, dtype=np.int64)
    sparse_rows(M_m, n, n, cols, nnz)
    zero, out = np.zeros((n, n)), np.empty((n, n))
    work = [np.empty((n, n)) for _ in range(3)]
    predict_bound(M_m, cols, nnz, M_r, np.arange(n), zero, P, np.empty(n), np.empty(n), zero, *work, out)
    return out


def reduce_zonotope(G, q: int) -> np.ndarray:
    """The generators after boxing the first q of G (n, p): (n, n + p - q) when q > 0."""
    G = np.asarray(G, dtype=np.float64)
    n, p = G.shape
    work = np.zeros((n, n + p))
    work[:, :p] = G
    return work[:, : reduce_order(work, p, q)].copy()


follow_dependencies(__name__)
