"""The shared EKF core: one numba kernel that filters a whole aligned run, and its trace.

Every model-based detector reads the `EkfTrace` this module returns (ALGORITHMS.md section 0);
none carries its own filter. The kernel `ekf_run` is model-agnostic: it dispatches f/F/h/H on
(model_id, group_id) through `logscan.models.kernels`, so one cached compilation serves every model.

Conventions (step k on the grid, u_k the input held at step k):
 - k = 0: x_prior = x0, P_prior = P0 (no prediction); k > 0: x_prior = f(x_post_{k-1}, u_k).
 - Multi-rate: only groups with a fresh sample at k are stacked into z, H, R.
 - A fresh group whose sample is non-finite or outside the group's physical range is skipped
   for that step as a whole and flagged in `rejected[k, g]`.
 - Inputs: a non-finite input row is replaced by the last finite one (`input_held[k]`).
 - Divergence (a non-positive-definite S, or a non-finite state or covariance) is flagged in
   `diverged[k]`; the filter restarts from x0/P0 at once, and then re-seeds every state that a
   group observes directly (z = gain * x[i]: position, attitude, gyro, encoders ...) from that
   group's next valid sample (x[i] = z / gain, P row/column i cleared, P[i, i] = R[j, j] / gain^2),
   instead of updating with it (`seeded[k, g]`). States no group observes directly keep x0/P0.
   When no x0 is given, the run starts in this seeding state too.
 - An episode of divergence is the diverged steps up to the next successful update; the trace
   lists episodes with their step counts.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit

from logscan.align import AlignedRun
from logscan.errors import ModelError
from logscan.models import kernels
from logscan.models.base import Model

# error_model="numpy": float division without the Python-style zero checks (no division here
# can see a zero: Cholesky pivots are checked > 0 first); not fastmath, NaN checks still hold.


# =============================================================================================
# small dense linear algebra on preallocated arrays (sizes n <= a few tens, m <= n)
# =============================================================================================
@njit(cache=True, error_model="numpy")
def _cholesky(A, r, m, L):
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
def _forward_sq(L, m, b, r, v):
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
def _cho_solve_rows(L, m, B, n):
    """Solve (L L^T) X = B[:m, :n] in place, all n columns at once (rows are contiguous)."""
    for i in range(m):  # L V = B
        Bi = B[i]
        for c in range(i):
            l = L[i, c]
            Bc = B[c]
            for j in range(n):
                Bi[j] -= l * Bc[j]
        d = 1.0 / L[i, i]
        for j in range(n):
            Bi[j] *= d
    for i in range(m - 1, -1, -1):  # L^T X = V
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
def _sparse_rows(M, m, n, cols, nnz):
    """Column indices of the non-zeros of each row of M[:m, :n] into cols[a, :nnz[a]]."""
    for a in range(m):
        c = 0
        for j in range(n):
            if M[a, j] != 0.0:
                cols[a, c] = j
                c += 1
        nnz[a] = c


@njit(cache=True, error_model="numpy")
def _sparse_mm(M, cols, nnz, m, B, n, out):
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
def _sym_plus_product(base, C, idx, cnt, B, n, out):
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
def _fpft_q(F, P, Q, n, fcols, fnnz, FP, W, out):
    """out = F P F^T + Q for symmetric P, F row-sparse (fcols/fnnz); FP, W (n, n) are work.

    FP = F P (row by row), W = (F P)^T = P F^T (P symmetric), out = Q + F W (lower triangle,
    mirrored).
    """
    _sparse_mm(F, fcols, fnnz, n, P, n, FP)
    for i in range(n):
        for j in range(n):
            W[j, i] = FP[i, j]
    _sym_plus_product(Q, F, fcols, fnnz, W, n, out)


@njit(cache=True, error_model="numpy")
def _all_finite(a):
    for v in a:
        if not np.isfinite(v):
            return False
    return True


@njit(cache=True, error_model="numpy")
def _all_finite2(A):
    for i in range(A.shape[0]):
        if not _all_finite(A[i]):
            return False
    return True


@njit(cache=True, error_model="numpy")
def _nan_fill(M):
    for i in range(M.shape[0]):
        for j in range(M.shape[1]):
            M[i, j] = np.nan


@njit(cache=True, error_model="numpy")
def _wrap_angle(a):
    return (a + np.pi) % (2.0 * np.pi) - np.pi


@njit(cache=True, error_model="numpy")
def _restart(x, P, x0, P0, seed_done):
    """Divergence: back to x0/P0, every direct group to be re-seeded; returns True."""
    n = x.size
    for i in range(n):
        x[i] = x0[i]
        for j in range(n):
            P[i, j] = P0[i, j]
    for g in range(seed_done.size):
        seed_done[g] = False
    return True


@njit(cache=True, error_model="numpy")
def _store(k, x, P, xs, P_diag, P_full, store_P):
    n = x.size
    for i in range(n):
        xs[k, i] = x[i]
        P_diag[k, i] = P[i, i]
    if store_P:
        for i in range(n):
            for j in range(n):
                P_full[k, i, j] = P[i, j]


@njit(cache=True, error_model="numpy")
def _joseph(P, Hs, hcols, hnnz, HP, KT, Rs, rcols, rnnz, m, n, all_cols, m_cnt, AT, DT, K, out):
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
    _sym_plus_product(AT, K, all_cols, m_cnt, DT, n, out)


# =============================================================================================
# the kernel
# =============================================================================================
@njit(cache=True, error_model="numpy")
def ekf_run(model_id, p, x0, P0, Q, u, u_default, z, fresh, group_ids, group_offsets,
            group_sizes, R_all, range_lo, range_hi, wrap, direct_idx, direct_gain, dt,
            seed_at_start,
            x_prior, x_post, P_prior_diag, P_post_diag, P_prior_full, P_post_full,
            y_out, S_out, S_diag_out, K_out, nis, nis_group, m_k, gain_norm,
            updated, rejected, seeded, diverged, input_held):
    """Filter N steps; every output array is preallocated by the caller (NaN / False filled,
    except S_out and K_out, which the kernel fills step by step: NaN where not updated).

    P_prior_full, P_post_full, S_out, K_out are stored when their first dimension is N
    (pass zero-length arrays to skip them). All work arrays are allocated once, before the loop.
    """
    N = u.shape[0]
    n = x0.size
    nu = u.shape[1]
    G = group_ids.size
    m_total = z.shape[1]
    store_P = P_prior_full.shape[0] == N
    store_S = S_out.shape[0] == N
    store_K = K_out.shape[0] == N
    x = x0.copy()
    P = P0.copy()
    u_last = u_default.copy()
    # direct groups: every output observes one state
    is_direct = np.zeros(G, dtype=np.bool_)
    for g in range(G):
        ok = True
        for j in range(group_offsets[g], group_offsets[g] + group_sizes[g]):
            if direct_idx[j] < 0:
                ok = False
        is_direct[g] = ok
    seed_done = np.zeros(G, dtype=np.bool_)
    pending = seed_at_start
    # counters start from a typed zero: a literal 0 makes numba compile every helper they
    # reach twice (once for Literal[int](0), once for int64), doubling the cold compile
    zero = np.int64(0)
    # work arrays (allocated once)
    rows, sel_g = np.empty(m_total, dtype=np.int64), np.empty(G, dtype=np.int64)
    x_new, kv, xs, x_upd = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    F, W, P_upd = np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    Aw, Jw, Jnw = np.empty((n, n)), np.empty((n, n)), np.empty((n, n))  # RK4 Jacobian stages
    R3, D3 = np.empty((3, 3)), np.empty((3, 3, 3))  # quadcopter rotation and its derivatives
    # non-zero columns per row of F and of H
    fcols, fnnz = np.empty((n, n), dtype=np.int64), np.empty(n, dtype=np.int64)
    hcols, hnnz = np.empty((m_total, n), dtype=np.int64), np.empty(m_total, dtype=np.int64)
    hx, y, v = np.zeros(m_total), np.zeros(m_total), np.zeros(m_total)
    Hs, HP, KT = np.zeros((m_total, n)), np.zeros((m_total, n)), np.zeros((m_total, n))
    S, Rs = np.zeros((m_total, m_total)), np.zeros((m_total, m_total))
    RsT = np.zeros((m_total, m_total))
    rcols, rnnz = np.empty((m_total, m_total), dtype=np.int64), np.empty(m_total, dtype=np.int64)
    L, Lg = np.zeros((m_total, m_total)), np.zeros((m_total, m_total))
    D, DT = np.zeros((n, m_total)), np.zeros((m_total, n))
    all_cols = np.empty((n, m_total), dtype=np.int64)  # all_cols[i, a] = a
    for i in range(n):
        for a in range(m_total):
            all_cols[i, a] = a
    m_cnt = np.empty(n, dtype=np.int64)

    for k in range(N):
        # ---- input ----------------------------------------------------------------------
        uk = u[k]
        if _all_finite(uk):
            for i in range(nu):
                u_last[i] = uk[i]
        else:
            input_held[k] = True
            uk = u_last
        # ---- predict: x_prior = f(x_post, u); P_prior = F P F^T + Q -----------------------
        if k > 0:
            kernels.predict_into(model_id, p, x, uk, dt, x_new, F, kv, xs, Aw, Jw, Jnw)
            _sparse_rows(F, n, n, fcols, fnnz)
            _fpft_q(F, P, Q, n, fcols, fnnz, Aw, W, P_upd)
            P, P_upd = P_upd, P
            for i in range(n):
                x[i] = x_new[i]
            if not (_all_finite(x) and _all_finite2(P)):
                diverged[k] = pending = _restart(x, P, x0, P0, seed_done)
        _store(k, x, P, x_prior, P_prior_diag, P_prior_full, store_P)
        # ---- select the fresh, valid groups -------------------------------------------------
        m = zero
        ng = zero
        for g in range(G):
            if not fresh[k, g]:
                continue
            o = group_offsets[g]
            ok = True
            for j in range(o, o + group_sizes[g]):
                zj = z[k, j]
                if not np.isfinite(zj) or zj < range_lo[j] or zj > range_hi[j]:
                    ok = False
            if not ok:
                rejected[k, g] = True
                continue
            if pending and is_direct[g] and not seed_done[g]:
                # re-seed the directly observed states from this sample
                for j in range(o, o + group_sizes[g]):
                    i = direct_idx[j]
                    gain = direct_gain[j]
                    x[i] = z[k, j] / gain
                    for c in range(n):
                        P[i, c] = 0.0
                        P[c, i] = 0.0
                    P[i, i] = R_all[j, j] / (gain * gain)
                seed_done[g] = True
                seeded[k, g] = True
                continue
            sel_g[ng] = g
            ng += 1
            for j in range(o, o + group_sizes[g]):
                rows[m] = j
                m += 1
        if pending:
            still = False
            for g in range(G):
                if is_direct[g] and not seed_done[g]:
                    still = True
            pending = still
        # ---- update -----------------------------------------------------------------------
        if store_S:  # S_out and K_out come unfilled (np.empty): NaN where not updated
            _nan_fill(S_out[k])
        if store_K:
            _nan_fill(K_out[k])
        if m > 0:
            r = zero
            for a in range(ng):
                g = sel_g[a]
                kernels.meas_into(model_id, group_ids[g], p, x, uk, r, hx, Hs, R3, D3)
                r += group_sizes[g]
            _sparse_rows(Hs, m, n, hcols, hnnz)
            for a in range(m):
                j = rows[a]
                # y~ = z - h(x_prior)
                ya = z[k, j] - hx[a]
                if wrap[j]:
                    ya = _wrap_angle(ya)
                y[a] = ya
                for b in range(m):
                    Rs[a, b] = R_all[j, rows[b]]
                    RsT[b, a] = Rs[a, b]
            _sparse_rows(RsT, m, m, rcols, rnnz)
            # H P (H sparse: its rows' non-zeros only)
            _sparse_mm(Hs, hcols, hnnz, m, P, n, HP)
            # S = H P H^T + R (upper triangle, mirrored)
            for a in range(m):
                for b in range(a, m):
                    t = 0.0
                    for s in range(hnnz[b]):
                        c = hcols[b, s]
                        t += HP[a, c] * Hs[b, c]
                    S[a, b] = t + Rs[a, b]
                for b in range(a):
                    S[a, b] = S[b, a]
            ok = _cholesky(S, zero, m, L)
            if ok:
                # K = P H^T S^-1  via  S K^T = H P  (P symmetric)
                for a in range(m):
                    for j in range(n):
                        KT[a, j] = HP[a, j]
                _cho_solve_rows(L, m, KT, n)
                for i in range(n):
                    t = x[i]
                    for a in range(m):
                        t += KT[a, i] * y[a]
                    x_upd[i] = t  # x_post = x_prior + K y~
                # P_post = (I - K H) P (I - K H)^T + K R K^T   (Joseph form)
                m_cnt[:] = m
                _joseph(P, Hs, hcols, hnnz, HP, KT, Rs, rcols, rnnz, m, n, all_cols, m_cnt, W, DT,
                        D, P_upd)
                if _all_finite(x_upd) and _all_finite2(P_upd):
                    for i in range(n):
                        x[i] = x_upd[i]
                    P, P_upd = P_upd, P
                    m_k[k] = m
                    # NIS = y^T S^-1 y = |L^-1 y|^2
                    nis[k] = _forward_sq(L, m, y, zero, v)
                    knorm = 0.0
                    for a in range(m):
                        for i in range(n):
                            knorm += KT[a, i] * KT[a, i]
                    gain_norm[k] = np.sqrt(knorm)
                    for a in range(m):
                        j = rows[a]
                        y_out[k, j] = y[a]
                        S_diag_out[k, j] = S[a, a]
                        if store_S:
                            for b in range(m):
                                S_out[k, j, rows[b]] = S[a, b]
                        if store_K:
                            for i in range(n):
                                K_out[k, i, j] = KT[a, i]
                    # per-group NIS on the group's own block of S
                    r = zero
                    for a in range(ng):
                        g = sel_g[a]
                        mg = group_sizes[g]
                        updated[k, g] = True
                        if r == 0:  # the leading block's factor is L's leading block
                            nis_group[k, g] = _forward_sq(L, mg, y, zero, v)
                        else:
                            _cholesky(S, r, mg, Lg)
                            nis_group[k, g] = _forward_sq(Lg, mg, y, r, v)
                        r += mg
                else:
                    ok = False
            if not ok:
                diverged[k] = pending = _restart(x, P, x0, P0, seed_done)
        _store(k, x, P, x_post, P_post_diag, P_post_full, store_P)


def cache_depends_on(dispatcher, *modules) -> None:
    """Make the on-disk numba cache of ``dispatcher`` stale when any of ``modules`` changes.

    numba keys a cached function on its own source file only, but `ekf_run` compiles the model
    functions of `logscan.models.kernels` into itself: without this, editing a model would leave
    the EKF running the old equations from the cache. The index's source stamp becomes
    (own stamp, sha256 of each dependency). Uses numba internals; a no-op if they change.
    """
    import hashlib

    cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    if cache_file is None or not hasattr(cache_file, "_source_stamp"):
        return
    digests = []
    for module in modules:
        with open(module.__file__, "rb") as fh:
            digests.append(hashlib.sha256(fh.read()).hexdigest())
    cache_file._source_stamp = (cache_file._source_stamp, *digests)


cache_depends_on(ekf_run, kernels)


# =============================================================================================
# trace and wrapper
# =============================================================================================
@dataclass
class DivergenceEpisode:
    """Diverged steps up to the next successful update (first step, last step, count)."""

    start_step: int
    end_step: int
    n_steps: int
    t_start: float
    t_end: float


@dataclass
class EkfTrace:
    """Per-step output of the shared EKF (N grid steps, n states, G groups, m_total = sum m_g).

    Group g's measurement columns are `group_offsets[g] : group_offsets[g] + group_sizes[g]`
    (`group_slice(name)`). Arrays with NaN mean "not updated at this step".
    """

    model_name: str
    state_names: list[str]
    group_names: list[str]
    group_offsets: np.ndarray  # (G,) int
    group_sizes: np.ndarray  # (G,) int
    t: np.ndarray  # (N,)
    dt: float
    x_prior: np.ndarray  # (N, n)
    x_post: np.ndarray  # (N, n)
    P_prior_diag: np.ndarray  # (N, n)
    P_post_diag: np.ndarray  # (N, n)
    y: np.ndarray  # (N, m_total) innovation z - h(x_prior), NaN where not updated
    S_diag: np.ndarray  # (N, m_total) diagonal of S, NaN where not updated
    nis: np.ndarray  # (N,) y^T S^-1 y over the stacked update, NaN without update
    nis_group: np.ndarray  # (N, G) y_g^T S_gg^-1 y_g per group, NaN where not updated
    m_k: np.ndarray  # (N,) int, measurements in the update (0: none)
    gain_norm: np.ndarray  # (N,) Frobenius norm of K, NaN without update
    updated: np.ndarray  # (N, G) bool, group used in the update
    rejected: np.ndarray  # (N, G) bool, fresh sample non-finite or outside the physical range
    seeded: np.ndarray  # (N, G) bool, sample used to (re-)seed directly observed states
    diverged: np.ndarray  # (N,) bool, divergence detected at this step (filter restarted)
    input_held: np.ndarray  # (N,) bool, non-finite input replaced by the last finite one
    Q: np.ndarray  # (n, n) process noise used
    R: np.ndarray  # (m_total, m_total) block-diagonal measurement noise used
    P_prior: np.ndarray | None = None  # (N, n, n) when full_P
    P_post: np.ndarray | None = None  # (N, n, n) when full_P
    S: np.ndarray | None = None  # (N, m_total, m_total) padded with NaN, when store_S
    K: np.ndarray | None = None  # (N, n, m_total) padded with NaN, when store_gain
    divergence_episodes: list[DivergenceEpisode] = field(default_factory=list)

    @property
    def n_steps(self) -> int:
        return int(self.t.size)

    def group_index(self, name: str) -> int:
        try:
            return self.group_names.index(name)
        except ValueError:
            raise ModelError(
                f"the trace has no group {name!r}", hint="groups: " + ", ".join(self.group_names)
            ) from None

    def group_slice(self, name: str) -> slice:
        g = self.group_index(name)
        o = int(self.group_offsets[g])
        return slice(o, o + int(self.group_sizes[g]))

    def summary(self) -> dict:
        """JSON-ready counts: updates, rejections and seeds per group, divergence, mean NIS."""
        with np.errstate(invalid="ignore"):
            mean_nis = {
                g: (float(np.nanmean(self.nis_group[:, i])) if self.updated[:, i].any() else None)
                for i, g in enumerate(self.group_names)
            }
        return {
            "steps": self.n_steps,
            "updates": dict(zip(self.group_names, self.updated.sum(axis=0).tolist())),
            "rejected": dict(zip(self.group_names, self.rejected.sum(axis=0).tolist())),
            "seeded": dict(zip(self.group_names, self.seeded.sum(axis=0).tolist())),
            "inputs_held": int(self.input_held.sum()),
            "divergence_episodes": len(self.divergence_episodes),
            "diverged_steps": int(self.diverged.sum()),
            "mean_nis": mean_nis,
        }


def divergence_episodes(
    t: np.ndarray, diverged: np.ndarray, m_k: np.ndarray
) -> list[DivergenceEpisode]:
    """Group diverged steps into episodes: an episode ends at the next successful update."""
    steps = np.flatnonzero(diverged)
    if steps.size == 0:
        return []
    successes = np.cumsum((m_k > 0) & ~diverged)
    new = np.ones(steps.size, dtype=bool)
    new[1:] = successes[steps[1:]] > successes[steps[:-1]]
    starts = np.flatnonzero(new)
    ends = np.append(starts[1:], steps.size) - 1
    return [
        DivergenceEpisode(int(steps[a]), int(steps[b]), int(b - a + 1), float(t[steps[a]]),
                          float(t[steps[b]]))
        for a, b in zip(starts, ends)
    ]


@dataclass
class KernelInputs:
    """The packed arrays `ekf_run` reads (built by `pack_run`; the reference filter reads them
    too)."""

    model_id: int
    p: np.ndarray
    x0: np.ndarray
    P0: np.ndarray
    Q: np.ndarray
    u: np.ndarray
    u_default: np.ndarray
    z: np.ndarray
    fresh: np.ndarray
    group_names: list[str]
    group_ids: np.ndarray
    group_offsets: np.ndarray
    group_sizes: np.ndarray
    R_all: np.ndarray
    range_lo: np.ndarray
    range_hi: np.ndarray
    wrap: np.ndarray
    direct_idx: np.ndarray
    direct_gain: np.ndarray
    dt: float
    seed_at_start: bool


def _square(name: str, value, size: int) -> np.ndarray:
    M = np.asarray(value, dtype=np.float64)
    if M.ndim == 1 and M.size == size:
        M = np.diag(M)
    if M.shape != (size, size):
        raise ModelError(
            f"{name} must be {size} x {size} (or a diagonal of {size}), got shape {M.shape}"
        )
    if not np.all(np.isfinite(M)):
        raise ModelError(f"{name} has non-finite entries")
    return M


def pack_run(model: Model, run: AlignedRun, Q=None, R=None, x0=None, P0=None) -> KernelInputs:
    """Check the run against the model and pack it into the kernel's arrays.

    R: None (each group's profile noise_std, else the model's default_R), or a dict
    group -> (m, m) matrix or (m,) standard deviations.
    """
    n = model.n_states
    N = run.n_steps
    u = np.ascontiguousarray(run.u, dtype=np.float64)
    if u.ndim != 2 or u.shape != (N, model.n_inputs):
        raise ModelError(
            f"model {model.name!r} takes {model.n_inputs} inputs ({', '.join(model.input_names)}) "
            f"but the run has inputs of shape {u.shape} for {N} steps",
            hint="map every model input to a log channel in the profile's [inputs]",
        )
    if not run.groups:
        raise ModelError("the run has no measurement groups: the filter has nothing to update with")
    names = list(run.groups)
    specs = [model.group(g) for g in names]
    sizes = np.array([s.size for s in specs], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    m_total = int(sizes.sum())
    z = np.empty((N, m_total))
    fresh = np.zeros((N, len(names)), dtype=np.bool_)
    R_all = np.zeros((m_total, m_total))
    R = dict(R or {})
    for g, (name, spec) in enumerate(zip(names, specs)):
        grp = run.groups[name]
        zg = np.asarray(grp.z, dtype=np.float64)
        if zg.ndim == 1:
            zg = zg[:, None]
        if zg.shape != (N, spec.size):
            raise ModelError(
                f"group {name!r}: {zg.shape[1] if zg.ndim == 2 else '?'} channels, the model's "
                f"group has {spec.size} ({', '.join(spec.outputs)})",
                hint="list one channel per model output in the profile",
            )
        o = offsets[g]
        z[:, o:o + spec.size] = zg
        fresh[:, g] = np.asarray(grp.fresh, dtype=bool)
        if name in R:
            given = np.square(R[name]) if np.ndim(R[name]) == 1 else R[name]  # std or matrix
            Rg = _square(f"R[{name}]", given, spec.size)
        elif grp.noise_std is not None:
            Rg = np.diag(np.square(np.broadcast_to(np.asarray(grp.noise_std, float), (spec.size,))))
        else:
            Rg = model.default_R(name)
        R_all[o:o + spec.size, o:o + spec.size] = Rg
    unknown_R = sorted(set(R) - set(names))
    if unknown_R:
        raise ModelError(f"R given for group(s) not in the run: {', '.join(unknown_R)}")
    seed = x0 is None
    x0 = model.default_x0() if x0 is None else np.asarray(x0, dtype=np.float64).reshape(-1)
    if x0.size != n or not np.all(np.isfinite(x0)):
        raise ModelError(f"x0 must hold {n} finite values")
    P0 = model.default_P0() if P0 is None else _square("P0", P0, n)
    Q = model.default_Q(run.dt) if Q is None else _square("Q", Q, n)
    finite_rows = np.flatnonzero(np.all(np.isfinite(u), axis=1))
    u_default = u[finite_rows[0]].copy() if finite_rows.size else np.zeros(model.n_inputs)
    direct = [s.direct_map() for s in specs]
    return KernelInputs(
        model_id=int(model.model_id),
        p=np.ascontiguousarray(model.param_vector(run.dt), dtype=np.float64),
        x0=np.ascontiguousarray(x0), P0=np.ascontiguousarray(P0), Q=np.ascontiguousarray(Q),
        u=u, u_default=u_default, z=z, fresh=fresh, group_names=names,
        group_ids=np.array([s.group_id for s in specs], dtype=np.int64),
        group_offsets=offsets, group_sizes=sizes, R_all=R_all,
        range_lo=np.concatenate([np.asarray(s.range_lo, float) for s in specs]),
        range_hi=np.concatenate([np.asarray(s.range_hi, float) for s in specs]),
        wrap=np.concatenate([s.wrap_mask() for s in specs]),
        direct_idx=np.concatenate([d[0] for d in direct]),
        direct_gain=np.concatenate([d[1] for d in direct]),
        dt=float(run.dt), seed_at_start=seed,
    )


def run_ekf(model: Model, run: AlignedRun, Q=None, R=None, x0=None, P0=None, full_P=False,
            store_gain=True, store_S=True) -> EkfTrace:
    """Filter the aligned run with the model; see the module docstring for the conventions.

    Memory: the full P, S and K add N*n*n, N*m*m and N*n*m float64 (a 1 h 100 Hz quadcopter log:
    415 MB each); `store_gain=False` / `store_S=False` drop K / S (the trace keeps y, S_diag, NIS
    and the gain norm), `full_P` adds P_prior and P_post.
    """
    k = pack_run(model, run, Q=Q, R=R, x0=x0, P0=P0)
    N, n, G, m = run.n_steps, model.n_states, len(k.group_names), k.z.shape[1]
    nan = np.nan
    out = dict(
        x_prior=np.full((N, n), nan), x_post=np.full((N, n), nan),
        P_prior_diag=np.full((N, n), nan), P_post_diag=np.full((N, n), nan),
        P_prior_full=np.full((N if full_P else 0, n, n), nan),
        P_post_full=np.full((N if full_P else 0, n, n), nan),
        # S_out, K_out: NaN-filled step by step by ekf_run (one pass over the memory, not two)
        y_out=np.full((N, m), nan), S_out=np.empty((N if store_S else 0, m, m)),
        S_diag_out=np.full((N, m), nan), K_out=np.empty((N if store_gain else 0, n, m)),
        nis=np.full(N, nan), nis_group=np.full((N, G), nan), m_k=np.zeros(N, dtype=np.int64),
        gain_norm=np.full(N, nan), updated=np.zeros((N, G), dtype=np.bool_),
        rejected=np.zeros((N, G), dtype=np.bool_), seeded=np.zeros((N, G), dtype=np.bool_),
        diverged=np.zeros(N, dtype=np.bool_), input_held=np.zeros(N, dtype=np.bool_),
    )
    if N:
        ekf_run(k.model_id, k.p, k.x0, k.P0, k.Q, k.u, k.u_default, k.z, k.fresh, k.group_ids,
                k.group_offsets, k.group_sizes, k.R_all, k.range_lo, k.range_hi, k.wrap,
                k.direct_idx, k.direct_gain, k.dt, k.seed_at_start, **out)
    t = np.asarray(run.t, dtype=np.float64)
    return EkfTrace(
        model_name=model.name, state_names=list(model.state_names), group_names=k.group_names,
        group_offsets=k.group_offsets, group_sizes=k.group_sizes, t=t, dt=k.dt,
        x_prior=out["x_prior"], x_post=out["x_post"], P_prior_diag=out["P_prior_diag"],
        P_post_diag=out["P_post_diag"], y=out["y_out"], S_diag=out["S_diag_out"],
        nis=out["nis"], nis_group=out["nis_group"], m_k=out["m_k"], gain_norm=out["gain_norm"],
        updated=out["updated"], rejected=out["rejected"], seeded=out["seeded"],
        diverged=out["diverged"], input_held=out["input_held"], Q=k.Q, R=k.R_all,
        P_prior=out["P_prior_full"] if full_P else None,
        P_post=out["P_post_full"] if full_P else None,
        S=out["S_out"] if store_S else None, K=out["K_out"] if store_gain else None,
        divergence_episodes=divergence_episodes(t, out["diverged"], out["m_k"]),
    )
