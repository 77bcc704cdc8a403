"""The fault-signature kernel of the observability verdict: how much evidence a unit fault leaves in
the filter's innovations over a window (docs/algorithms.md section 10).

A fault the filter does not model moves the mean of its error and of its innovations; to first order
(the filter linearised along its own trajectory) that mean obeys

    mu_prior_k = F_k mu_post_{k-1} + G_k du_k          (an actuator fault du_k enters like an input)
    r_k        = H_k mu_prior_k + b_k                   (a sensor fault b_k adds to its measurement)
    mu_post_k  = mu_prior_k - K_k r_k                   (the filter's own update pulls part of it in)

and the evidence it leaves over a window is the non-centrality of the innovations,
lambda = sum_k r_k^T S_k^-1 r_k, the filter's own S and K recomputed along its trajectory
(P_prior = F P F^T + Q, S = H P H^T + R, K = P H^T S^-1, Joseph update). The kernel runs one
signature per fault direction and per phase: phase j restarts (mu = 0, lambda = 0) at every window
start k = j * stride + q * window, so every window start on the stride grid gets the evidence of a
fault beginning there, in one pass.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import literally, njit

from logscan.filters.linalg import all_finite, all_finite2, cho_solve_rows, cholesky, forward_sq
from logscan.models import dispatch
from logscan.numba_cache import follow_dependencies


# ================================================================================================
# the kernel's arguments (N steps, n states, nu inputs, G groups, m_total outputs of all groups
# stacked group after group, A actuator and B sensor fault directions)
# ================================================================================================
class FilterModel(NamedTuple):
    """The filter's model: parameters, noises, prior and measurement groups (as the EKF ran)."""

    p: np.ndarray  # (n_p,) float64: the model's packed parameters (Model.param_vector)
    dt: float  # the grid step, s
    Q: np.ndarray  # (n, n) float64: process noise covariance of one step
    R: np.ndarray  # (m_total, m_total) float64: measurement noise covariance
    P0: np.ndarray  # (n, n) float64: the covariance at the first step
    group_ids: np.ndarray  # (G,) int64: each group's id in the model (its h, H)
    group_offsets: np.ndarray  # (G,) int64: each group's first output
    group_sizes: np.ndarray  # (G,) int64: each group's number of outputs


class FilterTrajectory(NamedTuple):
    """The filter's own trajectory, along which it is linearised."""

    x_prior: np.ndarray  # (N, n) float64
    x_post: np.ndarray  # (N, n) float64
    u: np.ndarray  # (N, nu) float64: the inputs as the filter held them (finite)
    updated: np.ndarray  # (N, G) bool: the groups the filter updated with at step k


class FaultDirections(NamedTuple):
    """The unit faults: A actuator directions, then B sensor biases."""

    act_dirs: np.ndarray  # (A, nu) float64: the input change per unit of actuator a
    act_values: np.ndarray  # (N, A) float64: actuator a's value (du_k = act_dirs[a] * act_values[k, a])
    sensor_cols: np.ndarray  # (B,) int64: the measurement column of each unit sensor bias


class Windows(NamedTuple):
    """The evidence windows, in steps."""

    window: np.int64  # the window length, a multiple of stride
    stride: np.int64  # the grid of window starts


@njit(cache=True, error_model="numpy")
def _mm(A, B, ra, ca, cb, out):
    """out[:ra, :cb] = A[:ra, :ca] @ B[:ca, :cb] (plain loops: compile in a fraction of np.dot's time)."""
    for i in range(ra):
        for j in range(cb):
            s = 0.0
            for c in range(ca):
                s += A[i, c] * B[c, j]
            out[i, j] = s


@njit(cache=True, error_model="numpy")
def _mm_t(A, B, ra, ca, rb, out):
    """out[:ra, :rb] = A[:ra, :ca] @ B[:rb, :ca]^T."""
    for i in range(ra):
        for j in range(rb):
            s = 0.0
            for c in range(ca):
                s += A[i, c] * B[j, c]
            out[i, j] = s


@njit(cache=True)
def signature_evidence(model_id, model, trajectory, faults, windows):
    """Non-centrality lambda of a unit fault per window start (on the stride grid) and direction.

    ``model`` (FilterModel) and ``trajectory`` (FilterTrajectory): the filter and its run; ``faults``
    (FaultDirections): a unit relative offset per actuator, a unit bias per sensor column;
    ``windows`` (Windows); ``model_id``: the model's kernel id, compiled as a literal.
    Returns (N // stride + 1, A + B) float64: lambda over [k, k + window) for k = i * stride (over
    what is left of the log for the last windows), NaN where the filter's trajectory is not finite.
    """
    literally(model_id)
    # the arguments' arrays under the kernel's names, read once: an attribute read inside the loop
    # would count a reference up and down at every access
    p, dt, Q, R, P0 = model.p, model.dt, model.Q, model.R, model.P0
    group_ids, offsets, sizes = model.group_ids, model.group_offsets, model.group_sizes
    x_prior, x_post, u, updated = trajectory.x_prior, trajectory.x_post, trajectory.u, trajectory.updated
    act_dirs, act_values, sensor_cols = faults.act_dirs, faults.act_values, faults.sensor_cols
    window, stride = windows.window, windows.stride
    N, n = x_post.shape
    nu = u.shape[1]
    A = act_dirs.shape[0]
    D = A + sensor_cols.size
    J = window // stride
    m_total = R.shape[0]
    out = np.full((N // stride + 1, D), np.nan)
    mu = np.zeros((J, D, n))
    lam = np.zeros((J, D))
    start = np.full(J, -1, dtype=np.int64)  # window start of each phase's running signature
    P = P0.copy()
    x_next, x_hi, kv, xs, tmp = np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    F, F2, Aw, Jw, Jnw = np.empty((n, n)), np.empty((n, n)), np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    FP, IKH = np.empty((n, n)), np.empty((n, n))
    Gd = np.zeros((A, n))
    ua = np.empty(nu)
    hx, Hs = np.zeros(m_total), np.zeros((m_total, n))
    R3, D3 = np.empty((3, 3)), np.empty((3, 3, 3))
    rows = np.empty(m_total, dtype=np.int64)
    S, L, Rm = np.empty((m_total, m_total)), np.zeros((m_total, m_total)), np.empty((m_total, m_total))
    PHt, KT, KR = np.empty((n, m_total)), np.empty((m_total, n)), np.empty((n, m_total))
    r, v = np.zeros(m_total), np.zeros(m_total)
    zero = np.int64(0)
    for k in range(1, N):
        # ---- restart the phases whose window starts here ---------------------------------------
        for j in range(J):
            if k >= j * stride and (k - j * stride) % window == 0:
                if start[j] >= 0:
                    for d in range(D):
                        out[start[j] // stride, d] = lam[j, d]
                start[j] = k
                mu[j] = 0.0
                lam[j] = 0.0
        xk = x_post[k - 1]
        if not (all_finite(xk) and all_finite(x_prior[k]) and all_finite2(P)):
            start[:] = -1  # a diverged filter: no verdict until the next window start
            P[:] = P0
            continue
        # ---- predict: F at (x_post, u), then G_a = df/du . dir_a by central differences -------
        # (one call site: the model's step is inlined wherever it is called, and compiled as often)
        h = 1e-6 * (1.0 + (np.abs(u[k]).max() if nu > 0 else 0.0))  # a model may have no input
        for e in range(2 * A + 1):
            a, sign = (e - 1) // 2, 1.0 if e % 2 == 1 else -1.0
            for i in range(nu):
                ua[i] = u[k, i] + (sign * h * act_dirs[a, i] if e > 0 else 0.0)
            dispatch.model_predict_into(model_id, p, xk, ua, dt, x_next, F2, kv, xs, Aw, Jw, Jnw)
            if e == 0:
                F[:] = F2
            elif e % 2 == 1:
                x_hi[:] = x_next
            else:
                for i in range(n):
                    Gd[a, i] = (x_hi[i] - x_next[i]) / (2.0 * h)
        # P_prior = F P F^T + Q
        _mm(F, P, n, n, n, FP)
        _mm_t(FP, F, n, n, n, P)
        for i in range(n):
            for c in range(n):
                P[i, c] += Q[i, c]
        for j in range(J):
            if start[j] < 0:
                continue
            for d in range(D):
                # mu_prior = F mu_post (+ G du for an actuator fault)
                for i in range(n):
                    s = 0.0
                    for c in range(n):
                        s += F[i, c] * mu[j, d, c]
                    tmp[i] = s
                mu[j, d] = tmp
            for a in range(A):
                for i in range(n):
                    mu[j, a, i] += Gd[a, i] * act_values[k, a]
        # ---- update with the groups the filter used ----------------------------------------
        m = zero
        Hs[:] = 0.0
        for g in range(group_ids.size):
            if updated[k, g]:
                dispatch.model_meas_into(model_id, group_ids[g], p, x_prior[k], u[k], m, hx, Hs, R3, D3)
                for c in range(sizes[g]):
                    rows[m + c] = offsets[g] + c
                m += sizes[g]
        if m == 0:
            continue
        for a in range(m):
            for b in range(m):
                Rm[a, b] = R[rows[a], rows[b]]
        # S = H P H^T + R;  K^T = S^-1 H P (S = L L^T)
        _mm_t(P, Hs, n, n, m, PHt)
        _mm(Hs, PHt, m, n, m, S)
        for a in range(m):
            for b in range(m):
                S[a, b] += Rm[a, b]
        if not cholesky(S, 0, m, L):
            start[:] = -1
            P[:] = P0
            continue
        for a in range(m):
            for i in range(n):
                KT[a, i] = PHt[i, a]
        cho_solve_rows(L, m, KT, n)
        # Joseph form: P = (I - K H) P (I - K H)^T + K R K^T
        for i in range(n):
            for c in range(n):
                s = 1.0 if i == c else 0.0
                for a in range(m):
                    s -= KT[a, i] * Hs[a, c]
                IKH[i, c] = s
        _mm(IKH, P, n, n, n, FP)
        _mm_t(FP, IKH, n, n, n, P)
        for i in range(n):
            for b in range(m):
                s = 0.0
                for a in range(m):
                    s += KT[a, i] * Rm[a, b]
                KR[i, b] = s
        for i in range(n):
            for c in range(n):
                s = 0.0
                for b in range(m):
                    s += KR[i, b] * KT[b, c]
                P[i, c] += s
        for j in range(J):
            if start[j] < 0:
                continue
            for d in range(D):
                # r = H mu_prior (+ the unit bias on its column)
                for a in range(m):
                    s = 0.0
                    for c in range(n):
                        s += Hs[a, c] * mu[j, d, c]
                    if d >= A and rows[a] == sensor_cols[d - A]:
                        s += 1.0
                    r[a] = s
                # lambda += r^T S^-1 r;  mu_post = mu_prior - K r
                lam[j, d] += forward_sq(L, m, r, zero, v)
                for i in range(n):
                    s = 0.0
                    for a in range(m):
                        s += KT[a, i] * r[a]
                    mu[j, d, i] -= s
    for j in range(J):  # the windows the log's end cut short: the evidence up to the end
        if start[j] >= 0:
            for d in range(D):
                out[start[j] // stride, d] = lam[j, d]
    return out


follow_dependencies(__name__)
