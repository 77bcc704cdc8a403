"""Rest the wheels claim and the other sensors deny: the frozen check's stillness, cross-examined.

Specified in docs/algorithms.md section 1f ("Rest the other sensors deny"). A ground robot's wheel
speed says when it stands (`Model.at_rest`); the frozen check then leaves still sensors, and the
wheel speed's own exact repeats, unjudged. A wheel speed stuck at exactly 0 while the robot drives
claims rest for as long as it is stuck, so nothing judged it, and the GNSS that kept moving was
blamed. Two sensors that do not read the wheels can deny the claim, per stretch of claimed rest:

- the IMU (`Model.motion_inputs`, the gyro's yaw rate): a standing robot's gyro shows its own noise,
  a driving one the shaking of the ground too. The mean square of the stretch's successive
  differences against the same over every window of its length of the log's driving (where the
  wheels say it moves; the scatter of driving is far from Gaussian, so its own windows are the
  reference): below their ``alpha`` quantile, the stretch is quieter than the log's driving: rest
  confirmed.
- the position sensor (`Model.motion_group`, the GNSS): its displacement from the stretch's first
  sample to its last, against what its noise and wander allow a standing receiver over that time
  (`Model.rest_position_var`): a chi-square test with one degree per axis; above its upper
  ``alpha`` point, it moved.

Only when both deny the rest is the stretch taken as motion: one of them alone can be a robot
whose gyro shakes at idle (an engine) or a GNSS that jumps while the robot stands, and the frozen
check would then call every stop of that robot stuck. ``alpha`` spends the check's false-alarm
budget over the log's stretches of rest (``budget_per_hour / stretches per hour``).
"""

from __future__ import annotations

import numpy as np
from scipy.special import chdtri  # not scipy.stats (46 MB to import)

from logscan.alarms import true_runs


def denied_rest(run, model, rest: np.ndarray | None, budget_per_hour: float) -> np.ndarray | None:
    """(N,) bool: the steps of the stretches of ``rest`` that both witnesses say were motion (module
    docstring); None when the model names no witnesses or nothing is at rest."""
    inputs = tuple(getattr(model, "motion_inputs", ()))
    group = run.groups.get(getattr(model, "motion_group", None) or "") if hasattr(run, "groups") else None
    u = getattr(run, "u", None)
    if rest is None or not inputs or group is None or group.z is None or u is None or not rest.any():
        return None
    rest = np.asarray(rest, dtype=bool)
    firsts, stops = true_runs(rest)
    duration_h = max(float(run.t[-1] - run.t[0]), 1e-9) / 3600.0
    alpha = min(0.5, float(budget_per_hour) * duration_h / firsts.size)
    denied = np.zeros(rest.size, dtype=bool)
    references = [_Driving(u[:, k], rest, alpha) for k in inputs]
    for first, stop in zip(firsts, stops):  # per stretch of rest: a wheel speed near its bound flickers
        shaken = all(ref.shaken(u[first:stop, k]) for k, ref in zip(inputs, references))
        if shaken and _moved(run.t, group, first, stop, model, alpha):
            denied[first:stop] = True
    return denied


class _Driving:
    """A witness input's squared successive differences where the wheels say the vehicle moves (the
    log's own driving, its rest stretches left out), as running sums; the ``alpha`` quantile of
    the means of its windows of one length is computed once per length: a wheel speed that hovers
    at the rest bound makes thousands of short stretches, of few distinct lengths."""

    def __init__(self, column: np.ndarray, rest: np.ndarray, alpha: float) -> None:
        d = np.diff(column)
        moving = ~(rest[1:] | rest[:-1]) & np.isfinite(d)
        self.sums = np.cumsum(np.concatenate(([0.0], d[moving] ** 2)))
        self.alpha = alpha
        self.quantiles: dict[int, float] = {}

    def shaken(self, stretch: np.ndarray) -> bool:
        """Whether a stretch of the input shakes as the log's driving does: its mean square
        difference is at least the ``alpha`` quantile of the driving's windows of its length (False
        when the driving holds no such window)."""
        d = np.diff(stretch)
        d = d[np.isfinite(d)]
        n = d.size
        if n < 1 or self.sums.size - 1 < n:
            return False
        if n not in self.quantiles:
            windows = (self.sums[n:] - self.sums[:-n]) / n
            self.quantiles[n] = float(np.quantile(windows, self.alpha))
        return float(np.mean(d**2)) >= self.quantiles[n]


def _moved(t: np.ndarray, group, first: int, stop: int, model, alpha: float) -> bool:
    """Whether the position sensor's displacement over a stretch is more than its noise and wander
    allow a standing receiver."""
    fresh = group.fresh[first:stop] & np.isfinite(group.z[first:stop]).all(axis=1)
    steps = first + np.flatnonzero(fresh)
    if steps.size < 2:
        return False
    a, b = steps[0], steps[-1]
    spec = model.groups.get(group.name)
    noise = np.asarray(group.noise_std if group.noise_std is not None else spec.noise_std, dtype=np.float64)
    variance = 2.0 * noise**2 + model.rest_position_var(float(t[b] - t[a]))
    shift = group.z[b] - group.z[a]
    return float(np.sum(shift**2 / variance)) > chdtri(shift.size, alpha)
