"""What the report draws of the UBIKF's covariance bound: trace(P+) against the point filter's
trace(P) on the same log (docs/algorithms.md section 2.1). The bound is above the point filter's
covariance wherever the model has interval uncertainty in A or C; equal when it has none.

On a simulated log, also its envelopes per state (`EnvelopeView`), which the report sets against
the true state the log carries (`logscan.report.ubikf_truth_view`)."""

from __future__ import annotations

import dataclasses
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


@dataclasses.dataclass(repr=False, eq=False)  # arrays: a field-wise == would be ambiguous
class EnvelopeView:
    """The UBIKF's estimate and envelopes per grid step (N,) and state (n,): the mid-model estimate
    x_mid, the hull [x_lo, x_hi] of its zonotope and diag(P+_post). The trace's own arrays, not
    copies; in the JSON summary it is one line (its ``str``), not the arrays."""

    t: np.ndarray  # (N,)
    state_names: tuple[str, ...]
    x_mid: np.ndarray  # (N, n)
    x_lo: np.ndarray  # (N, n)
    x_hi: np.ndarray  # (N, n)
    P_diag: np.ndarray  # (N, n) float32
    valid: np.ndarray  # (N,) bool: the UBIKF did not restart at that step

    def __str__(self) -> str:
        return (
            f"{self.t.size} steps x {len(self.state_names)} states of the UBIKF's estimate, hull and P+ "
            "(drawn against the true state in the report)"
        )

    __repr__ = __str__
