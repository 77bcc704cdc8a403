"""Plain numpy EKF: the test oracle of the numba core (same conventions, readable, slow).

It follows logscan.filters.ekf step by step with numpy/scipy linear algebra (cho_factor /
cho_solve, never inv) and the model's numpy f/F/h/H. The per-step Python loop is deliberate: this
module exists only to check the kernel in tests, never to filter a log.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import LinAlgError, cho_factor, cho_solve

from logscan.filters.ekf_pack import KernelInputs
from logscan.models.base import Model


def reference_ekf(model: Model, k: KernelInputs) -> dict:
    """Filter the packed run; returns x_prior, x_post, P_prior, P_post, y, nis, updated,
    rejected, gated, seeded, diverged (full P, for comparison with the kernel)."""
    with np.errstate(over="ignore", invalid="ignore"):  # divergence is detected, not warned
        return _reference_ekf(model, k)


def _reference_ekf(model: Model, k: KernelInputs) -> dict:
    N, n = k.u.shape[0], k.x0.size
    G, m_total = k.group_ids.size, k.z.shape[1]
    out = _outputs(N, n, G, m_total)
    slices = [slice(o, o + s) for o, s in zip(k.group_offsets, k.group_sizes)]
    is_direct = np.array([np.all(k.direct_idx[s] >= 0) for s in slices])
    x, P = k.x0.copy(), k.P0.copy()
    u_last = k.u_default.copy()
    pending, seed_done = k.seed_at_start, np.zeros(G, bool)

    def restart():
        return k.x0.copy(), k.P0.copy(), True, np.zeros(G, bool)

    for step in range(N):
        uk = k.u[step] if np.all(np.isfinite(k.u[step])) else u_last
        u_last = uk
        if step > 0:
            F = model.F(x, uk, k.dt)
            x = model.f(x, uk, k.dt)
            P = F @ P @ F.T + k.Q
            if not (np.all(np.isfinite(x)) and np.all(np.isfinite(P))):
                out["diverged"][step] = True
                x, P, pending, seed_done = restart()
        out["x_prior"][step], out["P_prior"][step] = x, P
        used = []
        for g, s in enumerate(slices):
            if not k.fresh[step, g]:
                continue
            zg = k.z[step, s]
            outside = np.any(zg < k.range_lo[s]) or np.any(zg > k.range_hi[s])
            if not np.all(np.isfinite(zg)) or outside:
                out["rejected"][step, g] = True
                continue
            if pending and is_direct[g] and not seed_done[g]:
                _seed(k, x, P, step, s)
                seed_done[g] = out["seeded"][step, g] = True
                continue
            if np.isfinite(k.gate[g]) and _gated(model, k, x, P, uk, step, g, out):
                continue
            used.append(g)
        if pending:
            pending = bool(np.any(is_direct & ~seed_done))
        if used:
            rows = np.concatenate([np.arange(slices[g].start, slices[g].stop) for g in used])
            result = _update(model, k, x, P, uk, step, used, rows)
            if result is not None:
                x, P, y, nis = result
                out["y"][step, rows] = y
                out["nis"][step] = nis
                out["updated"][step, used] = True
            else:
                out["diverged"][step] = True
                x, P, pending, seed_done = restart()
        out["x_post"][step], out["P_post"][step] = x, P
    return out


def _outputs(N: int, n: int, G: int, m_total: int) -> dict:
    """The result's arrays, NaN / False filled."""
    return {
        "x_prior": np.full((N, n), np.nan),
        "x_post": np.full((N, n), np.nan),
        "P_prior": np.full((N, n, n), np.nan),
        "P_post": np.full((N, n, n), np.nan),
        "y": np.full((N, m_total), np.nan),
        "nis": np.full(N, np.nan),
        "updated": np.zeros((N, G), bool),
        "rejected": np.zeros((N, G), bool),
        "gated": np.zeros((N, G), bool),
        "seeded": np.zeros((N, G), bool),
        "diverged": np.zeros(N, bool),
    }


def _seed(k: KernelInputs, x: np.ndarray, P: np.ndarray, step: int, s: slice) -> None:
    """Re-seed, in place, the states a direct group observes from its sample at ``step``."""
    zg = k.z[step, s]
    idx, gain = k.direct_idx[s], k.direct_gain[s]
    for j, i in enumerate(idx):
        x[i] = zg[j] / gain[j]
        P[i, :] = 0.0
        P[:, i] = 0.0
        rj = k.R_all[s, s][j, j]
        if k.R_std.shape[0] == k.u.shape[0] and np.isfinite(k.R_std[step, s][j]) and k.R_std[step, s][j] > 0:
            rj = k.R_std[step, s][j] ** 2
        P[i, i] = rj / gain[j] ** 2


def _gated(model: Model, k: KernelInputs, x, P, uk, step: int, g: int, out: dict) -> bool:
    """The outlier gate: group ``g`` alone against the prior; over its gate, its innovation is
    kept in ``out`` and it is left out of the update (True)."""
    rows = np.arange(k.group_offsets[g], k.group_offsets[g] + k.group_sizes[g])
    y, H, R = _innovation(model, k, x, uk, step, [g], rows)
    if float(y @ np.linalg.solve(H @ P @ H.T + R, y)) <= k.gate[g]:
        return False
    out["y"][step, rows] = y
    out["gated"][step, g] = True
    return True


def _innovation(model: Model, k: KernelInputs, x, uk, step: int, used: list[int], rows: np.ndarray):
    """(y~, H, R) of the groups ``used`` (outputs ``rows``) at ``step`` against the state ``x``."""
    H = np.vstack([model.H(k.group_names[g], x, uk) for g in used])
    hx = np.concatenate([model.h(k.group_names[g], x, uk) for g in used])
    y = k.z[step, rows] - hx
    y = np.where(k.wrap[rows], (y + np.pi) % (2 * np.pi) - np.pi, y)
    R = k.R_all[np.ix_(rows, rows)].copy()
    if k.R_std.shape[0] == k.u.shape[0]:  # per-sample noise replaces its row and column
        for a, j in enumerate(rows):
            sd = k.R_std[step, j]
            if np.isfinite(sd) and sd > 0:
                R[a, :] = 0.0
                R[:, a] = 0.0
                R[a, a] = sd * sd
    return y, H, R


def _update(model: Model, k: KernelInputs, x, P, uk, step: int, used: list[int], rows: np.ndarray):
    """The Joseph-form update with the groups ``used`` (outputs ``rows``): (x, P, y, NIS), or None
    when it fails (S not positive definite, a non-finite state or covariance)."""
    y, H, R = _innovation(model, k, x, uk, step, used, rows)
    S = H @ P @ H.T + R
    try:
        factor = cho_factor(S, lower=True)
        K = cho_solve(factor, H @ P).T
        x_new = model.boxplus(x, K @ y)
        IKH = np.eye(x.size) - K @ H
        P_new = IKH @ P @ IKH.T + K @ R @ K.T
        P_new = 0.5 * (P_new + P_new.T)
        ok: bool | np.bool_ = np.all(np.isfinite(x_new)) and np.all(np.isfinite(P_new))
    except (LinAlgError, ValueError):
        return None
    if not ok:
        return None
    return x_new, P_new, y, y @ cho_solve(factor, y)
