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
from numba.extending import overload

from logscan.filters.linalg import all_finite, all_finite2, cho_solve_rows, cholesky
from logscan.models import dispatch
from logscan.models.model_kernels import literal_kernel
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


# The evidence of every fault direction of every phase is one signature: column s = j * D + d of
# the (n, J * D) matrix mu (phase j, direction d), so a step moves all of them with one product
# per matrix (F mu, H mu, L^-1 r, K r) whose innermost loop runs along the signatures (contiguous,
# vectorised). Each sum keeps the order of the plain per-signature loops it replaces (a product
# skips only exact zeros of F and H), so the evidence is the same to the last bit.


def model_f_into(model_id, p, x, u, dt, x_next, k, xs, A0, F, Aw, Jw, Jnw):
    """x_next = f(x, u) of the model ``model_id`` (a compile-time constant; numba code only): the
    RK4 step of `logscan.models.rk4.rk4_f` in place, without its Jacobian, for a model with
    continuous dynamics (its sums in the same order: the same bits as the step the EKF takes); the
    model's own predict_into for the others (exactly discretised, no Jacobian to save). k, xs (n,),
    A0 (0, 0) and F, Aw, Jw, Jnw (n, n) are work arrays."""
    raise NotImplementedError("model_f_into is resolved by numba at compile time")


@overload(model_f_into)
def _model_f_into(model_id, p, x, u, dt, x_next, k, xs, A0, F, Aw, Jw, Jnw):
    fA = literal_kernel(model_id, "fA")
    if fA is not None:

        def rk4(model_id, p, x, u, dt, x_next, k, xs, A0, F, Aw, Jw, Jnw):
            c = dt / 6.0
            for i in range(x.size):
                x_next[i] = x[i]
                xs[i] = x[i]
            for stage in range(4):
                fA(p, xs, u, k, A0, False)
                w = 1.0 if stage == 0 or stage == 3 else 2.0
                step = 0.5 * dt if stage < 2 else dt
                for i in range(x.size):
                    x_next[i] += c * w * k[i]
                    xs[i] = x[i] + step * k[i]

        return rk4
    predict_into = literal_kernel(model_id, "predict_into")
    if predict_into is not None:

        def impl(model_id, p, x, u, dt, x_next, k, xs, A0, F, Aw, Jw, Jnw):
            predict_into(p, x, u, dt, x_next, F, k, xs, Aw, Jw, Jnw)

        return impl


@njit(cache=True, error_model="numpy")
def _mm_rows(A, B, ra, ca, cb, out):
    """out[:ra, :cb] = A[:ra, :ca] @ B[:ca, :cb], each sum in c order (zeros of A skipped: exact)."""
    for i in range(ra):
        for j in range(cb):
            out[i, j] = 0.0
        for c in range(ca):
            a = A[i, c]
            if a != 0.0:
                for j in range(cb):
                    out[i, j] += a * B[c, j]


@njit(cache=True, error_model="numpy")
def _transpose(A, r, c, out):
    """out[:c, :r] = A[:r, :c]^T."""
    for i in range(r):
        for j in range(c):
            out[j, i] = A[i, j]


@njit(cache=True, error_model="numpy")
def _mm_t(A, B, ra, ca, rb, out):
    """out[:ra, :rb] = A[:ra, :ca] @ B[:rb, :ca]^T."""
    for i in range(ra):
        for j in range(rb):
            s = 0.0
            for c in range(ca):
                s += A[i, c] * B[j, c]
            out[i, j] = s


@njit(cache=True, error_model="numpy")
def _input_columns(model_id, p, xk, uk, dt, act_dirs, h, ua, Gd, hi, lo, k, xs, A0, F, Aw, Jw, Jnw):
    """Gd[a] = df/du . act_dirs[a] at (xk, uk): central differences of the model's step (f alone
    when the model can; hi, lo, k, xs (n,), A0 (0, 0) and F, Aw, Jw, Jnw (n, n) are work arrays)."""
    literally(model_id)
    n, nu = xk.size, uk.size
    for a in range(act_dirs.shape[0]):
        for i in range(nu):
            ua[i] = uk[i] + h * act_dirs[a, i]
        model_f_into(model_id, p, xk, ua, dt, hi, k, xs, A0, F, Aw, Jw, Jnw)
        for i in range(nu):
            ua[i] = uk[i] - h * act_dirs[a, i]
        model_f_into(model_id, p, xk, ua, dt, lo, k, xs, A0, F, Aw, Jw, Jnw)
        for i in range(n):
            Gd[a, i] = (hi[i] - lo[i]) / (2.0 * h)


@njit(cache=True, error_model="numpy")
def _copy_square(src, n, dst):
    """dst[:n, :n] = src[:n, :n], element by element: a slice assignment from an array would compile
    numba's shape-mismatch message (string formatting, about 3 s of the first run's compile)."""
    for i in range(n):
        for c in range(n):
            dst[i, c] = src[i, c]


@njit(cache=True, error_model="numpy")
def _abs_max(v):
    """max |v_i| (0.0 for an empty v; NaN when v holds one, as np.abs(v).max()), without the
    temporary array and numba's array-max implementation to compile."""
    best = 0.0
    for i in range(v.size):
        a = abs(v[i])
        if a != a:
            return a
        if a > best:
            best = a
    return best


@njit(cache=True, error_model="numpy")
def _joseph(P, KT, Hs, Rm, m, n, IKH, IKHt, FP, KR, row):
    """P = (I - K H) P (I - K H)^T + K R K^T, in place (K^T in KT, m rows)."""
    for i in range(n):
        for c in range(n):
            IKH[i, c] = 1.0 if i == c else 0.0
        for a in range(m):
            k = KT[a, i]
            for c in range(n):
                IKH[i, c] -= k * Hs[a, c]
    _mm_rows(IKH, P, n, n, n, FP)
    _transpose(IKH, n, n, IKHt)
    _mm_rows(FP, IKHt, n, n, n, P)
    for i in range(n):
        for b in range(m):
            KR[i, b] = 0.0
        for a in range(m):
            k = KT[a, i]
            for b in range(m):
                KR[i, b] += k * Rm[a, b]
        for c in range(n):
            row[c] = 0.0
        for b in range(m):
            k = KR[i, b]
            for c in range(n):
                row[c] += k * KT[b, c]
        for c in range(n):
            P[i, c] += row[c]


@njit(cache=True, error_model="numpy")
def _signatures_update(mu, Hs, L, KT, m, n, rows, bias_of_row, A, D, J, r, v, acc, lam):
    """r = H mu (+ the unit bias of each sensor signature on its row); lambda += |L^-1 r|^2;
    mu -= K r; for all J * D signatures (columns) at once."""
    ns = J * D
    for a in range(m):
        for s in range(ns):
            r[a, s] = 0.0
        for c in range(n):
            h = Hs[a, c]
            if h != 0.0:
                for s in range(ns):
                    r[a, s] += h * mu[c, s]
        b = bias_of_row[rows[a]]
        if b >= 0:
            for j in range(J):
                r[a, j * D + A + b] += 1.0
    for s in range(ns):
        acc[s] = 0.0
    for i in range(m):  # forward substitution L v = r, all columns
        for s in range(ns):
            v[i, s] = r[i, s]
        for c in range(i):
            l = L[i, c]
            for s in range(ns):
                v[i, s] -= l * v[c, s]
        d = L[i, i]
        for s in range(ns):
            t = v[i, s] / d
            v[i, s] = t
            acc[s] += t * t
    for s in range(ns):
        lam[s] += acc[s]
    for i in range(n):
        for s in range(ns):
            acc[s] = 0.0
        for a in range(m):
            k = KT[a, i]
            for s in range(ns):
                acc[s] += k * r[a, s]
        for s in range(ns):
            mu[i, s] -= acc[s]


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
    ns = J * D
    m_total = R.shape[0]
    out = np.full((N // stride + 1, D), np.nan)
    mu, mu_next = np.zeros((n, ns)), np.zeros((n, ns))  # signature s = j * D + d in column s
    lam = np.zeros(ns)
    start = np.full(J, -1, dtype=np.int64)  # window start of each phase's running signature
    bias_of_row = np.full(m_total, -1, dtype=np.int64)  # the sensor signature biased on each row
    for b in range(sensor_cols.size):
        bias_of_row[sensor_cols[b]] = b
    P = P0.copy()
    x_next, kv, xs, row = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    x_hi, x_lo, A0 = np.empty(n), np.empty(n), np.empty((0, 0))
    F, Ft, Aw, Jw, Jnw = np.empty((n, n)), np.empty((n, n)), np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    FP, IKH, IKHt = np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    Gd = np.zeros((A, n))
    ua = np.empty(nu)
    hx, Hs = np.zeros(m_total), np.zeros((m_total, n))
    R3, D3 = np.empty((3, 3)), np.empty((3, 3, 3))
    rows = np.empty(m_total, dtype=np.int64)
    S, L, Rm = np.empty((m_total, m_total)), np.zeros((m_total, m_total)), np.empty((m_total, m_total))
    PHt, KT, KR = np.empty((n, m_total)), np.empty((m_total, n)), np.empty((n, m_total))
    r, v, acc = np.zeros((m_total, ns)), np.zeros((m_total, ns)), np.zeros(ns)
    zero = np.int64(0)
    for k in range(1, N):
        # ---- restart the phases whose window starts here ---------------------------------------
        for j in range(J):
            if k >= j * stride and (k - j * stride) % window == 0:
                if start[j] >= 0:
                    for d in range(D):
                        out[start[j] // stride, d] = lam[j * D + d]
                start[j] = k
                for s in range(j * D, (j + 1) * D):
                    lam[s] = 0.0
                    for i in range(n):
                        mu[i, s] = 0.0
        xk = x_post[k - 1]
        if not (all_finite(xk) and all_finite(x_prior[k]) and all_finite2(P)):
            start[:] = -1  # a diverged filter: no verdict until the next window start
            _copy_square(P0, n, P)
            continue
        # ---- predict: F at (x_post, u), then G_a = df/du . dir_a by central differences -------
        # (one call site each: the model's step is inlined wherever it is called, and compiled as often)
        dispatch.model_predict_into(model_id, p, xk, u[k], dt, x_next, F, kv, xs, Aw, Jw, Jnw)
        h = 1e-6 * (1.0 + _abs_max(u[k]))  # 0.0 for a model without inputs
        _input_columns(model_id, p, xk, u[k], dt, act_dirs, h, ua, Gd, x_hi, x_lo, kv, xs, A0, Ft, Aw, Jw, Jnw)
        # P_prior = F P F^T + Q
        _mm_rows(F, P, n, n, n, FP)
        _transpose(F, n, n, Ft)
        _mm_rows(FP, Ft, n, n, n, P)
        for i in range(n):
            for c in range(n):
                P[i, c] += Q[i, c]
        # mu_prior = F mu_post (+ G du for an actuator fault), every signature at once
        _mm_rows(F, mu, n, n, ns, mu_next)
        mu, mu_next = mu_next, mu
        for j in range(J):
            for a in range(A):
                value = act_values[k, a]
                for i in range(n):
                    mu[i, j * D + a] += Gd[a, i] * value
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
        _mm_rows(Hs, PHt, m, n, m, S)
        for a in range(m):
            for b in range(m):
                S[a, b] += Rm[a, b]
        if not cholesky(S, zero, m, L):  # int64 as in the EKF: one compile of it
            start[:] = -1
            _copy_square(P0, n, P)
            continue
        for a in range(m):
            for i in range(n):
                KT[a, i] = PHt[i, a]
        cho_solve_rows(L, m, KT, n)
        _joseph(P, KT, Hs, Rm, m, n, IKH, IKHt, FP, KR, row)
        # r = H mu_prior (+ the unit bias);  lambda += r^T S^-1 r;  mu_post = mu_prior - K r
        _signatures_update(mu, Hs, L, KT, m, n, rows, bias_of_row, A, D, J, r, v, acc, lam)
    for j in range(J):  # the windows the log's end cut short: the evidence up to the end
        if start[j] >= 0:
            for d in range(D):
                out[start[j] // stride, d] = lam[j * D + d]
    return out


follow_dependencies(__name__)
