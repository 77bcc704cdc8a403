"""Alignment of a Log onto a profile's analysis grid: zero-order hold, staleness, fresh-sample masks.

INTERFACE (fixed; the implementation of `align` is being written): downstream code (filters,
detectors, simulator tests) relies only on the dataclasses below.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class AlignedGroup:
    """One measurement group on the grid.

    z:      (N, m) float64, zero-order held value of each channel within the staleness limit,
            NaN where no sample is recent enough (never zero-filled).
    fresh:  (N,) bool, True at grid steps where every channel of the group has a sample newer than
            the previous grid step and not older than the staleness limit (the filter updates then).
    """

    name: str
    channels: list[str]
    z: np.ndarray
    fresh: np.ndarray
    noise_std: np.ndarray | None = None  # (m,) from the profile, None: the model's default
    nonfinite_count: int = 0  # non-finite samples masked out before holding


@dataclass
class AlignedRun:
    """Everything a filter needs, on one uniform grid of N steps of period dt (seconds).

    t:        (N,) float64 seconds since the log's start_ns (grid point k is t0 + k*dt).
    u:        (N, nu) float64 model inputs held within their staleness limit (NaN where stale).
    u_fresh:  (N,) bool, every input channel valid at the step.
    groups:   measurement groups by name, in the profile's order.
    mode:     (N,) float64 mode / set-point channel, or None.
    onboard_state / onboard_variance: (N, n) held on-board estimator channels, or None.
    """

    t: np.ndarray
    dt: float
    start_ns: int
    u: np.ndarray
    u_fresh: np.ndarray
    input_channels: list[str]
    groups: dict[str, AlignedGroup]
    mode: np.ndarray | None = None
    onboard_state: np.ndarray | None = None
    onboard_variance: np.ndarray | None = None
    warnings: list[str] = field(default_factory=list)
    gaps: list[tuple[float, float, str]] = field(default_factory=list)  # (start s, end s, channel)

    @property
    def n_steps(self) -> int:
        return int(self.t.size)
