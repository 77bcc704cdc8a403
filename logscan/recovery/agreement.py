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
from scipy.special import chdtri

from logscan.filters.ekf import pack_run
from logscan.filters.trace import EkfTrace
from logscan.models.dispatch import call_literal
from logscan.recovery.kernels import group_predictions
from logscan.recovery.records import LoopRun
from logscan.recovery.rerun import shared_R, slice_run

AGREE, DISAGREE, NO_SAMPLE = 1, -1, 0


def group_nis(packed, g: int, part: EkfTrace, u: np.ndarray, fresh: np.ndarray) -> np.ndarray:
    """(N,) NIS of group g's fresh samples against the recovery's prior, NaN elsewhere, inf for an
    impossible sample (non-finite or outside the physical range)."""
    o, m = int(packed.group_offsets[g]), int(packed.group_sizes[g])
    cols = slice(o, o + m)
    z = packed.z[:, cols]
    nis = np.full(z.shape[0], np.nan)
    possible = np.all(np.isfinite(z) & (z >= packed.range_lo[cols]) & (z <= packed.range_hi[cols]), axis=1)
    nis[fresh & ~possible] = np.inf
    steps = np.flatnonzero(fresh & possible)
    hx, H = np.empty((steps.size, m)), np.empty((steps.size, m, part.x_prior.shape[1]))
    gid = np.int64(packed.group_ids[g])
    call_literal(group_predictions, packed.model_id, gid, packed.p, part.x_prior, u, steps, hx, H)
    # y = z - h(x_R) (angles wrapped to [-pi, pi));  S = H P_R H^T + R;  NIS = y^T S^-1 y
    y = z[steps] - hx
    wrap = packed.wrap[cols]
    y[:, wrap] = (y[:, wrap] + np.pi) % (2.0 * np.pi) - np.pi
    S = H @ part.P_prior[steps] @ np.swapaxes(H, 1, 2) + sample_R(packed, cols, steps)
    nis[steps] = np.einsum("ki,ki->k", y, np.linalg.solve(S, y[:, :, None])[:, :, 0])
    return nis


def sample_R(packed, cols: slice, steps: np.ndarray) -> np.ndarray:
    """(s, m, m) the group's R at each step: a per-sample noise std (a receiver's own accuracy)
    replaces its output's row and column, as in the EKF kernel."""
    R = np.repeat(packed.R_all[cols, cols][None], steps.size, axis=0)
    if packed.R_std.shape[0] != packed.z.shape[0]:
        return R
    sd = packed.R_std[steps][:, cols]
    for j in range(sd.shape[1]):  # loop over the group's outputs
        rows = np.isfinite(sd[:, j]) & (sd[:, j] > 0)
        R[rows, j, :] = 0.0
        R[rows, :, j] = 0.0
        R[rows, j, j] = sd[rows, j] ** 2
    return R


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
        fresh = packed.fresh[:, g].copy()
        fresh[0] = False  # the checkpoint's own sample was already used by the shared filter
        nis = group_nis(packed, g, part, u, fresh)
        limit = chdtri(int(packed.group_sizes[g]), 1.0 - quantile)  # chi2.ppf(quantile, m)
        sampled = ~np.isnan(nis)
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
