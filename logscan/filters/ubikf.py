"""The UBIKF: a Kalman filter on an interval linear model with a covariance upper bound and a
sound envelope of the state estimates (docs/algorithms.md section 2).

Model `logscan.filters.interval_model.IntervalModel`: x_{k+1} = [A] x_k + [B] u_k + w, y_k = [C] x_k + v,
[M] = M_m +- M_r; Q+ and R+ are Loewner upper bounds of [Q] and [R] (`loewner_upper`).

Covariance bound (weighted): (sum_t a_t)(sum_t a_t)^T <= sum_t a_t a_t^T / lambda_t with lambda_t
proportional to the size of each term. With sigma = sqrt(diag P) and rho = M_r sigma:

    P+_prior = (s/s0) A_m P+_post A_m^T + s diag(rho_A) + Q+            s0 = sqrt(tr A_m P A_m^T), s = s0 + sum rho_A
    S+       = (c/c0) C_m P+_prior C_m^T + c diag(rho_C) + R+           c0, c likewise with C (rows updated)
    K        = (c/c0) P+_prior C_m^T (S+)^-1
    P+_post  = (d/d0) M P+_prior M^T + d sum_a (rho_C,a / |k_a|) k_a k_a^T + K R+ K^T,   M = I - K C_m,
               d0 = sqrt(tr M P M^T), d = d0 + sum_a rho_C,a |k_a|  (k_a: column a of K)

so every point filter (A, C, Q, R) in the intervals that uses this gain sequence has its Joseph
covariance below P+.

State set: the mid-model point estimate x_c and the zonotope x_c + G [-1, 1]^p of the deviations
of every admissible point filter's estimate (same gains, inputs and measurements) from it:

    x_c,prior = A_m x_c + B_m u              G <- [A_m G, diag(A_r (|x_c| + h) + B_r |u|)]
    r = y - C_m x_c,prior                     r_rad = rowsum |C_m G| + gamma,  gamma = C_r (|x_c,prior| + h_prior)
    x_c,post = x_c,prior + K r                G <- [(I - K C_m) G, K diag(gamma)]

with h = rowsum |G| the hull radius. Every L steps (default 60) the generators older than L steps
are boxed (`logscan.filters.intervals.reduce_order`). The innovation box [r] = r +- r_rad encloses
y - C x_prior for every admissible point filter (it is the image of the zonotope through [C]).

Conventions (as the EKF core, logscan.filters.ekf): k = 0: prior = x0, P0, no prediction; k > 0:
predict with u_k (a non-finite input row is replaced by the last finite one). A group updates at k
when it is fresh and its whole sample is finite. Divergence: a non-positive-definite S+, or P+, G
or x_c non-finite or above `cap` in absolute value: the step is flagged `diverged` and the filter
restarts from x0/P0 with an empty zonotope (no statistic of that step is stored).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numba import njit

from logscan.align import AlignedRun
from logscan.errors import ModelError
from logscan.filters.interval_model import IntervalModel, loewner_upper
from logscan.filters.intervals import (
    append_box,
    append_scaled_columns,
    reduce_order,
    subtract_product,
    widen,
    zonotope_hull_into,
    zonotope_map_into,
)
from logscan.filters.linalg import (
    all_finite,
    cho_solve_rows,
    cholesky,
    forward_sq,
    fpft_q,
    joseph,
    sparse_mm,
    sparse_rows,
)
from logscan.numba_cache import follow_dependencies


@dataclass
class UbikfTrace:
    """Per-step output of `run_ubikf` (N steps, n states, G groups, m = sum of the group sizes).

    Group g's measurement rows are `group_offsets[g] : group_offsets[g] + group_sizes[g]`; r_mid,
    r_rad and S hold the rows updated at a step, NaN elsewhere (S is NaN-padded to (m, m)).
    """

    t: np.ndarray  # (N,)
    x_mid: np.ndarray  # (N, n) mid-model point estimate x_c (posterior)
    x_lo: np.ndarray  # (N, n) hull of the posterior zonotope
    x_hi: np.ndarray
    P_trace: np.ndarray  # (N,) trace(P+_post)
    P_diag: np.ndarray  # (N, n) float32 diag(P+_post)
    r_mid: np.ndarray  # (N, m) innovation box midpoint y - C_m x_c,prior, NaN where not updated
    r_rad: np.ndarray  # (N, m) innovation box radius
    S: np.ndarray  # (N, m, m) S+, NaN-padded
    nis: np.ndarray  # (N,) point NIS r_mid^T (S+)^-1 r_mid, NaN without update
    updated: np.ndarray  # (N, G) bool
    m_k: np.ndarray  # (N,) int, measurements in the update
    diverged: np.ndarray  # (N,) bool, restarted from x0/P0 at this step
    n_generators: np.ndarray  # (N,) int, zonotope order p after the step
    group_names: tuple[str, ...]
    group_offsets: np.ndarray
    group_sizes: np.ndarray
    state_names: tuple[str, ...]
    K: np.ndarray | None = None  # (N, n, m) gain, NaN-padded (store_gain)
    P: np.ndarray | None = None  # (N, n, n) P+_post (store_P)


# ================================================================================================
# covariance bound
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


# ================================================================================================
# the kernel
# ================================================================================================
@njit(cache=True, error_model="numpy")
def below_cap(M, cap):
    """Every entry finite and |entry| <= cap."""
    for v in M.ravel():
        if not (abs(v) <= cap):
            return False
    return True


@njit(cache=True, error_model="numpy")
def interval_input_radius(A_r, x, h, B_r, u, out):
    """out = A_r (|x| + h) + B_r |u| (widened): the box the interval terms of the prediction add."""
    n = out.size
    for i in range(n):
        s = 0.0
        for j in range(x.size):
            s += A_r[i, j] * (abs(x[j]) + h[j])
        for j in range(u.size):
            s += B_r[i, j] * abs(u[j])
        out[i] = widen(s)


@njit(cache=True, error_model="numpy")
def select_rows(k, z, fresh, group_offsets, group_sizes, rows, upd):
    """Stack the rows of the groups with a fresh, finite sample at step k; returns their count."""
    m = 0
    for g in range(group_offsets.size):
        upd[g] = False
        if not fresh[k, g]:
            continue
        o = group_offsets[g]
        if not all_finite(z[k, o : o + group_sizes[g]]):
            continue
        upd[g] = True
        for j in range(o, o + group_sizes[g]):
            rows[m] = j
            m += 1
    return m


@njit(cache=True, error_model="numpy")
def ubikf_run(
    A_m, A_r, B_m, B_r, C_m, C_r, Q, R, x0, P0, u, u_default, z, fresh, group_offsets, group_sizes, L, cap,
    x_mid, x_lo, x_hi, P_trace, P_diag, r_mid, r_rad, S_out, nis, K_out, P_out, updated, m_k, diverged, n_gen,
):  # fmt: skip
    """Filter N steps; outputs preallocated by the caller (r_mid, r_rad, S_out, nis, K_out NaN,
    the flags False). K_out and P_out are stored when their first dimension is N."""
    N, nu = u.shape
    n = x0.size
    m_total = C_m.shape[0]
    store_K = K_out.shape[0] == N
    store_P = P_out.shape[0] == N
    cap_p = n + 2 * L * (n + m_total)  # generators: a box, then at most 2 L steps of new ones
    # work arrays (allocated once)
    x, x_prior, u_last, h, h_prior = x0.copy(), np.empty(n), u_default.copy(), np.zeros(n), np.zeros(n)
    sigma, rho, alpha = np.empty(n), np.empty(n), np.empty(n)
    P, P_prior, APA, FP, W, Z = (
        P0.copy(),
        np.empty((n, n)),
        np.empty((n, n)),
        np.empty((n, n)),
        np.empty((n, n)),
        np.zeros((n, n)),
    )
    G, G2 = np.zeros((n, cap_p)), np.zeros((n, cap_p))
    CG = np.zeros((m_total, cap_p))
    all_rows = np.arange(n)
    acols, annz = np.empty((n, n), dtype=np.int64), np.empty(n, dtype=np.int64)
    sparse_rows(A_m, n, n, acols, annz)
    rows, upd = np.empty(m_total, dtype=np.int64), np.zeros(group_offsets.size, dtype=np.bool_)
    Cs, HP, KT = np.zeros((m_total, n)), np.zeros((m_total, n)), np.zeros((m_total, n))
    hcols, hnnz = np.empty((m_total, n), dtype=np.int64), np.empty(m_total, dtype=np.int64)
    S, Rs, Lc = np.zeros((m_total, m_total)), np.zeros((m_total, m_total)), np.zeros((m_total, m_total))
    y, r_box, gamma, rho_c, v = (
        np.zeros(m_total),
        np.zeros(m_total),
        np.zeros(m_total),
        np.zeros(m_total),
        np.zeros(m_total),
    )
    all_cols = np.empty((n, m_total), dtype=np.int64)
    for i in range(n):
        all_cols[i, :] = np.arange(m_total)
    w = (all_cols, np.empty(n, dtype=np.int64), np.empty((m_total, m_total), dtype=np.int64),
         np.zeros(m_total, dtype=np.int64), np.empty((n, n)), np.empty((m_total, n)), np.zeros((n, m_total)),
         np.empty((n, m_total)))  # fmt: skip
    K = w[6]
    p, p_mark, age = 0, 0, 0
    for k in range(N):
        uk = u[k]
        if all_finite(uk):
            u_last[:] = uk
        # ---- predict --------------------------------------------------------------------------
        if age > 0:
            # G <- [A_m G, diag(A_r (|x| + h) + B_r |u|)]
            interval_input_radius(A_r, x, h, B_r, u_last, alpha)
            zonotope_map_into(A_m, acols, annz, G, p, G2)
            G, G2 = G2, G
            p = append_box(G, p, alpha)
            # x_c,prior = A_m x_c + B_m u
            for i in range(n):
                t = 0.0
                for j in range(n):
                    t += A_m[i, j] * x[j]
                for j in range(nu):
                    t += B_m[i, j] * u_last[j]
                x_prior[i] = t
            predict_bound(A_m, acols, annz, A_r, all_rows, Q, P, sigma, rho, Z, FP, W, APA, P_prior)
        else:
            x_prior[:] = x
            P_prior[:] = P
        zonotope_hull_into(G, n, p, h_prior)
        x[:] = x_prior
        h[:] = h_prior
        P, P_prior = P_prior, P
        ok = True
        # ---- update with the fresh groups ----------------------------------------------------
        m = select_rows(k, z, fresh, group_offsets, group_sizes, rows, upd)
        if m > 0:
            for a in range(m):
                Cs[a] = C_m[rows[a]]
                y[a] = z[k, rows[a]] - np.dot(C_m[rows[a]], x_prior)  # r = y - C_m x_c,prior
                for b in range(m):
                    Rs[a, b] = R[rows[a], rows[b]]
            sparse_rows(Cs, m, n, hcols, hnnz)
            sparse_mm(Cs, hcols, hnnz, m, P, n, HP)
            sqrt_diag(P, sigma)
            radius_times(C_r, rows, m, sigma, rho_c)
            ratio_c = innovation_bound(Cs, hcols, hnnz, m, P, HP, rho_c, Rs, S)
            ok = cholesky(S, 0, m, Lc)
            if ok:
                # K^T = (c/c0) (S+)^-1 C P
                for a in range(m):
                    for j in range(n):
                        KT[a, j] = ratio_c * HP[a, j]
                cho_solve_rows(Lc, m, KT, n)
                posterior_bound(P, Cs, hcols, hnnz, HP, KT, Rs, m, rho_c, w, P_prior)
                P, P_prior = P_prior, P
                # innovation box and the corrected zonotope: G <- [(I - K C_m) G, K diag(gamma)]
                for i in range(n):
                    sigma[i] = abs(x_prior[i]) + h_prior[i]
                radius_times(C_r, rows, m, sigma, gamma)
                sparse_mm(Cs, hcols, hnnz, m, G, p, CG)
                zonotope_hull_into(CG, m, p, r_box)
                subtract_product(K, m, CG, p, G)
                p = append_scaled_columns(G, p, K, m, gamma)
                # x_c,post = x_c,prior + K r
                for i in range(n):
                    x[i] = x_prior[i] + np.dot(K[i, :m], y[:m])
        age += 1
        if age % L == 0:
            p = reduce_order(G, p, p_mark)
            p_mark = p
        zonotope_hull_into(G, n, p, h)
        if not (ok and below_cap(x, cap) and below_cap(P, cap) and below_cap(h, cap)):
            diverged[k] = True
            x[:] = x0
            P[:] = P0
            h[:] = 0.0
            p, p_mark, age, m = 0, 0, 0, 0
        # ---- store ---------------------------------------------------------------------------
        tr = 0.0
        for i in range(n):
            x_mid[k, i] = x[i]
            x_lo[k, i] = x[i] - h[i]
            x_hi[k, i] = x[i] + h[i]
            P_diag[k, i] = P[i, i]
            tr += P[i, i]
        P_trace[k] = tr
        n_gen[k] = p
        if store_P:
            P_out[k] = P
        if m > 0:
            m_k[k] = m
            updated[k] = upd
            nis[k] = forward_sq(Lc, m, y, 0, v)  # r^T (S+)^-1 r
            for a in range(m):
                j = rows[a]
                r_mid[k, j] = y[a]
                r_rad[k, j] = widen(r_box[a] + gamma[a])
                for b in range(m):
                    S_out[k, j, rows[b]] = S[a, b]
                if store_K:
                    for i in range(n):
                        K_out[k, i, j] = K[i, a]


# ================================================================================================
# the Python entry point
# ================================================================================================
def unobservable_unstable_states(model: IntervalModel, rtol: float = 1e-9, margin: float = 1e-6) -> list[str]:
    """The states in the undetectable subspace of (A_m, C_m): the modes with |lambda| >= 1 - margin
    of the unobservable subspace (the largest A_m-invariant subspace in null(C_m), by orthogonal
    deflation with rank decisions relative to |A_m|, |C_m|)."""
    A, C = model.A_m, model.C_m
    n = A.shape[0]
    scale_A = max(np.linalg.norm(A, 2), 1.0)
    scale_C = max(np.linalg.norm(C, 2) if C.size else 0.0, np.finfo(float).tiny)

    def null_space(M, scale):
        if M.shape[0] == 0:
            return np.eye(M.shape[1])
        _, s, Vt = np.linalg.svd(M)
        rank = int(np.sum(s > rtol * scale))
        return Vt[rank:].T

    V = null_space(C, scale_C)  # null(C)
    while V.shape[1]:
        # {x in span V: A x in span V}
        N = null_space(A @ V - V @ (V.T @ A @ V), scale_A)
        if N.shape[1] == V.shape[1]:
            break
        V = V @ N  # orthonormal columns still
    if not V.shape[1]:
        return []
    T, Zs, sdim = scipy.linalg.schur(V.T @ A @ V, output="complex", sort=lambda lam: abs(lam) >= 1.0 - margin)
    if sdim == 0:
        return []
    U = np.abs(V @ Zs[:, :sdim])
    weight = np.sqrt(np.sum(U**2, axis=1))
    return [model.state_names[i] for i in range(n) if weight[i] > 1e-6]


def check_detectable(model: IntervalModel) -> None:
    """ModelError naming the states whose unstable or marginal modes no measurement sees."""
    states = unobservable_unstable_states(model)
    if states:
        raise ModelError(
            f"the interval model is not detectable: (A_m, C_m) cannot observe {', '.join(states)}",
            hint="add a measurement group that observes these states, or make their dynamics stable",
        )


def _measurements(model: IntervalModel, run: AlignedRun) -> tuple[np.ndarray, np.ndarray]:
    """z (N, m) and fresh (N, G) in the model's group order."""
    N = run.n_steps
    z = np.full((N, model.m), np.nan)
    fresh = np.zeros((N, len(model.group_names)), dtype=np.bool_)
    for g, name in enumerate(model.group_names):
        if name not in run.groups:
            raise ModelError(f"the run has no measurement group {name!r}", hint="groups: " + ", ".join(run.groups))
        o, size = int(model.group_offsets[g]), int(model.group_sizes[g])
        zg = np.asarray(run.groups[name].z, dtype=np.float64).reshape(N, -1)
        if zg.shape[1] != size:
            raise ModelError(f"group {name!r} has {zg.shape[1]} channels, the interval model {size}")
        z[:, o : o + size] = zg
        fresh[:, g] = np.asarray(run.groups[name].fresh, dtype=bool)
    return z, fresh


def run_ubikf(
    model: IntervalModel,
    run: AlignedRun,
    *,
    L: int = 60,
    cap: float = 1e12,
    store_gain: bool = False,
    store_P: bool = False,
) -> UbikfTrace:
    """Filter the aligned run with the interval model (see the module docstring).

    L: order-reduction period in steps; cap: divergence threshold on |P+|, |x_c| and the hull
    radius; store_gain / store_P add K (N, n, m) and P+_post (N, n, n). x0 defaults to zeros and
    P0 to the identity when the model gives none. Raises ModelError for an ill-formed or
    undetectable model, or a run that does not match it.
    """
    model.check()
    check_detectable(model)
    n, m, N, G = model.n, model.m, run.n_steps, len(model.group_names)
    u = np.ascontiguousarray(run.u, dtype=np.float64).reshape(N, -1)
    if u.shape[1] != model.B_m.shape[1]:
        raise ModelError(f"the interval model takes {model.B_m.shape[1]} inputs, the run has {u.shape[1]}")
    z, fresh = _measurements(model, run)
    x0 = np.zeros(n) if model.x0.size == 0 else np.asarray(model.x0, dtype=np.float64)
    P0 = np.eye(n) if model.P0.size == 0 else np.asarray(model.P0, dtype=np.float64)
    finite = np.flatnonzero(np.all(np.isfinite(u), axis=1))
    u_default = u[finite[0]].copy() if finite.size else np.zeros(u.shape[1])
    c = np.ascontiguousarray
    nan = np.nan
    out = dict(
        x_mid=np.full((N, n), nan),
        x_lo=np.full((N, n), nan),
        x_hi=np.full((N, n), nan),
        P_trace=np.full(N, nan),
        P_diag=np.full((N, n), nan, dtype=np.float32),
        r_mid=np.full((N, m), nan),
        r_rad=np.full((N, m), nan),
        S=np.full((N, m, m), nan),
        nis=np.full(N, nan),
        K=np.full((N if store_gain else 0, n, m), nan),
        P=np.full((N if store_P else 0, n, n), nan),
        updated=np.zeros((N, G), dtype=np.bool_),
        m_k=np.zeros(N, dtype=np.int64),
        diverged=np.zeros(N, dtype=np.bool_),
        n_generators=np.zeros(N, dtype=np.int64),
    )
    if N:
        matrices = [c(getattr(model, name), dtype=np.float64) for name in ("A_m", "A_r", "B_m", "B_r", "C_m", "C_r")]
        Q, R = c(loewner_upper(model.Q_m, model.Q_r)), c(loewner_upper(model.R_m, model.R_r))
        offsets, sizes = c(model.group_offsets, dtype=np.int64), c(model.group_sizes, dtype=np.int64)
        ubikf_run(
            *matrices, Q, R, c(x0), c(P0), u, u_default, z, fresh, offsets, sizes, int(L), float(cap), *out.values()
        )
    return UbikfTrace(
        t=np.asarray(run.t, dtype=np.float64),
        **{name: out[name] for name in ("x_mid", "x_lo", "x_hi", "P_trace", "P_diag", "r_mid", "r_rad", "S", "nis")},
        updated=out["updated"],
        m_k=out["m_k"],
        diverged=out["diverged"],
        n_generators=out["n_generators"],
        group_names=tuple(model.group_names),
        group_offsets=np.asarray(model.group_offsets),
        group_sizes=np.asarray(model.group_sizes),
        state_names=tuple(model.state_names),
        K=out["K"] if store_gain else None,
        P=out["P"] if store_P else None,
    )


follow_dependencies(__name__)
