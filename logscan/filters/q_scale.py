"""The filter's Q scaled per state: Q' = D^1/2 Q D^1/2 with D = diag(scale), and a model's Q with
the per-state scales that `logscan train --calibrate` fitted (`logscan.training.process_noise`, whose
docstring says why this form: a congruence keeps Q symmetric positive semi-definite).

It lives in the filters layer so that `logscan.filters.ekf` applies a model's calibrated Q without
importing the calibration; `logscan.training.process_noise` uses it to try its scales.
"""

from __future__ import annotations

import numpy as np


def scaled_Q(Q: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Q' = D^1/2 Q D^1/2, D = diag(scale) (see `logscan.training.process_noise`'s docstring)."""
    root = np.sqrt(np.asarray(scale, dtype=np.float64))
    return root[:, None] * np.asarray(Q, dtype=np.float64) * root[None, :]


def scale_vector(model, scales: dict[str, float] | None) -> np.ndarray:
    """One scale per state from {state name: scale} (a state not named: 1)."""
    scales = scales or {}
    return np.array([float(scales.get(name, 1.0)) for name in model.state_names])


def calibrated_Q(model, dt: float) -> np.ndarray | None:
    """The model's Q at ``dt`` scaled by its ``process_noise_scale`` ({state: scale}, set from the
    tables' calibration by `logscan.pipeline.preparation`), or None (the filter's default Q)."""
    scales = getattr(model, "process_noise_scale", None)
    if not scales:
        return None
    return scaled_Q(model.default_Q(dt), scale_vector(model, scales))
