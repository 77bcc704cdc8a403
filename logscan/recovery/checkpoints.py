"""Consistent checkpoints across loops and the choice of the checkpoint an anomaly rolls forward from.

A checkpoint is the shared EKF's (x_post, P_post) of every loop at one instant: consistent means the
same instant in every loop (the checkpointing paper's Definition 4.1). Loops at 10 Hz and 100 Hz
share the 10 Hz instants, so the candidate instants are the slowest loop's steps, each matched to
the nearest step of every other loop within a tolerance. Offline, storing them costs nothing: the
trace already holds every step, a checkpoint is just an index per loop.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from logscan.recovery.records import LoopRun


def loop_times(loops: Sequence[LoopRun]) -> list[np.ndarray]:
    """Each loop's grid times in the common frame (seconds since the first loop's start_ns)."""
    start = loops[0].run.start_ns
    return [np.asarray(lp.run.t, dtype=np.float64) + (lp.run.start_ns - start) * 1e-9 for lp in loops]


def slowest_period(loops: Sequence[LoopRun]) -> float:
    return max(float(lp.run.dt) for lp in loops)


@dataclass
class Checkpoints:
    """The consistent checkpoint instants: t (M,) and, per instant, the step of every loop (M, L)."""

    t: np.ndarray
    steps: np.ndarray
    loop_names: list[str]

    def step_of(self, index: int) -> dict[str, int]:
        return {name: int(self.steps[index, j]) for j, name in enumerate(self.loop_names)}


def nearest_steps(t_loop: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Index of the step of ``t_loop`` (sorted) nearest to each of ``times``."""
    right = np.clip(np.searchsorted(t_loop, times), 0, t_loop.size - 1)
    left = np.clip(right - 1, 0, t_loop.size - 1)
    return np.where(np.abs(t_loop[left] - times) <= np.abs(t_loop[right] - times), left, right)


def consistent_checkpoints(loops: Sequence[LoopRun], period_s: float, tol_s: float | None) -> Checkpoints:
    """The checkpoint ticks (every sample of the slowest loop, or its first sample of each period)
    that are consistent (every loop has a step within ``tol_s``) and usable (the checkpointed
    estimate is finite and the filter did not diverge there)."""
    times = loop_times(loops)
    slow = int(np.argmax([lp.run.dt for lp in loops]))
    tc = times[slow]
    tol = 0.5 * min(float(lp.run.dt) for lp in loops) if tol_s is None else float(tol_s)
    keep = np.ones(tc.size, dtype=bool)
    if period_s > 0 and tc.size:
        # the coordinator's tick: the first sample of each period (the paper's k % dt_c == 0)
        bucket = np.floor((tc - tc[0]) / period_s + 1e-9)
        keep[1:] = np.diff(bucket) > 0
    steps = np.empty((tc.size, len(loops)), dtype=np.int64)
    for j, (lp, t_loop) in enumerate(zip(loops, times)):
        if t_loop.size == 0:
            return Checkpoints(np.empty(0), np.empty((0, len(loops)), dtype=np.int64), [lp.name for lp in loops])
        near = nearest_steps(t_loop, tc)
        steps[:, j] = near
        keep &= np.abs(t_loop[near] - tc) <= tol
        keep &= usable_steps(lp)[near]
    return Checkpoints(tc[keep], steps[keep], [lp.name for lp in loops])


def usable_steps(loop: LoopRun) -> np.ndarray:
    """(N,) bool: steps whose (x_post, P_post) can seed a recovery."""
    tr = loop.trace
    finite_P = np.all(np.isfinite(tr.P_post.reshape(tr.P_post.shape[0], -1)), axis=1)
    return np.all(np.isfinite(tr.x_post), axis=1) & finite_P & ~np.asarray(tr.diverged, dtype=bool)


def select_checkpoint(
    cp: Checkpoints, t_detect: float, margin_s: float, blocked: Sequence[tuple[float, float]]
) -> int | None:
    """Index (into ``cp``) of the latest checkpoint k1 with t_detect - t_k1 > margin_s (detection
    time + the slowest loop's period) that lies in none of the ``blocked`` [lo, hi] intervals
    (earlier anomalies), else None."""
    ok = cp.t < t_detect - margin_s
    for lo, hi in blocked:
        ok &= ~((cp.t >= lo) & (cp.t <= hi))
    found = np.flatnonzero(ok)
    return int(found[-1]) if found.size else None
