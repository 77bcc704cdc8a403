"""The UBIKF: a Kalman filter on an interval linear model with a covariance upper bound and a
sound envelope of the state estimates (docs/algorithms.md section 2).

Model `logscan.models.interval_model.IntervalModel`: x_{k+1} = [A] x_k + [B] u_k + w, y_k = [C] x_k + v,
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
from typing import NamedTuple

import numpy as np
from numba import njit

from logscan.align import AlignedRun
from logscan.errors import ModelError
from logscan.filters.detectability import check_detectable
from logscan.filters.intervals import (
    append_box,
    append_scaled_columns,
    innovation_bound,
    posterior_bound,
    predict_bound,
    radius_times,
    reduce_order,
    sqrt_diag,
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
    sparse_mm,
    sparse_rows,
)
from logscan.models.interval_model import IntervalModel, loewner_upper
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
# the kernel's arguments (N steps, n states, nu inputs, G groups, m outputs of all groups stacked
# group after group; group g's rows are group_offsets[g] : + group_sizes[g])
# ================================================================================================
class UbikfModel(NamedTuple):
    """The interval model [M] = M_m +- M_r, its noise bounds, prior and measurement groups."""

    A_m: np.ndarray  # (n, n) float64: state transition, midpoint
    A_r: np.ndarray  # (n, n) float64: its radius (>= 0)
    B_m: np.ndarray  # (n, nu) float64: input matrix, midpoint
    B_r: np.ndarray  # (n, nu) float64: its radius
    C_m: np.ndarray  # (m, n) float64: output matrix, midpoint
    C_r: np.ndarray  # (m, n) float64: its radius
    Q: np.ndarray  # (n, n) float64: Q+, a Loewner upper bound of [Q]
    R: np.ndarray  # (m, m) float64: R+, a Loewner upper bound of [R]
    x0: np.ndarray  # (n,) float64: the initial state, and the state a restart returns to
    P0: np.ndarray  # (n, n) float64: its covariance
    group_offsets: np.ndarray  # (G,) int64: each group's first row
    group_sizes: np.ndarray  # (G,) int64: each group's number of rows


class UbikfData(NamedTuple):
    """The run's samples on the grid."""

    u: np.ndarray  # (N, nu) float64: the input of each step (a non-finite row: the last finite one)
    u_default: np.ndarray  # (nu,) float64: the input held before the first finite row
    z: np.ndarray  # (N, m) float64: the samples, group blocks side by side
    fresh: np.ndarray  # (N, G) bool: group g has a new sample at step k


class UbikfSettings(NamedTuple):
    """The filter's two settings."""

    L: int  # order-reduction period, steps (>= 1)
    cap: float  # divergence threshold on |P+|, |x_c| and the hull radius


class UbikfBuffers(NamedTuple):
    """What the kernel writes, preallocated by the caller (NaN filled; n_generators, m_k 0 and the
    flags False). K and P are stored when their first dimension is N (zero-length: skipped). The
    field names are `UbikfTrace`'s."""

    x_mid: np.ndarray  # (N, n) float64: mid-model point estimate x_c (posterior)
    x_lo: np.ndarray  # (N, n) float64: hull of the posterior zonotope
    x_hi: np.ndarray  # (N, n) float64
    P_trace: np.ndarray  # (N,) float64: trace(P+_post)
    P_diag: np.ndarray  # (N, n) float32: diag(P+_post)
    n_generators: np.ndarray  # (N,) int64: zonotope order after the step
    P: np.ndarray  # (N, n, n) float64: P+_post, or (0, n, n)
    r_mid: np.ndarray  # (N, m) float64: innovation box midpoint, NaN where not updated
    r_rad: np.ndarray  # (N, m) float64: innovation box radius
    S: np.ndarray  # (N, m, m) float64: S+ of the rows updated
    nis: np.ndarray  # (N,) float64: point NIS
    K: np.ndarray  # (N, n, m) float64: gain, or (0, n, m)
    updated: np.ndarray  # (N, G) bool
    m_k: np.ndarray  # (N,) int64: measurements in the update
    diverged: np.ndarray  # (N,) bool: restarted from x0/P0 at this step


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
def predict_step(A_m, acols, annz, A_r, B_m, B_r, u, x, h, G, p, G_out, alpha, x_prior):
    """x_c,prior = A_m x_c + B_m u and G_out = [A_m G, diag(A_r (|x_c| + h) + B_r |u|)]; returns
    the new generator count."""
    interval_input_radius(A_r, x, h, B_r, u, alpha)
    zonotope_map_into(A_m, acols, annz, G, p, G_out)
    for i in range(x.size):
        x_prior[i] = np.dot(A_m[i], x) + np.dot(B_m[i], u)
    return append_box(G_out, p, alpha)


@njit(cache=True, error_model="numpy")
def update_step(C_r, Cs, rows, m, y, Rs, P, x, h, G, p, work, P_out):
    """The correction with the m stacked rows (Cs = C_m[rows], y = r on entry): S+, K, P+_post
    into P_out, x_c += K r, G <- [(I - K C_m) G, K diag(gamma)]. Returns (ok, p); ok False when
    S+ is not positive definite. Leaves S+ and its Cholesky factor, the box radius of C_m G and
    gamma in `work`."""
    hcols, hnnz, HP, KT, S, Lc, CG, r_box, gamma, rho_c, sigma, w = work
    n = x.size
    sparse_rows(Cs, m, n, hcols, hnnz)
    sparse_mm(Cs, hcols, hnnz, m, P, n, HP)
    sqrt_diag(P, sigma)
    radius_times(C_r, rows, m, sigma, rho_c)
    ratio_c = innovation_bound(Cs, hcols, hnnz, m, P, HP, rho_c, Rs, S)
    if not cholesky(S, 0, m, Lc):
        return False, p
    # K^T = (c/c0) (S+)^-1 C P
    for a in range(m):
        for j in range(n):
            KT[a, j] = ratio_c * HP[a, j]
    cho_solve_rows(Lc, m, KT, n)
    posterior_bound(P, Cs, hcols, hnnz, HP, KT, Rs, m, rho_c, w, P_out)
    K = w[6]
    # innovation box radius rowsum |C_m G| + gamma, gamma = C_r (|x_c,prior| + h_prior)
    for i in range(n):
        sigma[i] = abs(x[i]) + h[i]
    radius_times(C_r, rows, m, sigma, gamma)
    sparse_mm(Cs, hcols, hnnz, m, G, p, CG)
    zonotope_hull_into(CG, m, p, r_box)
    # G <- [(I - K C_m) G, K diag(gamma)];  x_c,post = x_c,prior + K r
    subtract_product(K, m, CG, p, G)
    for i in range(n):
        x[i] += np.dot(K[i, :m], y[:m])
    return True, append_scaled_columns(G, p, K, m, gamma)


@njit(cache=True, error_model="numpy")
def store_step(k, x, h, P, p, out):
    """The posterior of step k into ``out`` (UbikfBuffers): x_c, its hull x_c -+ h, diag and trace
    of P+, generator count."""
    x_mid, x_lo, x_hi, P_diag, P_out = out.x_mid, out.x_lo, out.x_hi, out.P_diag, out.P
    tr = 0.0
    for i in range(x.size):
        x_mid[k, i] = x[i]
        x_lo[k, i] = x[i] - h[i]
        x_hi[k, i] = x[i] + h[i]
        P_diag[k, i] = P[i, i]
        tr += P[i, i]
    out.P_trace[k] = tr
    out.n_generators[k] = p
    if P_out.shape[0] == x_mid.shape[0]:
        P_out[k] = P


@njit(cache=True, error_model="numpy")
def store_update(k, rows, m, y, work, out, v):
    """The innovation box, S+, the point NIS and (out.K of length N) the gain of step k into ``out``
    (UbikfBuffers)."""
    r_box, gamma, S, Lc, K = work[7], work[8], work[4], work[5], work[11][6]
    r_mid, r_rad, S_out, K_out = out.r_mid, out.r_rad, out.S, out.K
    out.nis[k] = forward_sq(Lc, m, y, 0, v)  # r^T (S+)^-1 r
    for a in range(m):
        j = rows[a]
        r_mid[k, j] = y[a]
        r_rad[k, j] = widen(r_box[a] + gamma[a])
        for b in range(m):
            S_out[k, j, rows[b]] = S[a, b]
        if K_out.shape[0] == r_mid.shape[0]:
            for i in range(K.shape[0]):
                K_out[k, i, j] = K[i, a]


@njit(cache=True, error_model="numpy")
def work_arrays(n, m, cap_p):
    """The update's work arrays (see `update_step`), allocated once."""
    all_cols = np.empty((n, m), dtype=np.int64)
    for i in range(n):
        all_cols[i, :] = np.arange(m)
    int_n, int_m, int_mm = np.empty(n, dtype=np.int64), np.zeros(m, dtype=np.int64), np.empty((m, m), dtype=np.int64)
    w = (all_cols, int_n, int_mm, int_m, np.empty((n, n)), np.empty((m, n)), np.zeros((n, m)), np.empty((n, m)))
    hcols, hnnz = np.empty((m, n), dtype=np.int64), np.empty(m, dtype=np.int64)
    HP, KT, S, Lc = np.zeros((m, n)), np.zeros((m, n)), np.zeros((m, m)), np.zeros((m, m))
    return (hcols, hnnz, HP, KT, S, Lc, np.zeros((m, cap_p)), np.zeros(m), np.zeros(m), np.zeros(m), np.zeros(n), w)


@njit(cache=True, error_model="numpy")
def ubikf_run(model, data, settings, out):
    """Filter the N steps of ``data`` (UbikfData) with ``model`` (UbikfModel) and ``settings``
    (UbikfSettings) into ``out`` (UbikfBuffers)."""
    A_m, A_r, B_m, B_r, C_m, C_r = model.A_m, model.A_r, model.B_m, model.B_r, model.C_m, model.C_r
    x0, P0, group_offsets, group_sizes = model.x0, model.P0, model.group_offsets, model.group_sizes
    Q, R, u, z, fresh = model.Q, model.R, data.u, data.z, data.fresh
    L, cap = settings.L, settings.cap
    # read once (an attribute read inside the loop counts a reference up and down at each access)
    updated, m_k, diverged = out.updated, out.m_k, out.diverged
    n, m_total = x0.size, C_m.shape[0]
    cap_p = n + 2 * L * (n + m_total)  # generators: a box, then at most 2 L steps of new ones
    # work arrays (allocated once)
    x, x_prior, u_last, h = x0.copy(), np.empty(n), data.u_default.copy(), np.zeros(n)
    sigma, rho, alpha = np.empty(n), np.empty(n), np.empty(n)
    P, P_next, Wn = P0.copy(), np.empty((n, n)), np.zeros((4, n, n))  # Wn[3] stays zero
    G, G_next = np.zeros((n, cap_p)), np.zeros((n, cap_p))
    acols, annz, all_rows = np.empty((n, n), dtype=np.int64), np.empty(n, dtype=np.int64), np.arange(n)
    sparse_rows(A_m, n, n, acols, annz)
    rows, upd = np.empty(m_total, dtype=np.int64), np.zeros(group_offsets.size, dtype=np.bool_)
    Cs, Rs, y, v = np.zeros((m_total, n)), np.zeros((m_total, m_total)), np.zeros(m_total), np.zeros(m_total)
    work = work_arrays(n, m_total, cap_p)
    p, p_mark, age = 0, 0, 0
    for k in range(u.shape[0]):
        if all_finite(u[k]):
            u_last[:] = u[k]
        if age > 0:  # k = 0 and after a restart: the prior is x0, P0
            p = predict_step(A_m, acols, annz, A_r, B_m, B_r, u_last, x, h, G, p, G_next, alpha, x_prior)
            G, G_next = G_next, G
            x[:] = x_prior
            predict_bound(A_m, acols, annz, A_r, all_rows, Q, P, sigma, rho, Wn[3], Wn[0], Wn[1], Wn[2], P_next)
            P, P_next = P_next, P
            zonotope_hull_into(G, n, p, h)
        ok = True
        m = select_rows(k, z, fresh, group_offsets, group_sizes, rows, upd)
        if m > 0:
            for a in range(m):
                Cs[a] = C_m[rows[a]]
                y[a] = z[k, rows[a]] - np.dot(C_m[rows[a]], x)  # r = y - C_m x_c,prior
                for b in range(m):
                    Rs[a, b] = R[rows[a], rows[b]]
            ok, p = update_step(C_r, Cs, rows, m, y, Rs, P, x, h, G, p, work, P_next)
            P, P_next = P_next, P
        age += 1
        if age % L == 0:  # box the generators older than L steps
            p = reduce_order(G, p, p_mark)
            p_mark = p
        zonotope_hull_into(G, n, p, h)
        if not (ok and below_cap(x, cap) and below_cap(P, cap) and below_cap(h, cap)):
            diverged[k] = True
            x[:] = x0
            P[:] = P0
            h[:] = 0.0
            p, p_mark, age, m = 0, 0, 0, 0
        store_step(k, x, h, P, p, out)
        if m > 0:
            m_k[k] = m
            updated[k] = upd
            store_update(k, rows, m, y, work, out, v)


# ================================================================================================
# the Python entry point
# ================================================================================================
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
    if int(L) < 1:
        raise ValueError(f"the order-reduction period L must be at least 1 step, got {L}")
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
    out = _buffers(N, n, m, G, store_P=store_P, store_gain=store_gain)
    if N:
        kernel_model = _kernel_model(model, x0, P0)
        ubikf_run(kernel_model, UbikfData(u, u_default, z, fresh), UbikfSettings(int(L), float(cap)), out)
    buffers = out._asdict()
    buffers["P"] = out.P if store_P else None
    buffers["K"] = out.K if store_gain else None
    return UbikfTrace(
        t=np.asarray(run.t, dtype=np.float64),
        **buffers,
        group_names=tuple(model.group_names),
        group_offsets=np.asarray(model.group_offsets),
        group_sizes=np.asarray(model.group_sizes),
        state_names=tuple(model.state_names),
    )


def _buffers(N: int, n: int, m: int, G: int, *, store_P: bool, store_gain: bool) -> UbikfBuffers:
    """The kernel's output arrays, NaN / False / 0 filled (P and K empty unless stored)."""
    nan = np.nan
    return UbikfBuffers(
        x_mid=np.full((N, n), nan),
        x_lo=np.full((N, n), nan),
        x_hi=np.full((N, n), nan),
        P_trace=np.full(N, nan),
        P_diag=np.full((N, n), nan, dtype=np.float32),
        n_generators=np.zeros(N, dtype=np.int64),
        P=np.full((N if store_P else 0, n, n), nan),
        r_mid=np.full((N, m), nan),
        r_rad=np.full((N, m), nan),
        S=np.full((N, m, m), nan),
        nis=np.full(N, nan),
        K=np.full((N if store_gain else 0, n, m), nan),
        updated=np.zeros((N, G), dtype=np.bool_),
        m_k=np.zeros(N, dtype=np.int64),
        diverged=np.zeros(N, dtype=np.bool_),
    )


def _kernel_model(model: IntervalModel, x0: np.ndarray, P0: np.ndarray) -> UbikfModel:
    """The model's matrices as the kernel reads them (contiguous float64, Q+ and R+ bounds)."""
    c = np.ascontiguousarray
    names = ("A_m", "A_r", "B_m", "B_r", "C_m", "C_r")
    matrices = {name: c(getattr(model, name), dtype=np.float64) for name in names}
    return UbikfModel(
        **matrices,
        Q=c(loewner_upper(model.Q_m, model.Q_r)),
        R=c(loewner_upper(model.R_m, model.R_r)),
        x0=c(x0),
        P0=c(P0),
        group_offsets=c(model.group_offsets, dtype=np.int64),
        group_sizes=c(model.group_sizes, dtype=np.int64),
    )


follow_dependencies(__name__)
