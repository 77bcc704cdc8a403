"""The shared EKF kernel re-run from a checkpoint over a slice of a loop's run, some groups excluded.

Re-filtering and roll-forward are the same kernel (`logscan.filters.ekf.run_ekf`) on the slice
[k1, k_stop] of the aligned run, started from the checkpoint (x0 = x_post[k1], P0 = P_post[k1])
with the shared run's own Q and R, and with fresh masks cleared:
 - at the slice's first step for every group: the checkpoint is already a posterior (the kernel
   does not predict at its step 0, and must not update a second time with the sample at k1);
 - throughout for the excluded groups (the flagged sensors); clearing every group is the pure
   roll-forward x_R = f(...f(x_k1, u)..., u) with P_R = F P_R F^T + Q.
The kernel's input convention is the recovery's: step k predicts x_k = f(x_{k-1}, u[k]), where u[k]
(the input held at step k) is the input applied over (t_{k-1}, t_k] - the specification's u_{k-1},
applied over [t_{k-1}, t_k). Using the same kernel makes the re-run agree with the shared EKF to
rounding when nothing is excluded (tests/test_recovery_engine.py).
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import replace

import numpy as np

from logscan.align import AlignedGroup, AlignedRun
from logscan.errors import InternalError
from logscan.filters.ekf import run_ekf
from logscan.recovery.records import LoopRun
from logscan.traces import EkfTrace


def _cut(value, sl: slice):
    return None if value is None else np.asarray(value)[sl]


def slice_group(group: AlignedGroup, sl: slice, excluded: bool) -> AlignedGroup:
    """The group on the slice's steps; no fresh sample at the slice's first step, none at all when
    ``excluded``."""
    fresh = np.array(group.fresh[sl], dtype=bool)
    if fresh.size:
        fresh[0] = False
    if excluded:
        fresh[:] = False
    return replace(
        group,
        z=np.asarray(group.z)[sl],
        fresh=fresh,
        channel_fresh=_cut(group.channel_fresh, sl),
        noise_std_series=_cut(group.noise_std_series, sl),
        gate_closed=_cut(group.gate_closed, sl),
    )


def slice_run(run: AlignedRun, start: int, stop: int, excluded: Collection[str]) -> AlignedRun:
    """Steps start..stop-1 of ``run`` (what the filter reads; on-board estimator and redundant
    channels are dropped), the ``excluded`` groups without fresh samples."""
    sl = slice(start, stop)
    return replace(
        run,
        t=np.asarray(run.t)[sl],
        u=np.asarray(run.u)[sl],
        u_fresh=np.asarray(run.u_fresh)[sl],
        groups={name: slice_group(g, sl, name in excluded) for name, g in run.groups.items()},
        mode=_cut(run.mode, sl),
        ground=_cut(run.ground, sl),
        onboard_state=None,
        onboard_variance=None,
        redundant={},
        gaps=[],
        warnings=[],
    )


def shared_R(trace: EkfTrace) -> dict[str, np.ndarray]:
    """Each group's block of the R the shared run used (profile overrides included)."""
    return {name: trace.R[trace.group_slice(name), trace.group_slice(name)] for name in trace.group_names}


def rerun(loop: LoopRun, k1: int, k_stop: int, excluded: Collection[str], store_gain: bool = False) -> EkfTrace:
    """The shared filter from the checkpoint at step k1 to step k_stop (inclusive) of ``loop``,
    without the ``excluded`` groups' samples; full P kept (the bound and the agreement test read
    it)."""
    tr = loop.trace
    part = slice_run(loop.run, k1, k_stop + 1, set(excluded))
    return run_ekf(
        loop.model,
        part,
        Q=tr.Q,
        R=shared_R(tr),
        x0=tr.x_post[k1],
        P0=tr.P_post[k1],
        full_P=True,
        store_gain=store_gain,
        store_S=False,
        store_innovations=False,
    )


def take_in_last(loop: LoopRun, k1: int, part: EkfTrace, J: int) -> tuple[np.ndarray, np.ndarray]:
    """(x (J, n), P (J, n, n)): the re-run's first J steps with the last one filtered again from the
    recovery's posterior one step before, every group's sample used: the sample that ended the
    anomaly no longer shows it, so the recovered estimate takes it in there, as an on-board
    estimator goes on from the recovered state (docs/algorithms.md section 5)."""
    tr, P_part = loop.trace, full_P(part)
    step = run_ekf(
        loop.model,
        slice_run(loop.run, k1 + J - 2, k1 + J, ()),
        Q=tr.Q,
        R=shared_R(tr),
        x0=part.x_post[J - 2],
        P0=P_part[J - 2],
        full_P=True,
        store_S=False,
        store_innovations=False,
    )
    x, P = part.x_post[:J].copy(), P_part[:J].copy()
    x[-1], P[-1] = step.x_post[1], full_P(step)[1]
    return x, P


def full_P(trace: EkfTrace) -> np.ndarray:
    """The trace's full covariance series (N, n, n); every re-run keeps it."""
    if trace.P_post is None:
        raise InternalError("a recovery re-run kept no full covariance")
    return trace.P_post


def replace_mask(gain_trace: EkfTrace, flagged: Collection[str]) -> np.ndarray:
    """(N, n) bool, the paper's element replacement mask G = (K g != 0): the states whose gain
    column of a flagged group is non-zero, held from that group's latest update (a multi-rate group
    has no gain between its samples; the paper's single-rate filter has one every step). False
    before the slice's first flagged update: no state used a flagged sample since the checkpoint."""
    N, n = gain_trace.x_post.shape
    mask = np.zeros((N, n), dtype=bool)
    for name in flagged:
        g = gain_trace.group_index(name)
        K = gain_trace.K[:, :, gain_trace.group_slice(name)]
        depends = np.any(np.nan_to_num(K) != 0.0, axis=2)  # (N, n)
        steps = np.arange(N)
        last = np.maximum.accumulate(np.where(gain_trace.updated[:, g], steps, -1))
        held = np.where((last >= 0)[:, None], depends[np.maximum(last, 0)], False)
        mask |= held
    return mask
