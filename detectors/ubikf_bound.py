"""What the report draws of the UBIKF's covariance bound: trace(P+) against the point filter's
trace(P) on the same log (docs/algorithms.md section 2.1). The bound is above the point filter's
covariance wherever the model has interval uncertainty in A or C; equal when it has none."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class BoundView(NamedTuple):
    """trace(P+_post) of the UBIKF and trace(P_post) of the point EKF, per grid step (N,)."""

    t: np.ndarray
    bound: np.ndarray
    point: np.ndarray
    valid: np.ndarray  # bool: the UBIKF did not restart at that step

    def ratio(self) -> np.ndarray:
        """trace(P+) / trace(P) per step, NaN where either is not finite or the point one is 0."""
        with np.errstate(divide="ignore", invalid="ignore"):
            r = self.bound / self.point
        return np.where(self.valid & np.isfinite(r) & (self.point > 0), r, np.nan)

    def settled_ratio(self) -> float:
        """The median ratio over the second half of the log (NaN when none is finite)."""
        r = self.ratio()[self.t.size // 2 :]
        r = r[np.isfinite(r)]
        return float(np.median(r)) if r.size else float("nan")
