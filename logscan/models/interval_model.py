"""The interval linear model the UBIKF filters with (docs/algorithms.md section 2).

    x_{k+1} = [A] x_k + [B] u_k + w_k,   w ~ covariance in [Q]
    y_k     = [C] x_k + v_k,             v ~ covariance in [R]

Every interval matrix is midpoint and radius, [M] = M_m +- M_r with M_r >= 0 elementwise. The
measurement rows are the model's groups stacked in order (group g's rows are
``group_offsets[g] : group_offsets[g] + group_sizes[g]``), as in the EKF trace. A model that
supports the UBIKF provides ``interval_model(dt) -> IntervalModel`` (the discretised system on the
analysis grid); `logscan.filters.ubikf` runs on it.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from logscan.errors import ModelError


@dataclass(frozen=True)
class IntervalModel:
    """Discrete interval linear model: midpoints ``*_m`` and radii ``*_r`` (float64, radii >= 0)."""

    A_m: np.ndarray  # (n, n)
    A_r: np.ndarray
    B_m: np.ndarray  # (n, nu)
    B_r: np.ndarray
    C_m: np.ndarray  # (m, n), every group's rows stacked
    C_r: np.ndarray
    Q_m: np.ndarray  # (n, n) process noise covariance, midpoint and radius
    Q_r: np.ndarray
    R_m: np.ndarray  # (m, m) measurement noise covariance (block diagonal over groups)
    R_r: np.ndarray
    dt: float
    state_names: tuple[str, ...]
    group_names: tuple[str, ...]
    group_offsets: np.ndarray  # (G,) int
    group_sizes: np.ndarray  # (G,) int
    x0: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (n,) initial estimate (zeros if empty)
    P0: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # (n, n) initial bound

    @property
    def n(self) -> int:
        return int(self.A_m.shape[0])

    @property
    def m(self) -> int:
        return int(self.C_m.shape[0])

    def check(self) -> None:
        """ModelError naming what is wrong: shapes, finiteness, negative radii."""
        n, nu, m = self.A_m.shape[0], self.B_m.shape[1], self.C_m.shape[0]
        shapes = {
            "A": (n, n), "B": (n, nu), "C": (m, n), "Q": (n, n), "R": (m, m),
        }  # fmt: skip
        problems = []
        for name, shape in shapes.items():
            for part in ("m", "r"):
                value = getattr(self, f"{name}_{part}")
                if value.shape != shape:
                    problems.append(f"interval model: {name}_{part} has shape {value.shape}, expected {shape}")
                elif not np.isfinite(value).all():
                    problems.append(f"interval model: {name}_{part} has non-finite entries")
                elif part == "r" and (value < 0).any():
                    problems.append(f"interval model: {name}_r has negative radii")
        if problems:
            err = ModelError(problems[0] + (f" ({len(problems) - 1} more)" if len(problems) > 1 else ""))
            err.problems = problems
            raise err


def loewner_upper(M_m: np.ndarray, M_r: np.ndarray) -> np.ndarray:
    """A Loewner upper bound of every symmetric matrix in [M_m +- M_r]: M_m + diag(row sums of M_r)
    (for any |E| <= M_r, diag(rowsum M_r) - E is diagonally dominant, hence PSD). The elementwise
    upper ends are not an upper bound when off-diagonal entries are intervals."""
    return M_m + np.diag(np.asarray(M_r, dtype=np.float64).sum(axis=1))


# sampled check of the vertex enclosure: interior parameter sets drawn per derivation, and the
# margin by which the radius is widened when one of them leaves the vertex hull (non-monotone entry)
INTERIOR_SAMPLES = 256
NON_MONOTONE_MARGIN = 2.0


def enclose_over_box(
    evaluate: Callable[..., tuple[np.ndarray, ...]],
    box: dict[str, tuple[float, float]],
    seed: int = 0,
) -> tuple[list[tuple[np.ndarray, np.ndarray]], bool]:
    """Midpoint and radius of each matrix ``evaluate(**params)`` returns, over the parameter box
    ``box`` (name -> (lo, hi)); returns ([(mid, rad) per matrix], widened).

    The matrices are evaluated at the 2^p vertices of the box and the elementwise min/max taken
    (docs/algorithms.md section 2): an enclosure of every parameter set in the box when each entry
    is monotone in each parameter. That is then checked on INTERIOR_SAMPLES random parameter sets
    (seeded): where one leaves the vertex hull, that entry is not monotone, and its radius grows by
    (1 + NON_MONOTONE_MARGIN) times the largest distance a sample lay outside (the hull holding
    the samples, plus a margin for what the samples missed); ``widened`` is then True.
    """
    names = list(box)
    lo_hi = [box[k] for k in names]
    vertices = [evaluate(**dict(zip(names, corner))) for corner in itertools.product(*lo_hi)]
    lo = [np.min([v[i] for v in vertices], axis=0) for i in range(len(vertices[0]))]
    hi = [np.max([v[i] for v in vertices], axis=0) for i in range(len(vertices[0]))]
    rng = np.random.default_rng(seed)
    excess = [np.zeros_like(a) for a in lo]  # per entry: how far a sample left the vertex hull
    for _ in range(INTERIOR_SAMPLES if names else 0):
        mats = evaluate(**{k: rng.uniform(a, b) for k, (a, b) in zip(names, lo_hi)})
        for i, M in enumerate(mats):
            tol = 1e-12 * (np.abs(hi[i]) + np.abs(lo[i]))
            excess[i] = np.maximum(excess[i], np.maximum(M - hi[i] - tol, lo[i] - M - tol))
    widened = any(bool(np.any(e > 0.0)) for e in excess)
    result = []
    for a, b, e in zip(lo, hi, excess):
        e = np.maximum(e, 0.0)
        # a sample outside the hull: the hull grows to hold it, and the margin beyond
        result.append((0.5 * (a + b), 0.5 * (b - a) + (1.0 + NON_MONOTONE_MARGIN) * e))
    return result, widened
