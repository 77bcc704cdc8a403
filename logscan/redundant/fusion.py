"""Sensor fusion of one redundant sensor group into one signal (thesis chapter III; docs/algorithms.md section 4.5).

Every method takes the group's readings as an (N, s) array, one column per sensor on the detection grid, NaN (or any
non-finite value) where a sensor has no reading, and returns one fused value per step (NaN when no sensor reads):

 - naive average: the mean of the readings present at the step (thesis eq. 1);
 - moving average: the naive average, then the simple trailing mean over the last n steps (eq. 2);
 - median: the middle reading, or the mean of the two middle ones for an even count (eq. 3);
 - iterative filter: a weighted mean whose weights are re-estimated from each sensor's mean squared distance to the
   previous estimate over a block of T consecutive steps, iterated to convergence (eq. 4, reciprocal weights);
 - Marzullo: each reading is the interval [y_i - eps_i, y_i + eps_i]; with at most f of the n intervals faulty, the
   fused interval is the smallest interval containing every point that lies in at least n - f intervals (Marzullo's
   fault-tolerant intersection; it widens as f grows); a sensor whose interval misses it is flagged faulty;
 - hybrid: the median's value with Marzullo's fault flags (thesis section 4.3.5).

``rmse`` compares a fused signal with a reference (the fault-free fusion) and ``fit_poly`` fits the 5th-order
polynomial a profile's ``poly`` transform takes (pedal effort to pedal position in the thesis).
Everything is vectorised over time steps; the only loops run over sensors' iterations, never over samples.
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.polynomial import Polynomial

IF_BLOCK = 25  # T: consecutive steps sharing one set of iterative-filter weights (the smallest A-TFM window)
IF_ROUNDS = 10_000  # a cap only: blocks stop at their tolerance, nearly all within 50 rounds


def _readings(values: np.ndarray) -> np.ndarray:
    """``values`` as a float (N, s) array with NaN for every non-finite reading."""
    X = np.array(values, dtype=float)
    if X.ndim != 2:
        raise ValueError(f"fusion expects readings shaped (steps, sensors), got shape {X.shape}")
    X[~np.isfinite(X)] = np.nan
    return X


def _masked_mean(X: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
    """Weighted mean of the finite entries along the last axis; NaN where no finite entry has weight."""
    M = np.isfinite(X)
    W = M.astype(float) if w is None else np.where(M, w, 0.0)
    num = np.where(M, X, 0.0) * W
    den = W.sum(axis=-1)
    return np.divide(num.sum(axis=-1), den, out=np.full(den.shape, np.nan), where=den > 0)


def naive_average(values: np.ndarray) -> np.ndarray:
    """(N, s) readings (NaN: none) -> (N,) mean of the finite readings (NaN when none)."""
    # v_hat = (v_1 + ... + v_n) / n over the n sensors reading at the step
    return _masked_mean(_readings(values))


def moving_average(values: np.ndarray, n: int = 5) -> np.ndarray:
    """naive average, then the trailing mean over the last n steps (finite values only; fewer at the start)."""
    if int(n) != n or n < 1:
        raise ValueError(f"moving average window n must be a positive integer, got {n!r}")
    v = naive_average(values)
    # v_hat_t = (v_t + v_{t-1} + ... + v_{t-(n-1)}) / n, over the finite v in the window
    padded = np.concatenate([np.full(int(n) - 1, np.nan), v])
    return _masked_mean(sliding_window_view(padded, int(n)))


def median(values: np.ndarray) -> np.ndarray:
    """(N,) median of the finite readings per step."""
    X = np.sort(_readings(values), axis=1)  # NaN sorts last
    k = np.isfinite(X).sum(axis=1)
    # v_t = x_m, m = (n + 1) / 2 for odd n; (x_m + x_{m+1}) / 2, m = n / 2 for even n (1-based, sorted)
    lo = np.maximum((k - 1) // 2, 0)[:, None]
    hi = np.maximum(k // 2, 0)[:, None]
    if X.shape[1] == 0:
        return np.full(X.shape[0], np.nan)
    m = (np.take_along_axis(X, lo, axis=1)[:, 0] + np.take_along_axis(X, hi, axis=1)[:, 0]) / 2
    return np.where(k > 0, m, np.nan)


def _reciprocal_weights(d: np.ndarray) -> np.ndarray:
    """w_i = 1 / d_i scaled by min_j d_j (scale is free); when some d_j = 0 those sensors share all the weight."""
    d_min = np.nanmin(np.where(np.isfinite(d), d, np.inf), axis=-1, keepdims=True)
    w = np.divide(d_min, d, out=np.zeros_like(d), where=np.isfinite(d) & (d > 0))
    # the limit of 1 / d as d_j -> 0: the exact sensors take weight 1, the others 0
    return np.where(d_min == 0, (d == 0).astype(float), w)


def iterative_filter(
    values: np.ndarray, iterations: int = IF_ROUNDS, tol: float = 1e-9, *, block: int = IF_BLOCK
) -> np.ndarray:
    """Iterative filtering (thesis III, eq. 4; the weights of Laureti et al. as used by Rezvani et al.).

    The log is cut into blocks of T = ``block`` consecutive steps (the thesis's "block of the measurement ...
    at T consecutive instants"); within a block, with x_i^t sensor i's reading at step t:
        r^{l+1}(t) = sum_i w_i^l x_i^t / sum_i w_i^l,                 w^0 = 1 (so r^1 is the naive average)
        d_i^{l+1}  = (1 / T_i) sum_t (x_i^t - r^{l+1}(t))^2             (mean squared distance over the block)
        w_i^{l+1}  = 1 / d_i^{l+1}                                      (reciprocal discriminant g(d) = d^-1)
    iterated in each block until max_t |r^{l+1} - r^l| <= tol * (1 + max_t |r|) there, or ``iterations`` rounds.
    T_i counts sensor i's finite readings in the block; a step where every present sensor has weight 0 takes the
    naive average. The blocks still moving iterate together (vectorised over their steps); a converged block stops,
    so the few slow ones (the reciprocal weights can crawl when one sensor nears the estimate: about 1 block in 300
    of random data needs more than 300 rounds) cost little. The weights favour whichever sensor is nearest: with
    two agreeing sensors and one outlier the estimate settles on the agreeing pair (often on one of them), far from
    the outlier; ``block=1`` gives the per-step variant.
    """
    if int(block) != block or block < 1:
        raise ValueError(f"iterative filter block T must be a positive integer, got {block!r}")
    X = _readings(values)
    N, s = X.shape
    T = int(block)
    B = -(-N // T)
    Xb = np.concatenate([X, np.full((B * T - N, s), np.nan)]).reshape(B, T, s)
    M = np.isfinite(Xb)
    T_i = M.sum(axis=1)  # (B, s)
    fallback = _masked_mean(Xb)  # naive average, (B, T)
    r = fallback.copy()
    active = np.arange(B)  # the blocks not yet converged
    for _ in range(int(iterations)):
        if active.size == 0:
            break
        Xa, Ma, r_a = Xb[active], M[active], r[active]
        # d_i = (1 / T_i) sum_t (x_i^t - r(t))^2
        sq = np.where(Ma, (Xa - r_a[:, :, None]) ** 2, 0.0).sum(axis=1)
        d = np.divide(sq, T_i[active], out=np.full(sq.shape, np.nan), where=T_i[active] > 0)
        w = _reciprocal_weights(d)
        # r(t) = X w / sum w
        r_new = _masked_mean(Xa, w[:, None, :])
        r_new = np.where(np.isnan(r_new), fallback[active], r_new)
        step = np.max(np.abs(np.where(np.isfinite(r_a), r_new - r_a, 0.0)), axis=1)
        scale = 1.0 + np.max(np.abs(np.where(np.isfinite(r_new), r_new, 0.0)), axis=1)
        r[active] = r_new
        active = active[step > tol * scale]
    return r.reshape(B * T)[:N]


def marzullo(values: np.ndarray, eps: np.ndarray, f: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Marzullo's fault-tolerant intersection per step: returns (low, high, faulty (N, s) bool).

    Sensor intervals I_i = [y_i - eps_i, y_i + eps_i] (eps (N, s) or (s,); a reading or eps that is not finite drops
    the sensor at that step). With n intervals at a step and at most f faulty (default f = (n - 1) // 2), the result
    is the smallest interval containing every point covered by at least n - f intervals (at least 1 when f >= n):
    [low, high] = [min, max] of {p : #{i : p in I_i} >= n - f}. NaN low/high where no point is covered that often.
    A sensor is faulty where its interval does not intersect [low, high] (never where low is NaN).
    Vectorised: the 2s endpoints of each step sorted (starts before ends at a tie, the intervals are closed), and
    a running coverage count.
    """
    X = _readings(values)
    E = np.broadcast_to(np.asarray(eps, dtype=float), X.shape)
    if np.any(E[np.isfinite(E)] < 0):
        raise ValueError("marzullo: error bounds eps must be >= 0")
    if f is not None and (int(f) != f or f < 0):
        raise ValueError(f"marzullo: the number of faulty sensors f must be a non-negative integer, got {f!r}")
    present = np.isfinite(X) & np.isfinite(E)
    lo_i = np.where(present, X - E, np.nan)
    hi_i = np.where(present, X + E, np.nan)
    n = present.sum(axis=1)
    faults = (n - 1) // 2 if f is None else np.full_like(n, int(f))
    need = np.maximum(n - faults, 1)[:, None]
    # events: +1 at each start y_i - eps_i, -1 at each end y_i + eps_i; stable sort keeps starts first at ties
    pos = np.concatenate([lo_i, hi_i], axis=1)
    delta = np.concatenate([present, -present.astype(int)], axis=1).astype(int)
    order = np.argsort(pos, axis=1, kind="stable")
    p = np.take_along_axis(pos, order, axis=1)
    dv = np.take_along_axis(delta, order, axis=1)
    # coverage just after a start = intervals containing that point; just before an end = likewise
    cover = np.cumsum(dv, axis=1)
    low = np.where((dv > 0) & (cover >= need), p, np.inf).min(axis=1, initial=np.inf)
    high = np.where((dv < 0) & (cover - dv >= need), p, -np.inf).max(axis=1, initial=-np.inf)
    found = np.isfinite(low) & np.isfinite(high)
    low = np.where(found, low, np.nan)
    high = np.where(found, high, np.nan)
    faulty = present & found[:, None] & ((hi_i < low[:, None]) | (lo_i > high[:, None]))
    return low, high, faulty


def hybrid(values: np.ndarray, eps: np.ndarray, f: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Median value plus Marzullo's fault flag: (fused (N,), faulty (N, s))."""
    _, _, faulty = marzullo(values, eps, f)
    return median(values), faulty


def fuse_all(values: np.ndarray, eps: np.ndarray | None = None, n_moving: int = 5) -> dict[str, np.ndarray]:
    """Every method's fused (N,) signal by name: "average", "moving_average", "median",
    "iterative", and when eps is given "marzullo" (the interval's midpoint) and "hybrid"."""
    fused = {
        "average": naive_average(values),
        "moving_average": moving_average(values, n_moving),
        "median": median(values),
        "iterative": iterative_filter(values),
    }
    if eps is not None:
        low, high, _ = marzullo(values, eps)
        fused["marzullo"] = (low + high) / 2
        fused["hybrid"] = fused["median"]
    return fused


def rmse(fused: np.ndarray, reference: np.ndarray) -> float:
    """Root mean square of fused - reference over steps where both are finite (NaN if none)."""
    e = np.asarray(fused, dtype=float) - np.asarray(reference, dtype=float)
    e = e[np.isfinite(e)]
    # RMSE = sqrt(mean((v_hat - v_ref)^2))
    return float(np.sqrt(np.mean(e**2))) if e.size else float("nan")


def fit_poly(x: np.ndarray, y: np.ndarray, degree: int = 5) -> list[float]:
    """Coefficients c0..c_degree (numpy.polynomial.polynomial order, as the profile's
    [redundant.<g>] sensor `poly` takes them) of a least-squares fit of y on x
    (numpy.polynomial.Polynomial.fit(...).convert()), finite pairs only."""
    x = np.asarray(x, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    if x.shape != y.shape:
        raise ValueError(f"fit_poly: x and y differ in length ({x.size} vs {y.size})")
    if int(degree) != degree or degree < 0:
        raise ValueError(f"fit_poly: degree must be a non-negative integer, got {degree!r}")
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() <= degree:
        raise ValueError(f"fit_poly: {ok.sum()} finite (x, y) pairs cannot fit a degree-{degree} polynomial")
    # y ~ c0 + c1 x + ... + c_degree x^degree, least squares on the finite pairs
    c = Polynomial.fit(x[ok], y[ok], int(degree)).convert().coef
    return [float(v) for v in np.pad(c, (0, int(degree) + 1 - c.size))]
