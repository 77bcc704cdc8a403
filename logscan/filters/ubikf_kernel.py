"""The UBIKF's numba kernel: one pass over a log of the interval filter of `logscan.filters.ubikf`
(its docstring has the recursion; docs/algorithms.md section 2), on one block of states
(`logscan.filters.ubikf_blocks`). Its arguments are the NamedTuples below, each field's shape and
dtype in a comment. The step loop and every function it calls run without numba's reference
counting (``_nrt=False``; the shared helpers as private copies, `logscan.filters.ubikf_nrt`): it
allocates nothing, and the counting of every array view cost a third of the filter's time.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from logscan.filters import intervals, linalg
from logscan.filters.ubikf_nrt import nrt_free
from logscan.numba_cache import follow_dependencies

# the shared helpers the step loop calls, as private NRT-free copies (`logscan.filters.ubikf_nrt`)
append_box = nrt_free(intervals.append_box)
box_columns_into = nrt_free(intervals.box_columns_into)
innovation_bound = nrt_free(intervals.innovation_bound)
posterior_bound = nrt_free(intervals.posterior_bound)
predict_bound = nrt_free(intervals.predict_bound)
radius_times = nrt_free(intervals.radius_times)
sqrt_diag = nrt_free(intervals.sqrt_diag)
subtract_product = nrt_free(intervals.subtract_product)
widen = nrt_free(intervals.widen)
zonotope_hull_into = nrt_free(intervals.zonotope_hull_into)
zonotope_map_into = nrt_free(intervals.zonotope_map_into)
all_finite = nrt_free(linalg.all_finite)
cho_solve_rows = nrt_free(linalg.cho_solve_rows)
cholesky = nrt_free(linalg.cholesky)
forward_sq = nrt_free(linalg.forward_sq)
sparse_mm = nrt_free(linalg.sparse_mm)
sparse_rows = nrt_free(linalg.sparse_rows)


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
    L_box: int  # the steps whose new generators are boxed together (1 .. L, L a multiple of it)
    cap: float  # divergence threshold on |P+|, |x_c| and the hull radius


class UbikfBuffers(NamedTuple):
    """The whole model's outputs, preallocated by the caller (NaN filled; n_generators, m_k 0 and
    the flags False; P_trace 0 before the first block). Each block's kernel writes its states' and
    rows' entries (`BlockPlace`), adds its trace, generator count and NIS to the sums and sets
    ``diverged``; ``updated`` and ``m_k`` are the caller's, after every block. K and P are stored
    when their first dimension is N (zero-length: skipped). The field names are `UbikfTrace`'s."""

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


class BlockPlace(NamedTuple):
    """Where a block's states and rows sit in the whole model (`logscan.filters.ubikf_blocks`)."""

    states: np.ndarray  # (n,) int64: the whole model's index of each of the block's states
    rows: np.ndarray  # (m,) int64: the whole model's index of each of the block's measurement rows


# ================================================================================================
# the kernel
# ================================================================================================
@njit(cache=True, error_model="numpy", _nrt=False)
def below_cap(M, cap):
    """Every entry of the vector or matrix M finite and |entry| <= cap."""
    for v in M.flat:
        if not (abs(v) <= cap):
            return False
    return True


@njit(cache=True, error_model="numpy", _nrt=False)
def row_dot(M, i, x):
    """M[i] . x (a loop: numba's np.dot on short vectors is a BLAS call)."""
    t = 0.0
    for j in range(x.size):
        t += M[i, j] * x[j]
    return t


@njit(cache=True, error_model="numpy", _nrt=False)
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


@njit(cache=True, error_model="numpy", _nrt=False)
def select_rows(k, z, fresh, group_offsets, group_sizes, rows):
    """Stack the rows of the groups with a fresh, finite sample at step k; returns their count."""
    m = 0
    for g in range(group_offsets.size):
        if not fresh[k, g]:
            continue
        o = group_offsets[g]
        if not all_finite(z[k, o : o + group_sizes[g]]):
            continue
        for j in range(o, o + group_sizes[g]):
            rows[m] = j
            m += 1
    return m


@njit(cache=True, error_model="numpy", _nrt=False)
def predict_step(A_m, acols, annz, A_r, B_m, B_r, u, x, h, G, p, G_out, alpha, x_prior):
    """x_c,prior = A_m x_c + B_m u, G_out = A_m G and alpha = A_r (|x_c| + h) + B_r |u|: the prior
    zonotope is x_c,prior + G_out [-1, 1]^p + [-alpha, alpha] (the box is appended after the
    update, `update_step`, or as it is when no group updates)."""
    interval_input_radius(A_r, x, h, B_r, u, alpha)
    zonotope_map_into(A_m, acols, annz, G, p, G_out)
    for i in range(x.size):
        t = 0.0
        for j in range(x.size):
            t += A_m[i, j] * x[j]
        for j in range(u.size):
            t += B_m[i, j] * u[j]
        x_prior[i] = t


@njit(cache=True, error_model="numpy", _nrt=False)
def update_step(C_r, Cs, rows, m, y, Rs, P, x, h, alpha, G, p, work, P_out):
    """The correction with the m stacked rows (Cs = C_m[rows], y = r on entry) of the prior zonotope
    x_c + G [-1, 1]^p + [-alpha, alpha] (h its hull radius): S+, K, P+_post into P_out,
    x_c += K r, G <- [(I - K C_m) G, diag(|I - K C_m| alpha + |K| gamma)]. Returns (ok, p); ok
    False when S+ is not positive definite. Leaves S+ and its Cholesky factor, the box radius of
    C_m G (with the alpha box) and gamma in `work`."""
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
    # innovation box radius rowsum |C_m G| + |C_m| alpha + gamma, gamma = C_r (|x_c,prior| + h_prior)
    for i in range(n):
        sigma[i] = abs(x[i]) + h[i]
    radius_times(C_r, rows, m, sigma, gamma)
    sparse_mm(Cs, hcols, hnnz, m, G, p, CG)
    zonotope_hull_into(CG, m, p, r_box)
    for a in range(m):
        t = 0.0
        for s in range(hnnz[a]):
            t += abs(Cs[a, hcols[a, s]]) * alpha[hcols[a, s]]
        r_box[a] = widen(r_box[a] + t)
    # G <- (I - K C_m) G;  x_c,post = x_c,prior + K r
    subtract_product(K, m, CG, p, G)
    for i in range(n):
        t = 0.0
        for a in range(m):
            t += K[i, a] * y[a]
        x[i] += t
    # the new deviations, boxed once: (I - K C_m) [-alpha, alpha] + K [-gamma, gamma]
    for i in range(n):
        t = 0.0
        for j in range(n):
            kc = 0.0
            for a in range(m):
                kc += K[i, a] * Cs[a, j]
            t += abs((1.0 if i == j else 0.0) - kc) * alpha[j]
        for a in range(m):
            t += abs(K[i, a]) * gamma[a]
        sigma[i] = widen(t)
    return True, append_box(G, p, sigma)


@njit(cache=True, error_model="numpy", _nrt=False)
def store_step(k, x, h, P, p, out, states):
    """The posterior of step k into the block's states of ``out`` (UbikfBuffers): x_c, its hull
    x_c -+ h, diag of P+ and (out.P of length N) P+; its trace and the generator count added to
    the sums."""
    x_mid, x_lo, x_hi, P_diag, P_out = out.x_mid, out.x_lo, out.x_hi, out.P_diag, out.P
    tr = 0.0
    for i in range(x.size):
        s = states[i]
        x_mid[k, s] = x[i]
        x_lo[k, s] = x[i] - h[i]
        x_hi[k, s] = x[i] + h[i]
        P_diag[k, s] = P[i, i]
        tr += P[i, i]
    out.P_trace[k] += tr
    out.n_generators[k] += p
    if P_out.shape[0] == x_mid.shape[0]:
        for i in range(x.size):
            for j in range(x.size):
                P_out[k, states[i], states[j]] = P[i, j]


@njit(cache=True, error_model="numpy", _nrt=False)
def store_update(k, rows, m, y, work, out, v, place):
    """The innovation box, S+ and (out.K of length N) the gain of step k into the block's rows of
    ``out`` (UbikfBuffers); its point NIS, when finite, added to the step's."""
    r_box, gamma, S, Lc, K = work[7], work[8], work[4], work[5], work[11][6]
    r_mid, r_rad, S_out, K_out = out.r_mid, out.r_rad, out.S, out.K
    nis = forward_sq(Lc, m, y, 0, v)  # r^T (S+)^-1 r
    if np.isfinite(nis):
        before = out.nis[k]
        out.nis[k] = (0.0 if np.isnan(before) else before) + nis
    for a in range(m):
        j = place.rows[rows[a]]
        r_mid[k, j] = y[a]
        r_rad[k, j] = widen(r_box[a] + gamma[a])
        for b in range(m):
            S_out[k, j, place.rows[rows[b]]] = S[a, b]
        if K_out.shape[0] == r_mid.shape[0]:
            for i in range(K.shape[0]):
                K_out[k, place.states[i], j] = K[i, a]


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
def ubikf_run(model, data, settings, out, place):
    """Filter the N steps of ``data`` (UbikfData) with ``model`` (UbikfModel, one block) and
    ``settings`` (UbikfSettings) into the block's part of ``out`` (UbikfBuffers; ``place``:
    BlockPlace): the work arrays allocated once here, the steps run by `filter_steps`."""
    n, m_total = model.x0.size, model.C_m.shape[0]
    cap_p = n + 2 * settings.L * n + n  # generators: a box, then at most 2 L steps of n new ones
    state = (model.x0.copy(), data.u_default.copy(), model.P0.copy(), np.zeros((n, cap_p)), np.zeros((n, cap_p)))
    vectors = np.zeros((6, n))  # x_prior, h, sigma, rho, alpha and box_columns_into's box
    matrices = np.zeros((5, n, n))  # predict_bound's work (the fourth, its Z, stays zero), then P_next
    acols, annz = np.empty((n, n), dtype=np.int64), np.empty(n, dtype=np.int64)
    sparse_rows(model.A_m, n, n, acols, annz)
    rows = np.empty(m_total, dtype=np.int64)
    Cs, Rs = np.zeros((m_total, n)), np.zeros((m_total, m_total))
    y, v = np.zeros(m_total), np.zeros(m_total)
    scratch = (vectors, matrices, acols, annz, np.arange(n), rows, Cs, Rs, y, v)
    filter_steps(model, data, settings, out, place, state, scratch, work_arrays(n, m_total, cap_p))


@njit(cache=True, error_model="numpy", _nrt=False)
def filter_steps(model, data, settings, out, place, state, scratch, work):
    """The step loop of `ubikf_run` (NRT off: it allocates nothing, `logscan.filters.ubikf_nrt`)."""
    A_m, A_r, B_m, B_r, C_m, C_r = model.A_m, model.A_r, model.B_m, model.B_r, model.C_m, model.C_r
    x0, P0, group_offsets, group_sizes = model.x0, model.P0, model.group_offsets, model.group_sizes
    Q, R, u, z, fresh = model.Q, model.R, data.u, data.z, data.fresh
    L, L_box, cap, diverged = settings.L, settings.L_box, settings.cap, out.diverged
    x, u_last, P, G, G_next = state
    vectors, Wn, acols, annz, all_rows, rows, Cs, Rs, y, v = scratch
    x_prior, h, sigma, rho, alpha, box = vectors[0], vectors[1], vectors[2], vectors[3], vectors[4], vectors[5]
    P_next, n = Wn[4], x0.size
    p, p_mark, p_recent, age = 0, 0, 0, 0
    for k in range(u.shape[0]):
        if all_finite(u[k]):
            copy_into(u[k], u_last)
        if age > 0:  # k = 0 and after a restart: the prior is x0, P0
            predict_step(A_m, acols, annz, A_r, B_m, B_r, u_last, x, h, G, p, G_next, alpha, x_prior)
            G, G_next = G_next, G
            copy_into(x_prior, x)
            predict_bound(A_m, acols, annz, A_r, all_rows, Q, P, sigma, rho, Wn[3], Wn[0], Wn[1], Wn[2], P_next)
            P, P_next = P_next, P
            zonotope_hull_into(G, n, p, h)
            for i in range(n):  # the prior's hull: G's and the alpha box's
                h[i] = widen(h[i] + alpha[i])
        else:
            alpha[:] = 0.0
        ok = True
        m = select_rows(k, z, fresh, group_offsets, group_sizes, rows)
        if m > 0:
            for a in range(m):
                copy_into(C_m[rows[a]], Cs[a])
                y[a] = z[k, rows[a]] - row_dot(C_m, rows[a], x)  # r = y - C_m x_c,prior
                for b in range(m):
                    Rs[a, b] = R[rows[a], rows[b]]
            ok, p = update_step(C_r, Cs, rows, m, y, Rs, P, x, h, alpha, G, p, work, P_next)
            P, P_next = P_next, P
        else:
            p = append_box(G, p, alpha)
        age += 1
        if age % L_box == 0:  # box the last L_box steps' new generators together
            p = box_columns_into(G, p, p_recent, p, box)
            p_recent = p
        if age % L == 0:  # box the generators older than L steps
            p = box_columns_into(G, p, 0, p_mark, box)
            p_mark = p
            p_recent = p
        zonotope_hull_into(G, n, p, h)
        if not (ok and below_cap(x, cap) and below_cap(P, cap) and below_cap(h, cap)):
            diverged[k] = True
            copy_into(x0, x)
            copy_into(P0, P)
            h[:] = 0.0
            p, p_mark, p_recent, age, m = 0, 0, 0, 0, 0
        store_step(k, x, h, P, p, out, place.states)
        if m > 0:
            store_update(k, rows, m, y, work, out, v, place)


@njit(cache=True, error_model="numpy", _nrt=False)
def copy_into(src, dst):
    """dst[:] = src for two vectors or two matrices of one shape that do not overlap (``dst[:] =
    src`` checks for an overlap and may copy through a temporary, which needs the NRT)."""
    for i, value in enumerate(src.flat):
        dst.flat[i] = value


follow_dependencies(__name__)
