"""The shared EKF core: one numba kernel that filters a whole aligned run, and its trace.

Every model-based detector reads the `EkfTrace` (logscan.traces) this module returns
(docs/algorithms.md section 8); none carries its own filter. The kernel `ekf_run` is
model-agnostic: it calls the model's in-place f/F and h/H functions through
`logscan.models.dispatch`, resolved for the literal model id, so numba compiles and caches one
specialisation per model, only for the models a run uses; its linear algebra is `logscan.filters.linalg`.
Its arguments are grouped by meaning into the NamedTuples of `logscan.filters.ekf_pack`, every
field's shape and dtype beside it: `EkfModel` (parameters, Q, prior), `EkfSensors` (the groups'
layout, R, ranges), `EkfData` (the run's inputs and samples) and `EkfBuffers` (the trace it writes);
`pack_run` there builds the first three.

Conventions (step k on the grid, u_k the input held at step k):
 - k = 0: x_prior = x0, P_prior = P0 (no prediction); k > 0: x_prior = f(x_post_{k-1}, u_k).
 - Multi-rate: only groups with a fresh sample at k are stacked into z, H, R.
 - A fresh group whose sample is non-finite or outside the group's physical range is skipped
   for that step as a whole and flagged in `rejected[k, g]`. A group with an outlier gate
   (`EkfSensors.gate`) whose NIS against the prior exceeds it is left out of the update too, its
   innovation, diag(S) and NIS kept for the detectors (`nis_group` finite, `updated` False).
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

import numpy as np
from numba import literally, njit

from logscan.align import AlignedRun
from logscan.filters.coding import coded_variance, coding_vector_into
from logscan.filters.ekf_pack import (
    EkfBuffers,
    EkfData,
    EkfModel,
    EkfSensors,
    KernelInputs,
    pack_run,
    samples_side_by_side,
    trace_buffers,
    work_arrays,
)
from logscan.filters.linalg import (
    all_finite,
    all_finite2,
    cholesky,
    forward_sq,
    fpft_q,
    gain_rows,
    grow_pattern,
    innovation_covariance,
    innovations,
    joseph,
    pattern_holds,
    short_update,
    sparse_rows,
)
from logscan.models import dispatch
from logscan.models.base import Model
from logscan.needs import CodedVariance
from logscan.numba_cache import follow_dependencies
from logscan.traces import EkfTrace, divergence_episodes

# packing a run (logscan.filters.ekf_pack), importable from here as before
__all__ = [
    "EkfBuffers",
    "KernelInputs",
    "compiled_for",
    "ekf_run",
    "filter_into",
    "pack_run",
    "run_ekf",
    "samples_side_by_side",
]

# error_model="numpy": float division without the Python-style zero checks (no division here
# can see a zero: Cholesky pivots are checked > 0 first); not fastmath, NaN checks still hold.

# The short covariance update P - K S K^T is used where every variance keeps more than this share
# of its prior; else the step takes the Joseph form (docs/algorithms.md, "The covariance update").
# Rounding leaves P_ii - (K S K^T)_ii an absolute error of about (m + 1) eps P_ii, so the short
# form's variances keep a relative error below (m + 1) eps / SHORT_FORM_KEEP: 5e-9 for m <= 20.
SHORT_FORM_KEEP = 1e-6


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
    """x and the diagonal of P (and P itself when ``store_P``) into row k of the trace."""
    n = x.size
    for i in range(n):
        xs[k, i] = x[i]
        P_diag[k, i] = P[i, i]
    if store_P:
        for i in range(n):
            for j in range(n):
                P_full[k, i, j] = P[i, j]


@njit(cache=True, error_model="numpy", no_cpython_wrapper=True)
def _store_gain(k, pos, S, KT, S_out, K_out, store_S, store_K):
    """S and K of step k into the full trace in one pass (the buffers come unfilled): S_out[k, j, l]
    = S[pos[j], pos[l]] where outputs j and l were in the update (pos >= 0), else NaN; K likewise."""
    m_total = pos.size
    if store_S:
        Sk = S_out[k]
        for j in range(m_total):
            pj = pos[j]
            for c in range(m_total):
                pc = pos[c]
                Sk[j, c] = S[pj, pc] if pj >= 0 and pc >= 0 else np.nan
    if store_K:
        Kk = K_out[k]
        for i in range(Kk.shape[0]):
            for j in range(m_total):
                pj = pos[j]
                Kk[i, j] = KT[pj, i] if pj >= 0 else np.nan


# =============================================================================================
# the kernel
# =============================================================================================
# The cached entry point is the step loop itself, compiled without numba's reference counting
# (ekf_pack.EkfWork says why). It was once a wrapper around the loop as a function of its own,
# which LLVM then optimised twice (in its own module and again in the wrapper's): that second
# round cost 4-6 s of CPU of the first run's compile and bought no speed measurable on this
# machine (bench/README.md, issue 29 item 5, 2026-12-01).
@njit(cache=True, error_model="numpy", nogil=True, _nrt=False)
def ekf_run(model_id, model, sensors, data, out, work):
    """Filter the N steps of ``data`` (EkfData) with ``model`` (EkfModel) and ``sensors``
    (EkfSensors) into ``out`` (EkfBuffers), on the work arrays ``work`` (EkfWork, from
    `ekf_pack.work_arrays`); ``model_id`` is the model's kernel id, compiled as a literal (one
    specialisation per model, logscan.models.dispatch). Allocates nothing."""
    literally(model_id)
    # the arguments' arrays under the kernel's names, read once
    p, dt, Q, x0, P0 = model.p, model.dt, model.Q, model.x0, model.P0
    coding_floor, coding_r_max, ex_var = model.coding_floor, model.coding_r_max, out.ex_var
    group_ids, group_offsets, group_sizes = sensors.group_ids, sensors.group_offsets, sensors.group_sizes
    R_all, range_lo, range_hi, wrap = sensors.R_all, sensors.range_lo, sensors.range_hi, sensors.wrap
    direct_idx, direct_gain, gate = sensors.direct_idx, sensors.direct_gain, sensors.gate
    u, z, fresh, R_std = data.u, data.z, data.fresh, data.R_std
    x_prior, x_post, P_prior_diag, P_post_diag = out.x_prior, out.x_post, out.P_prior_diag, out.P_post_diag
    P_prior_full, P_post_full, y_out, S_out, K_out = out.P_prior_full, out.P_post_full, out.y_out, out.S_out, out.K_out
    S_diag_out, nis, nis_group, m_k, gain_norm = out.S_diag_out, out.nis, out.nis_group, out.m_k, out.gain_norm
    updated, rejected, seeded = out.updated, out.rejected, out.seeded
    diverged, input_held, steps_done = out.diverged, out.input_held, out.steps_done
    x, P, u_last, rows, sel_g = work.x, work.P, work.u_last, work.rows, work.sel_g
    is_direct, seed_done = work.is_direct, work.seed_done
    x_new, kv, xs, x_upd, dx = work.x_new, work.kv, work.xs, work.x_upd, work.dx
    F, W, P_upd, Aw, Jw, Jnw, R3, D3 = work.F, work.W, work.P_upd, work.Aw, work.Jw, work.Jnw, work.R3, work.D3
    F_bits, f_outside, fcols, fnnz = work.F_bits, work.f_outside, work.fcols, work.fnnz
    hcols, hnnz = work.hcols, work.hnnz
    hx, y, v, Hs, HP, KT, S, Rs, RsT = work.hx, work.y, work.v, work.Hs, work.HP, work.KT, work.S, work.Rs, work.RsT
    rcols, rnnz, L, Lg, D, DT, V = work.rcols, work.rnnz, work.L, work.Lg, work.D, work.DT, work.V
    all_cols, m_cnt, pos, cv = work.all_cols, work.m_cnt, work.pos, work.cv
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
    store_ex_var = ex_var.shape[0] == N
    pending = model.seed_at_start
    # counters start from a typed zero: a literal 0 makes numba compile every helper they
    # reach twice (once for Literal[int](0), once for int64), doubling the cold compile
    zero = np.int64(0)
    for k in range(N):
        steps_done[0] = k
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
            if not pattern_holds(F_bits, f_outside):  # F's non-zeros: a new one since the last step
                grow_pattern(F, n, f_outside, fcols, fnnz)
            fpft_q(F, P, Q, n, fcols, fnnz, Aw, W, P_upd)
            P, P_upd = P_upd, P
            for i in range(n):
                x[i] = x_new[i]
            # the previous P is finite, so a non-finite entry of F or of the new P shows on the new
            # P's diagonal (F[i, c] meets P[c, c], or where P's row c is zero, 0 * inf = NaN in the
            # terms of (F P F^T)[i, i])
            finite = all_finite(x)
            for i in range(n):
                if not np.isfinite(P[i, i]):
                    finite = False
            if not finite:
                diverged[k] = pending = _restart(x, P, x0, P0, seed_done)
        _store(k, x, P, x_prior, P_prior_diag, P_prior_full, store_P)
        if store_ex_var:
            coding_vector_into(P, coding_floor, coding_r_max, cv)
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
            mg = group_sizes[g]
            if gate[g] < np.inf:
                # the outlier gate (docs/algorithms.md 8.4): the group alone against the prior;
                # its block of the stacked S is this S, so its NIS is the update's nis_group
                for a in range(mg):
                    rows[m + a] = o + a
                dispatch.model_meas_into(model_id, group_ids[g], p, x, uk, zero, hx, Hs, R3, D3)
                sparse_rows(Hs, mg, n, hcols, hnnz)
                innovations(z[k], rows, m, mg, hx, wrap, R_all, R_std[k] if dyn_R else R_all[0], dyn_R, y, Rs)
                innovation_covariance(Hs, hcols, hnnz, mg, P, n, HP, Rs, S)
                if cholesky(S, zero, mg, L):
                    q = forward_sq(L, mg, y, zero, v)
                    if q > gate[g]:  # kept for the detectors, not used in the update
                        nis_group[k, g] = q
                        if store_y:
                            for a in range(mg):
                                y_out[k, o + a] = y[a]
                                S_diag_out[k, o + a] = S[a, a]
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
        if store_S or store_K:  # where each output sits in this step's update (-1: not in it)
            for j in range(m_total):
                pos[j] = -1
        if m > 0:
            r = zero
            for a in range(ng):
                g = sel_g[a]
                dispatch.model_meas_into(model_id, group_ids[g], p, x, uk, r, hx, Hs, R3, D3)
                r += group_sizes[g]
            sparse_rows(Hs, m, n, hcols, hnnz)
            # y~ = z - h(x_prior); S = H P H^T + R
            innovations(z[k], rows, zero, m, hx, wrap, R_all, R_std[k] if dyn_R else R_all[0], dyn_R, y, Rs)
            innovation_covariance(Hs, hcols, hnnz, m, P, n, HP, Rs, S)
            ok = cholesky(S, zero, m, L)
            if ok:
                # K = P H^T S^-1  via  S K^T = H P  (P symmetric): V = L^-1 H P, K^T = L^-T V
                gain_rows(L, m, HP, V, KT, n)
                # dx = K y, accumulated row by row of K^T: each dx[i] sums over a in the same order
                # as a dot product would, but the n sums run side by side (contiguous rows, no
                # chain of m dependent adds per state)
                for i in range(n):
                    dx[i] = 0.0
                for a in range(m):
                    KTa = KT[a]
                    ya = y[a]
                    for i in range(n):
                        dx[i] += KTa[i] * ya
                # x_post = x_prior (+) K y~ (additive but for a model with a rotation in its state)
                # (R3, D3: the measurements' rotation work, free again once they are evaluated)
                dispatch.model_boxplus_into(model_id, p, x, dx, x_upd, R3, D3)
                # P_post = P - K S K^T = P - V^T V (the short form, exact for the optimal gain K),
                # where every variance keeps more than SHORT_FORM_KEEP of its prior (that check is
                # also its finite check); else (I - K H) P (I - K H)^T + K R K^T (Joseph form)
                finite = short_update(P, V, m, n, SHORT_FORM_KEEP, P_upd)
                if not finite:
                    for a in range(m):  # R's non-zeros by column, for the Joseph form
                        for b in range(m):
                            RsT[b, a] = Rs[a, b]
                    sparse_rows(RsT, m, m, rcols, rnnz)
                    m_cnt[:] = m
                    joseph(P, Hs, hcols, hnnz, HP, KT, Rs, rcols, rnnz, m, n, all_cols, m_cnt, W, DT, D, P_upd)
                    finite = all_finite2(P_upd)
                if finite and all_finite(x_upd):
                    for i in range(n):
                        x[i] = x_upd[i]
                    P, P_upd = P_upd, P
                    m_k[k] = m
                    # NIS = y^T S^-1 y = |L^-1 y|^2
                    nis[k] = forward_sq(L, m, y, zero, v)
                    knorm = 0.0
                    for a in range(m):  # row sums first: m short chains instead of one of m n adds
                        KTa = KT[a]
                        ka = 0.0
                        for i in range(n):
                            ka += KTa[i] * KTa[i]
                        knorm += ka
                    gain_norm[k] = np.sqrt(knorm)
                    if store_ex_var:  # CV K S K^T CV^T = |V CV|^2 (logscan.filters.coding)
                        ex_var[k] = coded_variance(V, m, n, cv)
                    for a in range(m):
                        j = rows[a]
                        pos[j] = a
                        if store_y:
                            y_out[k, j] = y[a]
                            S_diag_out[k, j] = S[a, a]
                    # per-group NIS on the group's own block of S
                    r = zero
                    for a in range(ng):
                        g = sel_g[a]
                        mg = group_sizes[g]
                        updated[k, g] = True
                        if ng == 1:  # the group is the whole update: its NIS is the step's
                            nis_group[k, g] = nis[k]
                        elif r == 0:  # the leading block's factor is L's leading block
                            nis_group[k, g] = forward_sq(L, mg, y, zero, v)
                        else:
                            cholesky(S, r, mg, Lg)
                            nis_group[k, g] = forward_sq(Lg, mg, y, r, v)
                        r += mg
                else:
                    ok = False
            if not ok:
                diverged[k] = pending = _restart(x, P, x0, P0, seed_done)
        if store_S or store_K:
            _store_gain(k, pos, S, KT, S_out, K_out, store_S, store_K)
        _store(k, x, P, x_post, P_post_diag, P_post_full, store_P)
    steps_done[0] = N


def compiled_for(args: tuple):
    """ekf_run's compiled entry point for these arguments, the model id as a literal."""
    return dispatch.compiled_for_model(ekf_run, args)


def filter_into(model_id: int, model: EkfModel, sensors: EkfSensors, data: EkfData, out: EkfBuffers) -> None:
    """Filter ``data`` into ``out`` with the compiled ``ekf_run``, on fresh work arrays."""
    args = (model_id, model, sensors, data, out, work_arrays(model, sensors, data))
    compiled_for(args)(*args)


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
    steps_done: np.ndarray | None = None,
    coding: CodedVariance | None = None,
    seed: bool | None = None,
) -> EkfTrace:
    """Filter the aligned run with the model; see the module docstring for the conventions.
    ``steps_done``: a (1,) int64 array the kernel sets to the steps filtered so far (a progress
    watcher's; the kernel releases the GIL). ``coding``: the trace's ``ex_variance`` is the
    encoded check's predicted variance with that coding vector (`logscan.filters.coding`). ``seed``:
    start by seeding the directly observed states (None: when no x0 is given; `pack_run`).

    Memory: the full P, S and K add N*n*n, N*m*m and N*n*m float64 (a 1 h 100 Hz quadcopter log:
    415 MB each); `store_gain=False` / `store_S=False` drop K / S (the trace keeps NIS and the gain
    norm), `store_innovations=False` drops y and S_diag (2 * N*m float32: 35 MB for that log),
    `full_P` adds P_prior and P_post.
    """
    k = pack_run(model, run, Q=Q, R=R, x0=x0, P0=P0, coding=coding, seed=seed)
    N, n, G, m = run.n_steps, model.n_states, len(k.group_names), k.z.shape[1]
    out = trace_buffers(
        N,
        n,
        G,
        m,
        full_P=full_P,
        store_gain=store_gain,
        store_S=store_S,
        store_innovations=store_innovations,
        store_ex_var=coding is not None,
    )
    if steps_done is not None:
        out = out._replace(steps_done=steps_done)
    if N:
        filter_into(*k.kernel_arguments(), out)
    return _trace(model, run, k, out, full_P, store_gain, store_S, store_innovations, coding is not None)


def _trace(
    model: Model,
    run: AlignedRun,
    k: KernelInputs,
    out: EkfBuffers,
    full_P: bool,
    store_gain: bool,
    store_S: bool,
    store_innovations: bool,
    store_ex_var: bool,
) -> EkfTrace:
    """The trace of a filtered run: the kernel's buffers, the ones not stored as None."""
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
        ex_variance=out.ex_var if store_ex_var else None,
        divergence_episodes=divergence_episodes(t, out.diverged, out.m_k),
    )


follow_dependencies(__name__)
