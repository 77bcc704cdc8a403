"""Keeping the alarm: the flagged sensors tested against the recovered prediction, and the end of an
anomaly when they agree again for a hold time.

A detector on the shared EKF's innovations loses the anomaly once the EKF has absorbed the bias; the
recovered estimate has not absorbed it (the flagged groups are excluded), so each flagged group's
fresh sample is tested against the recovery's prior (x_R, P_R):
    y = z - h(x_R),   S = H P_R H^T + R_g,   NIS = y^T S^-1 y   (chi-square with m_g dof)
and agrees when NIS <= the chi-square quantile. A sample outside the group's physical range (or
non-finite) disagrees.
"""

from __future__ import annotations

from collections.abc import Collection

import numpy as np
from numba import njit
from scipy.stats import chi2

from logscan.filters.ekf import pack_run
from logscan.filters.trace import EkfTrace
from logscan.models.dispatch import H_meas, h_meas
from logscan.numba_cache import follow_dependencies
from logscan.recovery.records import LoopRun
from logscan.recovery.rerun import shared_R, slice_run

AGREE, DISAGREE, NO_SAMPLE = 1, -1, 0


@njit(cache=True)
def group_nis(model_id, gid, p, x_prior, P_prior, u, z, fresh, R, lo, hi, wrap, nis):
    """NIS of one group's fresh samples against a prior; inf for an impossible sample.

    x_prior (N, n), P_prior (N, n, n), u (N, nu) finite, z (N, m), fresh (N,), R (m, m),
    lo/hi (m,) physical range, wrap (m,) angular outputs; nis (N,) NaN-filled by the caller."""
    N = x_prior.shape[0]
    m = z.shape[1]
    for k in range(N):
        if not fresh[k]:
            continue
        ok = True
        for j in range(m):
            if not (np.isfinite(z[k, j]) and z[k, j] >= lo[j] and z[k, j] <= hi[j]):
                ok = False
        if not ok:
            nis[k] = np.inf
            continue
        x = x_prior[k]
        hx = h_meas(model_id, gid, p, x, u[k])
        H = H_meas(model_id, gid, p, x, u[k])
        # y = z - h(x_R), angles wrapped to [-pi, pi)
        y = z[k] - hx
        for j in range(m):
            if wrap[j]:
                y[j] = (y[j] + np.pi) % (2.0 * np.pi) - np.pi
        # S = H P_R H^T + R;  NIS = y^T S^-1 y (solve, no inverse)
        S = H @ P_prior[k] @ H.T + R
        nis[k] = np.dot(y, np.linalg.solve(S, y))


def held_inputs(u: np.ndarray) -> np.ndarray:
    """Inputs with each non-finite row replaced by the last finite one (as the EKF kernel holds them),
    zeros before the first finite row."""
    finite = np.all(np.isfinite(u), axis=1)
    last = np.maximum.accumulate(np.where(finite, np.arange(u.shape[0]), -1))
    held = u[np.maximum(last, 0)].copy()
    held[last < 0] = 0.0
    return held


def agreement_status(loop: LoopRun, k1: int, part: EkfTrace, flagged: Collection[str], quantile: float) -> np.ndarray:
    """(len(part),) int8 over the slice starting at k1: AGREE where every flagged group with a fresh
    sample agrees with the recovery's prior, DISAGREE where one does not, NO_SAMPLE elsewhere."""
    N = part.n_steps
    sliced = slice_run(loop.run, k1, k1 + N, ())
    packed = pack_run(loop.model, sliced, Q=loop.trace.Q, R=shared_R(loop.trace), x0=part.x_post[0])
    u = held_inputs(packed.u)
    status = np.full(N, NO_SAMPLE, dtype=np.int8)
    for name in flagged:
        g = packed.group_names.index(name)
        cols = slice(int(packed.group_offsets[g]), int(packed.group_offsets[g] + packed.group_sizes[g]))
        nis = np.full(N, np.nan)
        fresh = packed.fresh[:, g].copy()
        fresh[0] = False  # the checkpoint's own sample was already used by the shared filter
        z = np.ascontiguousarray(packed.z[:, cols])
        R = np.ascontiguousarray(packed.R_all[cols, cols])
        group_nis(
            packed.model_id, packed.group_ids[g], packed.p, part.x_prior, part.P_prior, u, z, fresh, R,
            packed.range_lo[cols], packed.range_hi[cols], packed.wrap[cols], nis,
        )  # fmt: skip
        limit = chi2.ppf(quantile, int(packed.group_sizes[g]))
        sampled = np.isfinite(nis) | np.isinf(nis)
        status[sampled & (nis <= limit) & (status != DISAGREE)] = AGREE
        status[sampled & ~(nis <= limit)] = DISAGREE
    return status


def agreed_at(t: np.ndarray, status: np.ndarray, t_from: float, hold_s: float) -> float | None:
    """The first time >= t_from of an agreeing sample after which no sample disagrees for hold_s
    (the hold must fit in ``t``), else None."""
    cand = np.flatnonzero((status == AGREE) & (t >= t_from))
    if cand.size == 0:
        return None
    dis = np.flatnonzero(status == DISAGREE)
    nxt = np.searchsorted(dis, cand, side="right")
    t_next = np.append(t[dis], np.inf)[nxt]  # the next disagreeing sample's time (inf: none)
    ok = (t_next > t[cand] + hold_s) & (t[cand] + hold_s <= t[-1] + 1e-9)
    found = np.flatnonzero(ok)
    return float(t[cand[found[0]]]) if found.size else None


follow_dependencies(__name__)
