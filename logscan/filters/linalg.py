"""Small dense linear algebra of the EKF kernel, on preallocated arrays (numba).

Sizes n <= a few tens, m <= n; every function writes into arrays its caller allocated once, so
the kernel's step loop never allocates. Matrices are C-ordered: row-wise loops read contiguous
memory; the sparse products skip the zeros of a Jacobian's rows (`sparse_rows` lists them).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from logscan.numba_cache import follow_dependencies

# error_model="numpy": float division without the Python-style zero checks (no division here
# can see a zero: Cholesky pivots are checked > 0 first); not fastmath, NaN checks still hold.


@njit(cache=True, error_model="numpy")
def cholesky(A, r, m, L):
    """Lower Cholesky factor of the block A[r:r+m, r:r+m] into L[:m, :m]; False when that block
    is not positive definite."""
    for j in range(m):
        s = A[r + j, r + j]
        for c in range(j):
            s -= L[j, c] * L[j, c]
        if not (s > 0.0) or not np.isfinite(s):
            return False
        d = np.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, m):
            t = A[r + i, r + j]
            for c in range(j):
                t -= L[i, c] * L[j, c]
            L[i, j] = t / d
    return True


@njit(cache=True, error_model="numpy")
def forward_sq(L, m, b, r, v):
    """|L^-1 b[r:r+m]|^2: solve L v = b[r:r+m] (forward substitution) and return v^T v."""
    acc = 0.0
    for i in range(m):
        t = b[r + i]
        for c in range(i):
            t -= L[i, c] * v[c]
        t /= L[i, i]
        v[i] = t
        acc += t * t
    return acc


@njit(cache=True, error_model="numpy")
def forward_rows(L, m, B, n):
    """Solve L X = B[:m, :n] in place (forward substitution), all n columns at once."""
    for i in range(m):
        Bi = B[i]
        for c in range(i):
            l = L[i, c]
            Bc = B[c]
            for j in range(n):
                Bi[j] -= l * Bc[j]
        d = 1.0 / L[i, i]
        for j in range(n):
            Bi[j] *= d


@njit(cache=True, error_model="numpy")
def backward_rows(L, m, B, n):
    """Solve L^T X = B[:m, :n] in place (back substitution), all n columns at once."""
    for i in range(m - 1, -1, -1):
        Bi = B[i]
        for c in range(i + 1, m):
            l = L[c, i]
            Bc = B[c]
            for j in range(n):
                Bi[j] -= l * Bc[j]
        d = 1.0 / L[i, i]
        for j in range(n):
            Bi[j] *= d


@njit(cache=True, error_model="numpy")
def cho_solve_rows(L, m, B, n):
    """Solve (L L^T) X = B[:m, :n] in place, all n columns at once (rows are contiguous)."""
    forward_rows(L, m, B, n)  # L V = B
    backward_rows(L, m, B, n)  # L^T X = V


@njit(cache=True, error_model="numpy")
def gain_rows(L, m, HP, V, KT, n):
    """K^T = S^-1 H P (S = L L^T) row by row, in two halves: V = L^-1 H P, then K^T = L^-T V;
    V is kept (P - V^T V is the short covariance update). The operations of `cho_solve_rows`."""
    for i in range(m):
        for j in range(n):
            V[i, j] = HP[i, j]
    forward_rows(L, m, V, n)  # L V = H P
    for i in range(m):
        for j in range(n):
            KT[i, j] = V[i, j]
    backward_rows(L, m, KT, n)  # L^T K^T = V


@njit(cache=True, error_model="numpy")
def short_update(P, V, m, n, keep, out):
    """The short covariance update out = P - V^T V (V = L^-1 H P, S = L L^T, so V^T V = K S K^T
    = K H P) on the lower triangle, mirrored, row by row. Returns True when every variance keeps
    more than ``keep`` of its prior (out[i, i] > keep P[i, i]); False also when one is not finite.

    For a finite P (the kernel's prior always is), that check is the whole finite check: every V[a, i]
    enters out[i, i], and |V[a, i] V[a, j]| <= sqrt(P[i, i] P[j, j]) when the variances pass."""
    ok = True
    for i in range(n):
        Oi = out[i]
        Pi = P[i]
        for j in range(i + 1):
            Oi[j] = Pi[j]
        for a in range(m):
            Va = V[a]
            f = Va[i]
            for j in range(i + 1):
                Oi[j] -= f * Va[j]
        if not (Oi[i] > keep * Pi[i]) or not np.isfinite(Oi[i]):
            ok = False
    for i in range(n):
        for j in range(i + 1, n):
            out[i, j] = out[j, i]
    return ok


@njit(cache=True, error_model="numpy")
def sparse_rows(M, m, n, cols, nnz):
    """Column indices of the non-zeros of each row of M[:m, :n] into cols[a, :nnz[a]] (the rest of
    cols[a] is overwritten too). Branch-free: every index is written, the count moves on a non-zero
    (a Jacobian's pattern is not one a branch predictor learns)."""
    for a in range(m):
        c = 0
        Ma = M[a]
        ca = cols[a]
        for j in range(n):
            ca[c] = j
            c += Ma[j] != 0.0
        nnz[a] = c


@njit(cache=True, error_model="numpy")
def pattern_holds(bits, outside):
    """True when every entry of a matrix that ``outside`` marks (-1) is a zero of either sign, so
    the pattern `grow_pattern` keeps still covers all of its non-zeros (NaN and inf among them).
    ``bits``: the matrix's entries as int64 (a C-ordered (n, n) float64 array's flat int64 view);
    shifting out the sign bit leaves zero exactly for +0.0 and -0.0. One OR per entry, no branch:
    numba vectorises it, a small part of `sparse_rows`' serial count."""
    acc = np.int64(0)
    for i in range(bits.size):
        acc |= (bits[i] << 1) & outside[i]
    return acc == 0


@njit(cache=True, error_model="numpy")
def grow_pattern(M, n, outside, cols, nnz):
    """Add the non-zeros of M[:n, :n] (NaN counts) to the kept pattern (outside[i * n + j] = 0
    from then on), and list the pattern's columns of each row into cols[i, :nnz[i]]. The pattern
    only grows: an entry of it that is zero at a step adds +-0 terms to the sparse products, which
    leave their sums unchanged (the factors they meet are finite)."""
    for i in range(n):
        c = 0
        for j in range(n):
            if M[i, j] != 0.0:
                outside[i * n + j] = 0
            if outside[i * n + j] == 0:
                cols[i, c] = j
                c += 1
        nnz[i] = c


@njit(cache=True, error_model="numpy")
def sparse_mm(M, cols, nnz, m, B, n, out):
    """out[:m, :n] = M[:m] B[:, :n] for row-sparse M (row a's non-zeros at cols[a, :nnz[a]])."""
    for a in range(m):
        Oa = out[a]
        for j in range(n):
            Oa[j] = 0.0
        for s in range(nnz[a]):
            c = cols[a, s]
            f = M[a, c]
            Bc = B[c]
            for j in range(n):
                Oa[j] += f * Bc[j]


@njit(cache=True, error_model="numpy")
def sym_plus_product(base, C, idx, cnt, B, n, out):
    """out = base + C B when the result is symmetric: the lower triangle
    out[i, j<=i] = base[i, j] + sum_s C[i, c] B[c, j] (c = idx[i, s], s < cnt[i]: the non-zeros
    of C's row i), mirrored to the upper triangle. (The lower triangle pairs the short rows with
    the sparse bottom rows of a Jacobian: fewer products than the upper one.)"""
    for i in range(n):
        Oi = out[i]
        for j in range(i + 1):
            Oi[j] = base[i, j]
        for s in range(cnt[i]):
            c = idx[i, s]
            f = C[i, c]
            Bc = B[c]
            for j in range(i + 1):
                Oi[j] += f * Bc[j]
    for i in range(n):
        for j in range(i + 1, n):
            out[i, j] = out[j, i]


@njit(cache=True, error_model="numpy")
def fpft_q(F, P, Q, n, fcols, fnnz, FP, W, out):
    """out = F P F^T + Q for symmetric P, F row-sparse (fcols/fnnz); FP, W (n, n) are work.

    FP = F P (row by row), W = (F P)^T = P F^T (P symmetric), out = Q + F W (lower triangle,
    mirrored).
    """
    sparse_mm(F, fcols, fnnz, n, P, n, FP)
    for i in range(n):
        for j in range(n):
            W[j, i] = FP[i, j]
    sym_plus_product(Q, F, fcols, fnnz, W, n, out)


@njit(cache=True, error_model="numpy")
def joseph(P, Hs, hcols, hnnz, HP, KT, Rs, rcols, rnnz, m, n, all_cols, m_cnt, AT, DT, K, out):
    """Joseph form out = (I - K H) P (I - K H)^T + K R K^T, K = KT^T, without forming I - K H:

    A = (I - K H) P;  A (I - K H)^T + K R K^T = A + (K R - A H^T) K^T = A + D K^T, and as the
    result is symmetric it is evaluated transposed, row by row (contiguous rows only):
    A^T = P - (H P)^T K^T (P symmetric),  D^T = R^T K^T - H A^T,  out = A^T + K D^T.
    out is the lower triangle, mirrored (the symmetric part, as the reference's 0.5 (P + P^T)).
    rcols/rnnz: the non-zero rows of each column of R. AT (n, n), DT (m, n) and K (n, m) are
    work; all_cols[i, :m] = 0..m-1, m_cnt[:] = m.
    """
    for c in range(n):  # A^T[c, :] = P[c, :] - sum_a (H P)[a, c] K^T[a, :]
        ATc = AT[c]
        for j in range(n):
            ATc[j] = P[c, j]
        for a in range(m):
            h = HP[a, c]
            KTa = KT[a]
            for j in range(n):
                ATc[j] -= h * KTa[j]
    for a in range(m):  # D^T[a, :] = sum_b R[b, a] K^T[b, :] - sum_c H[a, c] A^T[c, :]
        DTa = DT[a]
        for j in range(n):
            DTa[j] = 0.0
        for s in range(rnnz[a]):  # the non-zeros of R's column a (R is block diagonal)
            b = rcols[a, s]
            r = Rs[b, a]
            KTb = KT[b]
            for j in range(n):
                DTa[j] += r * KTb[j]
        for s in range(hnnz[a]):  # the non-zeros of H's row a
            c = hcols[a, s]
            h = Hs[a, c]
            ATc = AT[c]
            for j in range(n):
                DTa[j] -= h * ATc[j]
        for i in range(n):
            K[i, a] = KT[a, i]
    sym_plus_product(AT, K, all_cols, m_cnt, DT, n, out)


@njit(cache=True, error_model="numpy")
def all_finite(a):
    for v in a:
        if not np.isfinite(v):
            return False
    return True


@njit(cache=True, error_model="numpy")
def all_finite2(A):
    for i in range(A.shape[0]):
        if not all_finite(A[i]):
            return False
    return True


@njit(cache=True, error_model="numpy")
def nan_fill(M):
    for i in range(M.shape[0]):
        for j in range(M.shape[1]):
            M[i, j] = np.nan


@njit(cache=True, error_model="numpy")
def wrap_angle(a):
    return (a + np.pi) % (2.0 * np.pi) - np.pi


@njit(cache=True, error_model="numpy")
def innovations(zk, rows, first, m, hx, wrap, R_all, R_std_k, dyn_R, y, Rs):
    """y~ = z - h(x_prior) (angles wrapped) and R of the m outputs ``rows[first:first + m]`` into
    y[:m] and Rs[:m, :m]; a finite positive per-sample std (``R_std_k``) replaces its row and column."""
    for a in range(m):
        j = rows[first + a]
        ya = zk[j] - hx[a]
        if wrap[j]:
            ya = wrap_angle(ya)
        y[a] = ya
        for b in range(m):
            Rs[a, b] = R_all[j, rows[first + b]]
    if dyn_R:  # per-sample noise (a receiver's own accuracy estimate): replaces row and column
        for a in range(m):
            sd = R_std_k[rows[first + a]]
            if np.isfinite(sd) and sd > 0.0:
                for b in range(m):
                    Rs[a, b] = 0.0
                    Rs[b, a] = 0.0
                Rs[a, a] = sd * sd


@njit(cache=True, error_model="numpy")
def innovation_covariance(Hs, hcols, hnnz, m, P, n, HP, Rs, S):
    """HP = H P (H sparse) and S = H P H^T + R (upper triangle, mirrored) of the m rows of Hs."""
    sparse_mm(Hs, hcols, hnnz, m, P, n, HP)
    for a in range(m):
        for b in range(a, m):
            t = 0.0
            for s in range(hnnz[b]):
                c = hcols[b, s]
                t += HP[a, c] * Hs[b, c]
            S[a, b] = t + Rs[a, b]
        for b in range(a):
            S[a, b] = S[b, a]


follow_dependencies(__name__)  # the disk cache filed by what the kernels compile (logscan.numba_cache)
