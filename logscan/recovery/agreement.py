"""Keeping the alarm: the flagged sensors tested against the recovered prediction, and the end of an
anomaly when they agree again for a hold time.

A detector on the shared EKF's innovations loses the anomaly once the EKF has absorbed the bias; the
recovered estimate has not absorbed it (the flagged groups are excluded), so each flagged group's
fresh sample is tested against the recovery's prior (x_R, P_R):
    y = z - h(x_R),   S = H P_R H^T + R_g,   NIS = y^T S^-1 y   (chi-square with m_g dof)
and agrees when NIS <= the chi-square quantile. A sample outside the group's physical range (or
non-finite) disagrees. A disagreeing sample whose NIS also exceeds chi2.ppf(1 - alpha, m_g), alpha
the false-alarm budget's per-sample probability (`keep_alpha`), *shows the anomaly* (SHOWN): after
the alarms last showed the anomaly only such a sample keeps a recovery open (`released_at`): one that
disagrees without showing it ends the recovery (the recovered estimate did not re-agree), and so does
one that agrees unless the anomaly shows again within hold_s.
"""

from __future__ import annotations

from collections.abc import Collection

import numpy as np
from scipy.special import chdtri

from logscan.detectors.budget import design_rate
from logscan.filters.ekf import pack_run
from logscan.models.dispatch import call_literal
from logscan.recovery.kernels import group_predictions
from logscan.recovery.records import LoopRun
from logscan.recovery.rerun import shared_R, slice_run
from logscan.traces import EkfTrace

AGREE, DISAGREE, NO_SAMPLE, SHOWN = 1, -1, 0, -2  # SHOWN: disagrees beyond the budget's bound too


def keep_alpha(budget_per_hour: float, proof_hours: float, samples_per_s: float) -> float:
    """The per-sample probability that a consistent recovered estimate and an honest sensor sampled
    ``samples_per_s`` times a second show an anomaly: the false-alarm budget's design rate (as `nis`
    designs for, `logscan.detectors.budget.design_rate`) over the samples of an hour."""
    return design_rate(budget_per_hour, proof_hours) / (3600.0 * max(samples_per_s, 1e-9))


def sample_rate(fresh: np.ndarray, t: np.ndarray) -> float:
    """Fresh samples per second over ``t`` (at least one sample over the span)."""
    span = float(t[-1] - t[0]) if t.size > 1 else 0.0
    return max(int(np.count_nonzero(fresh)), 1) / span if span > 0 else 1.0


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


def agreement_status(
    loop: LoopRun,
    k1: int,
    part: EkfTrace,
    flagged: Collection[str],
    quantile: float,
    budget: tuple[float, float] | None = None,
) -> np.ndarray:
    """(len(part),) int8 over the slice starting at k1: AGREE where every flagged group with a fresh
    sample agrees with the recovery's prior, DISAGREE where one does not, NO_SAMPLE elsewhere; with
    ``budget`` = (budget_per_hour, proof_hours), SHOWN where one shows the anomaly (its NIS beyond the
    chi-square quantile of `keep_alpha` at the group's own rate over the whole run, `keep_bound`)."""
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
        status[sampled & (nis <= limit) & (status == NO_SAMPLE)] = AGREE
        status[sampled & ~(nis <= limit) & (status != SHOWN)] = DISAGREE
        if budget is not None:
            status[sampled & ~(nis <= keep_bound(loop, name, budget))] = SHOWN
    return status


def keep_bound(loop: LoopRun, group: str, budget: tuple[float, float]) -> float:
    """chi2.ppf(1 - keep_alpha, m_g): the NIS beyond which a sample of ``group`` shows the anomaly,
    at the group's own sample rate over the loop's whole run."""
    grp = loop.run.groups[group]
    rate = sample_rate(np.asarray(grp.fresh), np.asarray(loop.run.t))
    return float(chdtri(int(np.asarray(grp.z).shape[1]), keep_alpha(budget[0], budget[1], rate)))


def agreed_at(t: np.ndarray, status: np.ndarray, t_from: float, hold_s: float) -> float | None:
    """The first time >= t_from of an agreeing sample after which no sample disagrees (DISAGREE or
    SHOWN) for hold_s (the hold must fit in ``t``), else None."""
    cand = np.flatnonzero((status == AGREE) & (t >= t_from))
    if cand.size == 0:
        return None
    dis = np.flatnonzero(status < NO_SAMPLE)
    nxt = np.searchsorted(dis, cand, side="right")
    t_next = np.append(t[dis], np.inf)[nxt]  # the next disagreeing sample's time (inf: none)
    ok = (t_next > t[cand] + hold_s) & (t[cand] + hold_s <= t[-1] + 1e-9)
    found = np.flatnonzero(ok)
    return float(t[cand[found[0]]]) if found.size else None


def released_at(t: np.ndarray, status: np.ndarray, t_from: float, hold_s: float) -> tuple[float, bool] | None:
    """After the alarms last showed the anomaly (from ``t_from``), the first sample that ends the
    recovery, as (time, agreed): a sample that disagrees without showing the anomaly (DISAGREE: the
    recovered estimate did not re-agree), or one that agrees with no sample showing the anomaly
    (SHOWN) over the next hold_s; ``agreed``: it agrees and none disagrees over that hold. None if
    neither occurs."""
    later = t >= t_from
    dis = np.flatnonzero((status == DISAGREE) & later)
    cand = np.flatnonzero((status == AGREE) & later)
    shown = np.flatnonzero(status == SHOWN)
    t_shown = np.append(t[shown], np.inf)[np.searchsorted(shown, cand, side="right")]  # the next SHOWN
    held = cand[t_shown > t[cand] + hold_s]
    ends = [int(k[0]) for k in (dis, held) if k.size]
    if not ends:
        return None
    k = min(ends)
    if status[k] == DISAGREE:
        return float(t[k]), False
    return float(t[k]), not bool(dis.size and t[dis[np.searchsorted(dis, k)]] <= t[k] + hold_s)
