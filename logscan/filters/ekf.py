"""The shared EKF core: one numba kernel that filters a whole aligned run, and its trace.

Every model-based detector reads the `EkfTrace` (logscan.filters.trace) this module returns
(docs/algorithms.md section 8); none carries its own filter. The kernel `ekf_run` is
model-agnostic: it calls the model's in-place f/F and h/H functions through
`logscan.models.dispatch`, resolved for the literal model id, so numba compiles and caches one
specialisation per model, only for the models a run uses; its linear algebra is `logscan.filters.linalg`.
Its arguments are grouped by meaning into NamedTuples, every field's shape and dtype beside it:
`EkfModel` (parameters, Q, prior), `EkfSensors` (the groups' layout, R, ranges), `EkfData` (the
run's inputs and samples) and `EkfBuffers` (the trace it writes); `pack_run` builds the first three.

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

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import literally, njit

from logscan.align import AlignedRun
from logscan.errors import ModelError
from logscan.filters.linalg import (
    all_finite,
    all_finite2,
    cho_solve_rows,
    cholesky,
    forward_sq,
    fpft_q,
    joseph,
    nan_fill,
    sparse_mm,
    sparse_rows,
    wrap_angle,
)
from logscan.filters.q_scale import calibrated_Q
from logscan.filters.trace import EkfTrace, divergence_episodes
from logscan.models import dispatch
from logscan.models.base import Model
from logscan.numba_cache import follow_dependencies

# error_model="numpy": float division without the Python-style zero checks (no division here
# can see a zero: Cholesky pivots are checked > 0 first); not fastmath, NaN checks still hold.


@njit(cache=True, error_model="numpy", no_cpython_wrapper=True)
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


@njit(cache=True, error_model="numpy", no_cpython_wrapper=True)
def _store(k, x, P, xs, P_diag, P_full, store_P):
    n = x.size
    for i in range(n):
        xs[k, i] = x[i]
        P_diag[k, i] = P[i, i]
    if store_P:
        for i in range(n):
            for j in range(n):
                P_full[k, i, j] = P[i, j]


# =============================================================================================
# the kernel's arguments (N steps, n states, nu inputs, G groups, m_total outputs of all groups
# stacked group after group; a group's outputs are rows group_offsets[g] : + group_sizes[g])
# =============================================================================================
class EkfModel(NamedTuple):
    """The model and the prior: what the kernel holds fixed over a run."""

    p: np.ndarray  # (n_p,) float64: the model's packed parameters (Model.param_vector)
    dt: float  # the grid step, s
    Q: np.ndarray  # (n, n) float64: process noise covariance of one step
    x0: np.ndarray  # (n,) float64: the initial state, and the state a restart returns to
    P0: np.ndarray  # (n, n) float64: its covariance
    seed_at_start: bool  # no x0 given: seed the directly observed states from their first samples


class EkfSensors(NamedTuple):
    """The measurement groups: which model outputs, their noise, range and direct states."""

    group_ids: np.ndarray  # (G,) int64: each group's id in the model (its h, H)
    group_offsets: np.ndarray  # (G,) int64: each group's first output
    group_sizes: np.ndarray  # (G,) int64: each group's number of outputs
    R_all: np.ndarray  # (m_total, m_total) float64: measurement noise covariance (group blocks)
    range_lo: np.ndarray  # (m_total,) float64: physical range of each output (outside: rejected)
    range_hi: np.ndarray  # (m_total,) float64
    wrap: np.ndarray  # (m_total,) bool: an angle (its innovation wraps to [-pi, pi))
    direct_idx: np.ndarray  # (m_total,) int64: the state i an output observes as z = gain * x[i], else -1
    direct_gain: np.ndarray  # (m_total,) float64: that gain


class EkfData(NamedTuple):
    """The run's samples on the grid."""

    u: np.ndarray  # (N, nu) float64: the input held at each step (a non-finite row: the last finite one)
    u_default: np.ndarray  # (nu,) float64: the input held before the first finite row
    z: np.ndarray  # (N, m_total) float64: the samples, group blocks side by side
    fresh: np.ndarray  # (N, G) bool: group g has a new sample at step k
    R_std: np.ndarray  # (N, m_total) float64: per-sample noise std (NaN: R_all's); (0, m_total): none


class EkfBuffers(NamedTuple):
    """What the kernel writes, preallocated by the caller (NaN / False / 0 filled, but S_out and
    K_out, which the kernel NaN-fills step by step). The optional ones (marked *) are stored when
    their first dimension is N; a zero-length first dimension skips them."""

    x_prior: np.ndarray  # (N, n) float64
    x_post: np.ndarray  # (N, n) float64
    P_prior_diag: np.ndarray  # (N, n) float32
    P_post_diag: np.ndarray  # (N, n) float32
    P_prior_full: np.ndarray  # (N, n, n) float64 *
    P_post_full: np.ndarray  # (N, n, n) float64 *
    y_out: np.ndarray  # (N, m_total) float32 * innovation, NaN where not updated
    S_out: np.ndarray  # (N, m_total, m_total) float64 * innovation covariance
    S_diag_out: np.ndarray  # (N, m_total) float32, stored with y_out
    K_out: np.ndarray  # (N, n, m_total) float64 * gain
    nis: np.ndarray  # (N,) float64
    nis_group: np.ndarray  # (N, G) float64
    m_k: np.ndarray  # (N,) int64: outputs in the update (0: none)
    gain_norm: np.ndarray  # (N,) float64: Frobenius norm of K
    updated: np.ndarray  # (N, G) bool
    rejected: np.ndarray  # (N, G) bool: fresh but non-finite or out of range
    seeded: np.ndarray  # (N, G) bool
    diverged: np.ndarray  # (N,) bool
    input_held: np.ndarray  # (N,) bool


# =============================================================================================
# the kernel
# =============================================================================================
@njit(cache=True, error_model="numpy")
def ekf_run(model_id, model, sensors, data, out):
    """Filter the N steps of ``data`` (EkfData) with ``model`` (EkfModel) and ``sensors``
    (EkfSensors) into ``out`` (EkfBuffers); ``model_id`` is the model's kernel id, compiled as a
    literal. All work arrays are allocated once, before the loop.
    """
    literally(model_id)  # one specialisation per model (logscan.models.dispatch)
    # the arguments' arrays under the kernel's names, read once: an attribute read inside the loop
    # would count a reference up and down at every access (2-3 % of a step)
    p, dt, Q, x0, P0 = model.p, model.dt, model.Q, model.x0, model.P0
    group_ids, group_offsets, group_sizes = sensors.group_ids, sensors.group_offsets, sensors.group_sizes
    R_all, range_lo, range_hi, wrap = sensors.R_all, sensors.range_lo, sensors.range_hi, sensors.wrap
    direct_idx, direct_gain = sensors.direct_idx, sensors.direct_gain
    u, z, fresh, R_std = data.u, data.z, data.fresh, data.R_std
    x_prior, x_post, P_prior_diag, P_post_diag = out.x_prior, out.x_post, out.P_prior_diag, out.P_post_diag
    P_prior_full, P_post_full, y_out, S_out, K_out = out.P_prior_full, out.P_post_full, out.y_out, out.S_out, out.K_out
    S_diag_out, nis, nis_group, m_k, gain_norm = out.S_diag_out, out.nis, out.nis_group, out.m_k, out.gain_norm
    updated, rejected, seeded = out.updated, out.rejected, out.seeded
    diverged, input_held = out.diverged, out.input_held
    N = u.shape[0]
    n = x0.size
    nu = u.shape[1]
    G = group_ids.size
    m_total = z.shape[1]
    store_P = P_prior_full.shape[0] == N
    store_y = y_out.shape[0] == N  # y and the diagonal of S
    store_S = S_out.shape[0] == N
    store_K = K_out.shape[0] == N
    dyn_R = R_std.shape[0] == N
    x = x0.copy()
    P = P0.copy()
    u_last = data.u_default.copy()
    # direct groups: every output observes one state
    is_direct = np.zeros(G, dtype=np.bool_)
    for g in range(G):
        ok = True
        for j in range(group_offsets[g], group_offsets[g] + group_sizes[g]):
            if direct_idx[j] < 0:
                ok = False
        is_direct[g] = ok
    seed_done = np.zeros(G, dtype=np.bool_)
    pending = model.seed_at_start
    # counters start from a typed zero: a literal 0 makes numba compile every helper they
    # reach twice (once for Literal[int](0), once for int64), doubling the cold compile
    zero = np.int64(0)
    # work arrays (allocated once)
    rows, sel_g = np.empty(m_total, dtype=np.int64), np.empty(G, dtype=np.int64)
    x_new, kv, xs, x_upd, dx = np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
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
        if all_finite(uk):
            for i in range(nu):
                u_last[i] = uk[i]
        else:
            input_held[k] = True
            uk = u_last
        # ---- predict: x_prior = f(x_post, u); P_prior = F P F^T + Q -----------------------
        if k > 0:
            dispatch.model_predict_into(model_id, p, x, uk, dt, x_new, F, kv, xs, Aw, Jw, Jnw)
            sparse_rows(F, n, n, fcols, fnnz)
            fpft_q(F, P, Q, n, fcols, fnnz, Aw, W, P_upd)
            P, P_upd = P_upd, P
            for i in range(n):
                x[i] = x_new[i]
            if not (all_finite(x) and all_finite2(P)):
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
                    rj = R_all[j, j]
                    if dyn_R and np.isfinite(R_std[k, j]) and R_std[k, j] > 0.0:
                        rj = R_std[k, j] * R_std[k, j]
                    P[i, i] = rj / (gain * gain)
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
            nan_fill(S_out[k])
        if store_K:
            nan_fill(K_out[k])
        if m > 0:
            r = zero
            for a in range(ng):
                g = sel_g[a]
                dispatch.model_meas_into(model_id, group_ids[g], p, x, uk, r, hx, Hs, R3, D3)
                r += group_sizes[g]
            sparse_rows(Hs, m, n, hcols, hnnz)
            for a in range(m):
                j = rows[a]
                # y~ = z - h(x_prior)
                ya = z[k, j] - hx[a]
                if wrap[j]:
                    ya = wrap_angle(ya)
                y[a] = ya
                for b in range(m):
                    Rs[a, b] = R_all[j, rows[b]]
            if dyn_R:  # per-sample noise (a receiver's own accuracy estimate): replaces row and column
                for a in range(m):
                    sd = R_std[k, rows[a]]
                    if np.isfinite(sd) and sd > 0.0:
                        for b in range(m):
                            Rs[a, b] = 0.0
                            Rs[b, a] = 0.0
                        Rs[a, a] = sd * sd
            for a in range(m):
                for b in range(m):
                    RsT[b, a] = Rs[a, b]
            sparse_rows(RsT, m, m, rcols, rnnz)
            # H P (H sparse: its rows' non-zeros only)
            sparse_mm(Hs, hcols, hnnz, m, P, n, HP)
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
            ok = cholesky(S, zero, m, L)
            if ok:
                # K = P H^T S^-1  via  S K^T = H P  (P symmetric)
                for a in range(m):
                    for j in range(n):
                        KT[a, j] = HP[a, j]
                cho_solve_rows(L, m, KT, n)
                for i in range(n):
                    t = 0.0
                    for a in range(m):
                        t += KT[a, i] * y[a]
                    dx[i] = t
                # x_post = x_prior (+) K y~ (additive but for a model with a rotation in its state)
                dispatch.model_boxplus_into(model_id, p, x, dx, x_upd)
                # P_post = (I - K H) P (I - K H)^T + K R K^T   (Joseph form)
                m_cnt[:] = m
                joseph(P, Hs, hcols, hnnz, HP, KT, Rs, rcols, rnnz, m, n, all_cols, m_cnt, W, DT, D, P_upd)
                if all_finite(x_upd) and all_finite2(P_upd):
                    for i in range(n):
                        x[i] = x_upd[i]
                    P, P_upd = P_upd, P
                    m_k[k] = m
                    # NIS = y^T S^-1 y = |L^-1 y|^2
                    nis[k] = forward_sq(L, m, y, zero, v)
                    knorm = 0.0
                    for a in range(m):
                        for i in range(n):
                            knorm += KT[a, i] * KT[a, i]
                    gain_norm[k] = np.sqrt(knorm)
                    for a in range(m):
                        j = rows[a]
                        if store_y:
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
                            nis_group[k, g] = forward_sq(L, mg, y, zero, v)
                        else:
                            cholesky(S, r, mg, Lg)
                            nis_group[k, g] = forward_sq(Lg, mg, y, r, v)
                        r += mg
                else:
                    ok = False
            if not ok:
                diverged[k] = pending = _restart(x, P, x0, P0, seed_done)
        _store(k, x, P, x_post, P_post_diag, P_post_full, store_P)


# =============================================================================================
# packing a run for the kernel, and the Python entry point
# =============================================================================================
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
    R_std: np.ndarray  # (N, m_total) per-sample noise std, NaN where none; (0, m_total): none
    range_lo: np.ndarray
    range_hi: np.ndarray
    wrap: np.ndarray
    direct_idx: np.ndarray
    direct_gain: np.ndarray
    dt: float
    seed_at_start: bool

    def kernel_arguments(self) -> tuple[int, EkfModel, EkfSensors, EkfData]:
        """``ekf_run``'s arguments before its buffers: the model id and the pack's arrays grouped
        by meaning (the same arrays, not copies)."""
        model = EkfModel(self.p, self.dt, self.Q, self.x0, self.P0, self.seed_at_start)
        sensors = EkfSensors(
            self.group_ids,
            self.group_offsets,
            self.group_sizes,
            self.R_all,
            self.range_lo,
            self.range_hi,
            self.wrap,
            self.direct_idx,
            self.direct_gain,
        )
        return self.model_id, model, sensors, EkfData(self.u, self.u_default, self.z, self.fresh, self.R_std)


def _square(name: str, value, size: int) -> np.ndarray:
    M = np.asarray(value, dtype=np.float64)
    if M.ndim == 1 and M.size == size:
        M = np.diag(M)
    if M.shape != (size, size):
        raise ModelError(f"{name} must be {size} x {size} (or a diagonal of {size}), got shape {M.shape}")
    if not np.all(np.isfinite(M)):
        raise ModelError(f"{name} has non-finite entries")
    return M


def _group_ranges(run: AlignedRun, names: list[str], specs, which: str) -> np.ndarray:
    """``range_lo`` or ``range_hi`` of every output, group after group: the aligned group's
    (from the profile) when it has one, else the model's GroupSpec's."""
    parts = []
    for name, spec in zip(names, specs):
        own = getattr(run.groups[name], which, None)
        parts.append(np.broadcast_to(np.asarray(getattr(spec, which) if own is None else own, float), (spec.size,)))
    return np.concatenate(parts)


def samples_side_by_side(
    run: AlignedRun, names: list[str], offsets: np.ndarray, sizes: np.ndarray
) -> np.ndarray | None:
    """The (N, m_total) float64 array whose column blocks are the groups' samples in this order
    (what `logscan.align` builds), else None. The kernel only reads z, so it may share it."""
    first = run.groups[names[0]].z
    base = first.base if isinstance(first, np.ndarray) else None
    if not isinstance(base, np.ndarray) or base.dtype != np.float64 or not base.flags.c_contiguous:
        return None
    if base.shape != (run.n_steps, int(sizes.sum())):
        return None
    origin = base.__array_interface__["data"][0]
    for name, offset, size in zip(names, offsets.tolist(), sizes.tolist()):
        z = run.groups[name].z
        if not isinstance(z, np.ndarray) or z.base is not base or z.shape != (run.n_steps, size):
            return None
        if z.__array_interface__["data"][0] != origin + 8 * offset or z.strides != base.strides:
            return None
    return base


def pack_run(model: Model, run: AlignedRun, Q=None, R=None, x0=None, P0=None) -> KernelInputs:
    """Check the run against the model and pack it into the kernel's arrays.

    Q: None (the model's default_Q, scaled by its calibrated ``process_noise_scale`` when set),
    or an (n, n) matrix. R: None (each group's profile noise_std, else the model's default_R), or a dict
    group -> (m, m) matrix or (m,) standard deviations. The physical range (samples outside it are
    rejected) is each group's profile range_lo / range_hi where given, else the model's.
    """
    dispatch.check_model_id(model.model_id, model.name)
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
    z = samples_side_by_side(run, names, offsets, sizes)  # alignment's own array, when it has that layout
    packed = z is not None
    z = np.empty((N, m_total)) if z is None else z
    fresh = np.zeros((N, len(names)), dtype=np.bool_)
    R_all = np.zeros((m_total, m_total))
    R_std = None  # per-sample noise of the groups that have it (AlignedGroup.noise_std_series)
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
        if not packed:
            z[:, o : o + spec.size] = zg
        fresh[:, g] = np.asarray(grp.fresh, dtype=bool)
        if name in R:
            given = np.square(R[name]) if np.ndim(R[name]) == 1 else R[name]  # std or matrix
            Rg = _square(f"R[{name}]", given, spec.size)
        elif grp.noise_std is not None:
            Rg = np.diag(np.square(np.broadcast_to(np.asarray(grp.noise_std, float), (spec.size,))))
        else:
            Rg = model.default_R(name)
        R_all[o : o + spec.size, o : o + spec.size] = Rg
        noise = getattr(grp, "noise_std_series", None)
        if noise is not None:
            if R_std is None:
                R_std = np.full((N, m_total), np.nan)
            R_std[:, o : o + spec.size] = np.asarray(noise, dtype=np.float64).reshape(N, spec.size)
    unknown_R = sorted(set(R) - set(names))
    if unknown_R:
        raise ModelError(f"R given for group(s) not in the run: {', '.join(unknown_R)}")
    seed = x0 is None
    x0 = model.default_x0() if x0 is None else np.asarray(x0, dtype=np.float64).reshape(-1)
    if x0.size != n or not np.all(np.isfinite(x0)):
        raise ModelError(f"x0 must hold {n} finite values")
    P0 = model.default_P0() if P0 is None else _square("P0", P0, n)
    if Q is None:  # the model's, scaled when trained tables calibrated it (`logscan.training.process_noise`)
        Q = calibrated_Q(model, run.dt)
    Q = model.default_Q(run.dt) if Q is None else _square("Q", Q, n)
    finite_rows = np.flatnonzero(np.all(np.isfinite(u), axis=1))
    u_default = u[finite_rows[0]].copy() if finite_rows.size else np.zeros(model.n_inputs)
    direct = [s.direct_map() for s in specs]
    return KernelInputs(
        model_id=int(model.model_id),
        p=np.ascontiguousarray(model.param_vector(run.dt), dtype=np.float64),
        x0=np.ascontiguousarray(x0),
        P0=np.ascontiguousarray(P0),
        Q=np.ascontiguousarray(Q),
        u=u,
        u_default=u_default,
        z=z,
        fresh=fresh,
        group_names=names,
        group_ids=np.array([s.group_id for s in specs], dtype=np.int64),
        group_offsets=offsets,
        group_sizes=sizes,
        R_all=R_all,
        R_std=np.empty((0, m_total)) if R_std is None else np.ascontiguousarray(R_std),
        # the profile's physical range of a group where it gives one, else the model's
        range_lo=_group_ranges(run, names, specs, "range_lo"),
        range_hi=_group_ranges(run, names, specs, "range_hi"),
        wrap=np.concatenate([s.wrap_mask() for s in specs]),
        direct_idx=np.concatenate([d[0] for d in direct]),
        direct_gain=np.concatenate([d[1] for d in direct]),
        dt=float(run.dt),
        seed_at_start=seed,
    )


def compiled_for(args: tuple):
    """ekf_run's compiled entry point for these arguments, the model id as a literal."""
    return dispatch.compiled_for_model(ekf_run, args)


def run_ekf(
    model: Model,
    run: AlignedRun,
    Q=None,
    R=None,
    x0=None,
    P0=None,
    full_P=False,
    store_gain=True,
    store_S=True,
    store_innovations=True,
) -> EkfTrace:
    """Filter the aligned run with the model; see the module docstring for the conventions.

    Memory: the full P, S and K add N*n*n, N*m*m and N*n*m float64 (a 1 h 100 Hz quadcopter log:
    415 MB each); `store_gain=False` / `store_S=False` drop K / S (the trace keeps NIS and the gain
    norm), `store_innovations=False` drops y and S_diag (2 * N*m float32: 35 MB for that log),
    `full_P` adds P_prior and P_post.
    """
    k = pack_run(model, run, Q=Q, R=R, x0=x0, P0=P0)
    N, n, G, m = run.n_steps, model.n_states, len(k.group_names), k.z.shape[1]
    nan = np.nan
    out = EkfBuffers(
        x_prior=np.full((N, n), nan),
        x_post=np.full((N, n), nan),
        # float32: variances are scales (coding vectors, consistency bands), 7 digits are ample,
        # and a 1-hour log keeps 35 MB less
        P_prior_diag=np.full((N, n), nan, dtype=np.float32),
        P_post_diag=np.full((N, n), nan, dtype=np.float32),
        P_prior_full=np.full((N if full_P else 0, n, n), nan),
        P_post_full=np.full((N if full_P else 0, n, n), nan),
        # S_out, K_out: NaN-filled step by step by ekf_run (one pass over the memory, not two)
        # float32: y and diag(S) are drawn (the report's measured-vs-predicted figures), never
        # filtered further; a 1-hour log keeps 35 MB less
        y_out=np.full((N if store_innovations else 0, m), nan, dtype=np.float32),
        S_out=np.empty((N if store_S else 0, m, m)),
        S_diag_out=np.full((N if store_innovations else 0, m), nan, dtype=np.float32),
        K_out=np.empty((N if store_gain else 0, n, m)),
        nis=np.full(N, nan),
        nis_group=np.full((N, G), nan),
        m_k=np.zeros(N, dtype=np.int64),
        gain_norm=np.full(N, nan),
        updated=np.zeros((N, G), dtype=np.bool_),
        rejected=np.zeros((N, G), dtype=np.bool_),
        seeded=np.zeros((N, G), dtype=np.bool_),
        diverged=np.zeros(N, dtype=np.bool_),
        input_held=np.zeros(N, dtype=np.bool_),
    )
    if N:
        args = (*k.kernel_arguments(), out)
        compiled_for(args)(*args)
    t = np.asarray(run.t, dtype=np.float64)
    return EkfTrace(
        model_name=model.name,
        state_names=list(model.state_names),
        group_names=k.group_names,
        group_offsets=k.group_offsets,
        group_sizes=k.group_sizes,
        t=t,
        dt=k.dt,
        x_prior=out.x_prior,
        x_post=out.x_post,
        P_prior_diag=out.P_prior_diag,
        P_post_diag=out.P_post_diag,
        y=out.y_out if store_innovations else None,
        S_diag=out.S_diag_out if store_innovations else None,
        nis=out.nis,
        nis_group=out.nis_group,
        m_k=out.m_k,
        gain_norm=out.gain_norm,
        updated=out.updated,
        rejected=out.rejected,
        seeded=out.seeded,
        diverged=out.diverged,
        input_held=out.input_held,
        Q=k.Q,
        R=k.R_all,
        P_prior=out.P_prior_full if full_P else None,
        P_post=out.P_post_full if full_P else None,
        S=out.S_out if store_S else None,
        K=out.K_out if store_gain else None,
        divergence_episodes=divergence_episodes(t, out.diverged, out.m_k),
    )


follow_dependencies(__name__)
