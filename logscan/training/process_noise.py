"""The process noise Q that `logscan train --calibrate` fits: blocks of like states, Q scaled per
block, the innovations' likelihood it is fitted on, and one fitting step (`logscan.training.calibration`).

Q keeps the model's structure: a scale s_i per state (one per block of like states) gives
Q' = D^1/2 Q D^1/2 with D = diag(s), so a state's variance is multiplied by its block's scale and a
covariance between two states (position and velocity driven by one accelerometer noise) by the
geometric mean of theirs; a congruence, Q' is symmetric positive semi-definite whenever Q is.

Why a likelihood and not covariance matching (Mohamed & Schwarz, "Adaptive Kalman filtering for
INS/GPS"; Myers & Tapley): covariance matching compares each state's corrections K y with their
predicted covariance K S K^T. When the innovations' level is right (mean NIS 1) the two agree in
expectation whatever the split of S between H P H^T and R (for a directly measured random walk
E[K y y^T K^T] = K S K^T exactly when NIS is 1), so alternated with the R scaling it stops
anywhere on that line: on simulated quadcopter logs whose Q was 10x too large it ended with the
gyro's R at 0.2x the truth and its Q at 2.5x; and a state's mismatch is often another block's Q
propagated by F (the quadcopter's attitude, driven by the rate block's Q, came out negative).
What separates Q from R is the innovations' time structure: a filter whose Q is too large has a
gain too large and innovations larger than the optimal predictor's, and the innovation form of
the Gaussian likelihood, -2 log L = sum_k (log det S_k + y_k^T S_k^-1 y_k), is least at the
true noise (the prediction-error decomposition); the same simulated logs give every block's
minimum at the simulated Q (and on `ins` logs, whose NIS barely moves with Q, too).

The level of S is left to the R scaling (mean NIS per output 1): the cost of a Q scale is taken
with each group's S scaled by its mean y^2 / S (the likelihood concentrated over that level,
`_concentrated_cost`), so what decides Q is the innovations' time structure. With the plain cost
the alternation crept along the NIS-is-1 line (the quadcopter's gyro R still 0.7x the truth after
five iterations); concentrated, Q 10x and 0.1x too large came back to 0.09-0.13x and 8-13x with
every R within 1 % of the truth. A group whose R the calibration has scaled down to its floor
cannot set its level any more (its S is mostly H P H^T): its cost is the plain one, so Q sets it
(on a SITL log, whose GNSS is far quieter than any R a profile guesses, the concentrated cost
drove the velocity Q up 7,700x while the position NIS sat at 0.001).

Simplified: the cost is the composite likelihood of each output on its own (log S_jj +
y_j^2 / S_jj from the trace's diagonal of S, summed over outputs and updates), not the joint one
of the stacked S: the trace keeps only diag(S) per step (the full S of a 1-hour log is hundreds of
MB). Each output's marginal density is the right one at the true noise, so the composite score is
still zero there. Each block's scale is fitted by one parabolic step in log scale per iteration
(three filter passes over the training logs), one block after the other; the scales are one per
block for all the logs (a Q that changes during a flight is not followed).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from logscan.filters.ekf import run_ekf
from logscan.filters.q_scale import scaled_Q

Q_SCALE_MIN = 1e-4  # the smallest scale of a block's Q
Q_SCALE_MAX = 1e4
Q_STEP = math.log(2.0)  # the step of a block's log scale where the cost is sampled (x2, /2)
Q_MAX_MOVE = 3 * Q_STEP  # the largest move in one iteration (x8)
# a block whose cost changes less than this at x2 and /2 is not identifiable from the logs
# (-2 log L units: a likelihood ratio of e, the 84 % point of a chi-square with 1 degree of freedom)
Q_FLAT = 2.0

# the three axes of one quantity: alone (x), as a one-letter stem's suffix (vx) or after "_" (v_north)
AXES = {
    ("x", "y", "z"): "position",
    ("north", "east", "down"): "position",
    ("roll", "pitch", "yaw"): "attitude",
    ("p", "q", "r"): "body_rate",
}
STEMS = {"v": "velocity"}


def _axis_stem(name: str, axes: tuple[str, ...]) -> str | None:
    """The stem of ``name`` as one of ``axes`` ("" for the axis alone), else None."""
    for axis in axes:
        if name == axis:
            return ""
        if name.endswith("_" + axis):
            return name[: -len(axis) - 1]
        if len(name) == len(axis) + 1 and name.endswith(axis):
            return name[:1]
    return None


def state_blocks(model) -> dict[str, list[int]]:
    """The model's states in blocks of like physical meaning: the three axes of one quantity
    (`AXES`: x/y/z, north/east/down, roll/pitch/yaw, p/q/r, alone or after a stem: vx, v_north,
    gyro_bias_x) form one block named after the quantity; every other state is a block of its own.
    For `ins`: position, velocity, attitude, gyro_bias, accel_bias, baro_offset."""
    names = list(model.state_names)
    found: dict[tuple[str, tuple[str, ...]], list[int]] = {}
    for i, name in enumerate(names):
        for axes in AXES:
            stem = _axis_stem(name, axes)
            if stem is not None:
                found.setdefault((stem, axes), []).append(i)
                break
    blocks: dict[str, list[int]] = {}
    grouped: set[int] = set()
    for (stem, axes), states in found.items():
        if len(states) != len(axes):  # not all three axes: not one quantity
            continue
        label = STEMS.get(stem, stem) or AXES[axes]
        blocks[label if label not in blocks else f"{label}_{states[0]}"] = states
        grouped.update(states)
    for i, name in enumerate(names):
        if i not in grouped:
            blocks[name if name not in blocks else f"{name}_{i}"] = [i]
    return dict(sorted(blocks.items(), key=lambda item: item[1][0]))


@dataclass
class Evaluation:
    """One filter pass over the training logs: each group's (mean NIS per output, updates) and the
    innovations' cost (-2 log L, composite, each group's level of S taken out: `_concentrated_cost`)
    over ``samples`` outputs."""

    nis: dict[str, tuple[float, int]]
    cost: float
    samples: int


def evaluate(
    model,
    runs: Sequence,
    noise_std: dict[str, np.ndarray],
    scale: np.ndarray,
    judged: Sequence | None = None,
    floored: frozenset[str] = frozenset(),
) -> Evaluation:
    """Filter ``runs`` with R from ``noise_std`` and Q scaled by ``scale`` (one per state); the
    NIS and the likelihood over each run's ``judged`` steps ((N,) bool, None: all of them), the
    ``floored`` groups' at their own level (`_concentrated_cost`)."""
    sums: dict[str, float] = {}
    counts: dict[str, int] = {}
    terms: dict[str, np.ndarray] = {}  # per group: sum of log S_jj, of y_j^2 / S_jj, outputs
    for r, run in enumerate(runs):
        Q = scaled_Q(model.default_Q(run.dt), scale)
        trace = run_ekf(model, run, Q=Q, R=noise_std, store_gain=False, store_S=False, store_innovations=True)
        steps = judged[r] if judged is not None and judged[r] is not None else slice(None)
        for g, name in enumerate(trace.group_names):
            nis = trace.nis_group[steps, g]
            used = trace.updated[steps, g] & np.isfinite(nis)
            sums[name] = sums.get(name, 0.0) + float(nis[used].sum())
            counts[name] = counts.get(name, 0) + int(used.sum())
        for name, offset, size in zip(trace.group_names, trace.group_offsets.tolist(), trace.group_sizes.tolist()):
            y = trace.y[steps, offset : offset + size].astype(np.float64)
            S = trace.S_diag[steps, offset : offset + size].astype(np.float64)
            ok = np.isfinite(y) & np.isfinite(S) & (S > 0)
            parts = terms.setdefault(name, np.zeros(3))
            parts += (float(np.log(S[ok]).sum()), float((y[ok] ** 2 / S[ok]).sum()), float(ok.sum()))
    sizes = {name: model.group(name).size for name in sums}
    nis = {name: (sums[name] / (sizes[name] * counts[name]) if counts[name] else np.nan, counts[name]) for name in sums}
    cost = _concentrated_cost(terms, floored)
    return Evaluation(nis=nis, cost=cost, samples=int(sum(t[2] for t in terms.values())))


def _concentrated_cost(terms: dict[str, np.ndarray], floored: frozenset[str] = frozenset()) -> float:
    """-2 log L of each output on its own, log S_jj + y_j^2 / S_jj summed (constants dropped), with
    each group's S scaled by c_g = mean(y_j^2 / S_jj), the c_g that makes it least:
    sum log S_jj + n_g log c_g + n_g per group. The level of S is the R scaling's to set (mean NIS
    per output 1); with it taken out, the cost of a Q scale is what the innovations' time structure
    says, not how wide S is, and R and Q do not trade along the line where NIS is 1."""
    cost = 0.0
    for name, (log_S, nis, n) in terms.items():
        if name in floored:  # its R can go no lower: the level is Q's to set, plain -2 log L
            cost += log_S + nis
        elif n > 0 and nis > 0:  # nis = 0: innovations all zero, a group that says nothing
            cost += log_S + n * np.log(nis / n) + n
    return float(cost)


@dataclass
class BlockFit:
    """A block's fit so far: its log scale and whether the logs have ever told its Q apart."""

    states: list[int]
    log_scale: float = 0.0
    identified: bool = False


def fit_blocks(
    model,
    runs,
    noise_std,
    blocks: dict[str, BlockFit],
    current: Evaluation,
    judged: Sequence | None = None,
    floored: frozenset[str] = frozenset(),
) -> tuple[Evaluation, float]:
    """One step of every block's log scale (in order, each from the others' latest): the cost at
    the current scale, x2 and /2, the least of a parabola through them (at most `Q_MAX_MOVE`
    away), and the best of the points tried. A block whose cost barely changes (`Q_FLAT`) keeps
    its scale. Returns the evaluation at the new scales and the largest move (log scale)."""
    lo, hi = math.log(Q_SCALE_MIN), math.log(Q_SCALE_MAX)

    def scale_with(name: str, log_scale: float) -> np.ndarray:
        scale = np.ones(model.n_states)
        for other, fit in blocks.items():
            scale[fit.states] = math.exp(log_scale if other == name else fit.log_scale)
        return scale

    largest = 0.0
    for name, fit in blocks.items():
        at = fit.log_scale
        tried = {at: current}
        for point in (max(lo, at - Q_STEP), min(hi, at + Q_STEP)):
            tried[point] = evaluate(model, runs, noise_std, scale_with(name, point), judged, floored)
        down, up = tried[max(lo, at - Q_STEP)].cost, tried[min(hi, at + Q_STEP)].cost
        if max(abs(down - current.cost), abs(up - current.cost)) < Q_FLAT:
            continue
        fit.identified = True
        # the parabola through (-h, down), (0, J0), (h, up): its least at -h (up - down) / (2 curvature)
        curvature = up + down - 2.0 * current.cost
        move = Q_MAX_MOVE * np.sign(down - up) if curvature <= 0 else -Q_STEP * (up - down) / (2.0 * curvature)
        point = float(np.clip(at + np.clip(move, -Q_MAX_MOVE, Q_MAX_MOVE), lo, hi))
        if point not in tried:
            tried[point] = evaluate(model, runs, noise_std, scale_with(name, point), judged, floored)
        best = min(tried, key=lambda p: tried[p].cost)
        largest = max(largest, abs(best - at))
        fit.log_scale, current = best, tried[best]
    return current, largest
