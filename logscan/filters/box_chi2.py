"""The chi-square statistic over an innovation box: the UBIKF fault test (docs/algorithms.md section 2).

Per update the innovation is only known to lie in a box ``[r] = r_m +- r_r`` (m components, radii
``r_r >= 0``) and the statistic ``beta(r) = r^T S^-1 r`` (S symmetric positive definite) ranges over

    beta_lo = min_{r in [r]} r^T H r,    beta_hi = max_{r in [r]} r^T H r,    H = S^-1.

Minimum: a strictly convex QP with bound constraints ``lo = r_m - r_r <= r <= hi = r_m + r_r``,
solved exactly by a primal active-set method (`box_qp_argmin`). It is 0 when the box holds 0.

Maximum: a convex function's maximum over a box is attained at one of its 2^m vertices
``r_m + s * r_r`` (s in {-1, +1}^m). They are enumerated in Gray-code order, one coordinate
flipped per vertex: flipping coordinate i moves r by ``d e_i`` with ``d = +-2 r_r[i]``, so with
``w = H r`` kept up to date

    beta(r + d e_i) = beta(r) + d (2 w_i + d H_ii),    w <- w + d H[:, i],

O(m) per vertex (`box_max_vertex`). Coordinates with zero radius do not count. Above
``MAX_VERTEX_DIM`` free coordinates the enumeration is replaced by the bound

    beta_hi <= (|r_m| + r_r)^T |H| (|r_m| + r_r)

(|r_i| <= |r_m,i| + r_r,i for every r in the box, and r^T H r <= sum |H_ij| |r_i| |r_j|), which
over-estimated the maximum by up to 3.4x in the UBIKF runs.

`box_chi2_bounds` evaluates both over N filter steps at once, each on the rows updated at that step.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from logscan.filters.linalg import cho_solve_rows, cholesky
from logscan.numba_cache import follow_dependencies

MAX_VERTEX_DIM = 12

# multiplier tolerance of the active set, relative to the magnitude of the terms of the gradient
_GRAD_RTOL = 64.0 * np.finfo(np.float64).eps

# state of a coordinate in the active set
_FREE = 0
_AT_LO = -1
_AT_HI = 1
_PINNED = 2  # zero radius: fixed for good


@njit(cache=True, error_model="numpy")
def _quad(H, x, m):
    """x[:m]^T H[:m, :m] x[:m]."""
    acc = 0.0
    for i in range(m):
        t = 0.0
        for j in range(m):
            t += H[i, j] * x[j]
        acc += x[i] * t
    return acc


@njit(cache=True, error_model="numpy")
def _qp_min(c, rad, H, m, x, state, free, Hf, L, p):
    """min of x^T H x over c[:m] +- rad[:m] (H[:m, :m] SPD); the minimiser into x[:m].

    Primal active-set method on ``0.5 x^T H x`` (gradient g = H x). Start at the point of the box
    nearest 0 (each coordinate clipped: free where its interval holds 0, else at the bound nearest
    0). Then repeat: with the fixed coordinates held, the step p_F to the minimiser over the free
    ones solves ``H_FF p_F = -g_F`` (Cholesky); move along it until the first free coordinate
    meets a bound (it becomes fixed there) or the full step is taken. After a full step the point
    is optimal when every fixed coordinate's multiplier has the right sign (g_i >= 0 at a lower
    bound, g_i <= 0 at an upper one, up to rounding); otherwise the most violating coordinate is
    freed. Each full step strictly lowers the objective, so no active set repeats and the method
    ends in finitely many steps (about m in practice; capped at 50 (m + 1)). Returns NaN when
    H_FF is not numerically positive definite. Work arrays: free, state (int, m), p (m x 1), Hf, L
    (m x m).
    """
    inside = True
    for i in range(m):
        lo = c[i] - rad[i]
        hi = c[i] + rad[i]
        if lo > 0.0:
            x[i] = lo
            state[i] = _AT_LO
            inside = False
        elif hi < 0.0:
            x[i] = hi
            state[i] = _AT_HI
            inside = False
        else:
            x[i] = 0.0
            state[i] = _FREE
        if rad[i] == 0.0:
            state[i] = _PINNED
    if inside:
        return 0.0
    for _ in range(50 * (m + 1)):
        nf = 0
        for i in range(m):
            if state[i] == _FREE:
                free[nf] = i
                nf += 1
        if nf > 0:
            for a in range(nf):
                t = 0.0
                for j in range(m):
                    t += H[free[a], j] * x[j]
                p[a, 0] = -t
                for b in range(nf):
                    Hf[a, b] = H[free[a], free[b]]
            if not cholesky(Hf, 0, nf, L):
                return np.nan
            cho_solve_rows(L, nf, p, 1)
            alpha = 1.0
            block = -1
            for a in range(nf):
                i = free[a]
                if p[a, 0] > 0.0:
                    t = (c[i] + rad[i] - x[i]) / p[a, 0]
                elif p[a, 0] < 0.0:
                    t = (c[i] - rad[i] - x[i]) / p[a, 0]
                else:
                    continue
                if t < alpha:
                    alpha = t
                    block = a
            if alpha < 0.0:
                alpha = 0.0
            for a in range(nf):
                x[free[a]] += alpha * p[a, 0]
            if block >= 0:
                i = free[block]
                if p[block, 0] > 0.0:
                    x[i] = c[i] + rad[i]
                    state[i] = _AT_HI
                else:
                    x[i] = c[i] - rad[i]
                    state[i] = _AT_LO
                continue
        worst = 0.0
        leave = -1
        for i in range(m):
            if state[i] == _AT_LO or state[i] == _AT_HI:
                t = 0.0
                size = 0.0
                for j in range(m):
                    t += H[i, j] * x[j]
                    size += abs(H[i, j] * x[j])
                v = -t if state[i] == _AT_LO else t
                if v > _GRAD_RTOL * size and v > worst:
                    worst = v
                    leave = i
        if leave < 0:
            break
        state[leave] = _FREE
    return max(_quad(H, x, m), 0.0)


@njit(cache=True, error_model="numpy")
def _max_vertex(c, rad, H, m, act, u, v, G):
    """max of x^T H x over c[:m] +- rad[:m] (H[:m, :m] symmetric positive semi-definite).

    Gray-code walk over the vertices of the coordinates with rad > 0 (the k active ones): vertex t
    differs from vertex t - 1 in bit b = the number of trailing zeros of t. The rank-one update of
    the module docstring, in coordinates scaled by the radii (G = D H D and u = D H v over the
    active coordinates, D = diag(rad)): setting the sign of coordinate b to s changes

        q <- q + 4 (s u_b + G_bb),    u <- u + 2 s G[b, :]

    (a contiguous row: O(k) per vertex). The best vertex is evaluated again from scratch at the end
    (no rounding drift from the 2^k updates). More than MAX_VERTEX_DIM active coordinates: the
    bound (|c| + rad)^T |H| (|c| + rad) instead. Work arrays: act (int, m), u, v (m), G (m x m).
    """
    k = 0
    for i in range(m):
        v[i] = c[i] - rad[i]
        if rad[i] > 0.0:
            act[k] = i
            k += 1
    if k > MAX_VERTEX_DIM:
        acc = 0.0
        for i in range(m):
            ai = abs(c[i]) + rad[i]
            for j in range(m):
                acc += ai * abs(H[i, j]) * (abs(c[j]) + rad[j])
        return acc
    for a in range(k):
        i = act[a]
        t = 0.0
        for j in range(m):
            t += H[i, j] * v[j]
        u[a] = rad[i] * t
        for b in range(k):
            G[a, b] = rad[i] * H[i, act[b]] * rad[act[b]]
    q = _quad(H, v, m)
    best = q
    best_code = 0
    code = 0
    for t in range(1, 1 << k):
        b = 0
        while not (t >> b) & 1:
            b += 1
        code ^= 1 << b
        s = 1.0 if (code >> b) & 1 else -1.0
        q += 4.0 * (s * u[b] + G[b, b])
        Gb = G[b]
        for a in range(k):
            u[a] += 2.0 * s * Gb[a]
        if q > best:
            best = q
            best_code = code
    for a in range(k):
        i = act[a]
        v[i] = c[i] + rad[i] if (best_code >> a) & 1 else c[i] - rad[i]
    return _quad(H, v, m)


@njit(cache=True, error_model="numpy")
def box_qp_argmin(r_mid, r_rad, H):
    """(min, argmin) of r^T H r over the box r_mid +- r_rad (H SPD, r_rad >= 0): `_qp_min`."""
    m = r_mid.shape[0]
    x = np.zeros(m)
    value = _qp_min(
        r_mid, r_rad, H, m, x, np.empty(m, np.int64), np.empty(m, np.int64),
        np.empty((m, m)), np.empty((m, m)), np.empty((m, 1)),
    )  # fmt: skip
    return value, x


@njit(cache=True, error_model="numpy")
def box_qp_min(r_mid, r_rad, H):
    """beta_lo = min over r in r_mid +- r_rad of r^T H r (H = S^-1 SPD, r_rad >= 0); 0 when the box
    holds 0; NaN when H is not numerically positive definite. Primal active set: `_qp_min`."""
    return box_qp_argmin(r_mid, r_rad, H)[0]


@njit(cache=True, error_model="numpy")
def box_max_vertex(r_mid, r_rad, H):
    """beta_hi = max over r in r_mid +- r_rad of r^T H r (H = S^-1 SPD, r_rad >= 0): the best of
    the box's vertices (Gray-code enumeration) for up to MAX_VERTEX_DIM coordinates of non-zero
    radius; above that the upper bound (|r_mid| + r_rad)^T |H| (|r_mid| + r_rad), which can
    over-estimate the maximum (by up to 3.4x in the UBIKF runs). `_max_vertex`."""
    m = r_mid.shape[0]
    return _max_vertex(r_mid, r_rad, H, m, np.empty(m, np.int64), np.empty(m), np.empty(m), np.empty((m, m)))


@njit(cache=True, error_model="numpy")
def _bounds_loop(r_mid, r_rad, S, mask, beta_lo, beta_hi):
    """Per step: gather the masked rows, H = S_sub^-1 by Cholesky, then `_qp_min` and `_max_vertex`.
    NaN for a step with no row, a non-finite gathered value or an S_sub that is not positive
    definite. Every work array is allocated once, for the largest m."""
    N, M = r_mid.shape
    idx = np.empty(M, np.int64)
    c = np.empty(M)
    rad = np.empty(M)
    Ss = np.empty((M, M))
    L = np.empty((M, M))
    H = np.empty((M, M))
    Hf = np.empty((M, M))
    x = np.empty(M)
    w = np.empty(M)
    iw1 = np.empty(M, np.int64)
    iw2 = np.empty(M, np.int64)
    p = np.empty((M, 1))
    for k in range(N):
        beta_lo[k] = np.nan
        beta_hi[k] = np.nan
        m = 0
        for j in range(M):
            if mask[k, j]:
                idx[m] = j
                m += 1
        if m == 0:
            continue
        ok = True
        for a in range(m):
            c[a] = r_mid[k, idx[a]]
            rad[a] = r_rad[k, idx[a]]
            ok = ok and np.isfinite(c[a]) and np.isfinite(rad[a]) and rad[a] >= 0.0
            for b in range(m):
                Ss[a, b] = S[k, idx[a], idx[b]]
        if not ok or not cholesky(Ss, 0, m, L):
            continue
        for a in range(m):
            for b in range(m):
                H[a, b] = 1.0 if a == b else 0.0
        cho_solve_rows(L, m, H, m)
        for a in range(m):  # symmetric to the last bit
            for b in range(a):
                s = 0.5 * (H[a, b] + H[b, a])
                H[a, b] = s
                H[b, a] = s
        beta_lo[k] = _qp_min(c, rad, H, m, x, iw1, iw2, Hf, L, p)
        beta_hi[k] = _max_vertex(c, rad, H, m, iw1, w, x, Hf)


def box_chi2_bounds(
    r_mid: np.ndarray, r_rad: np.ndarray, S: np.ndarray, rows: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Per step k (N steps), over the measurement rows that were updated at that step
    (finite r_mid[k, j]; S[k] is (m_total, m_total) NaN-padded outside those rows), the minimum and
    maximum of r^T S_k^-1 r over the box r_mid[k] +- r_rad[k] restricted to those rows. Returns
    (beta_lo (N,), beta_hi (N,)), NaN where no row was updated. One numba loop over the steps.

    r_mid, r_rad: (N, m_total); S: (N, m_total, m_total). ``rows`` (optional, bool (N, m_total))
    narrows the updated rows further (a row counts where it is True and r_mid is finite). With J
    the updated rows of step k, H = (S_k[J, J])^-1 (Cholesky) and

        beta_lo[k] = min_{r in r_mid[k, J] +- r_rad[k, J]} r^T H r   (`box_qp_min`: active set)
        beta_hi[k] = max_{r in r_mid[k, J] +- r_rad[k, J]} r^T H r   (`box_max_vertex`)

    beta_hi is the exact vertex maximum up to MAX_VERTEX_DIM rows of non-zero radius, above that
    the over-estimate (|r_m| + r_r)^T |H| (|r_m| + r_r). Both are NaN at a step whose r_rad or S
    is not finite on J, whose radius is negative, or whose S_k[J, J] is not positive definite.
    """
    r_mid = np.ascontiguousarray(r_mid, dtype=np.float64)
    r_rad = np.ascontiguousarray(r_rad, dtype=np.float64)
    S = np.ascontiguousarray(S, dtype=np.float64)
    if r_mid.ndim != 2 or r_rad.shape != r_mid.shape or S.shape != (*r_mid.shape, r_mid.shape[1]):
        raise ValueError(
            f"box_chi2_bounds wants r_mid, r_rad (N, m) and S (N, m, m); got {r_mid.shape}, {r_rad.shape}, {S.shape}"
        )
    mask = np.isfinite(r_mid)
    if rows is not None:
        rows = np.asarray(rows, dtype=bool)
        if rows.shape != r_mid.shape:
            raise ValueError(f"box_chi2_bounds: rows has shape {rows.shape}, r_mid {r_mid.shape}")
        mask &= rows
    beta_lo = np.empty(r_mid.shape[0])
    beta_hi = np.empty(r_mid.shape[0])
    _bounds_loop(r_mid, r_rad, S, mask, beta_lo, beta_hi)
    return beta_lo, beta_hi


follow_dependencies(__name__)
