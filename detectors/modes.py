"""Runs of one mode value on a grid: where the profile's mode (or set-point) channel changes, and
the segments between changes, which the mode-aware detectors (A-TFM's training, KGN's steady gate)
work on."""

from __future__ import annotations

import numpy as np


def mode_changes(mode: np.ndarray) -> np.ndarray:
    """(N,) bool: True where a new run of one mode value starts (always at 0; NaN runs count as one
    value; values are compared to 1e-6)."""
    key = np.round(mode, 6)
    change = np.ones(mode.size, dtype=bool)
    change[1:] = ~((key[1:] == key[:-1]) | (np.isnan(key[1:]) & np.isnan(key[:-1])))
    return change


def mode_segments(mode: np.ndarray, settle: int) -> list[tuple[float, int, int]]:
    """(mode value, first, stop) of each run of one mode value, its first ``settle`` samples dropped
    (the vehicle is still reaching the new speed); runs of NaN mode are skipped."""
    if mode.size == 0:
        return []
    key = np.round(mode, 6)
    change = np.flatnonzero(mode_changes(mode)[1:]) + 1
    starts = np.concatenate(([0], change))
    stops = np.concatenate((change, [mode.size]))
    return [
        (float(key[a]), int(a + settle), int(b))
        for a, b in zip(starts, stops)
        if np.isfinite(key[a]) and b - a > settle
    ]
