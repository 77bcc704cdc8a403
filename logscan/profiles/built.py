"""What every built-in profile builder shares: the built profile, rates, TOML lists."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class BuiltProfile:
    """A built-in profile: its name, TOML text (commented, to edit) and what was left out."""

    name: str
    text: str
    notes: list[str] = field(default_factory=list)
    # why the profile's model cannot run on this log ("": it can): only the detectors that need no
    # filter run (health, PX4's own estimator tests), and the model is a `not checked` line
    model_not_run: str = ""


def rate_hz(t_ns: np.ndarray) -> float:
    """A channel's sample rate: 1 / the median interval between its samples (0 for fewer than 2)."""
    t = np.unique(np.asarray(t_ns, dtype=np.int64))
    if t.size < 2:
        return 0.0
    return float(1e9 / np.median(np.diff(t)))


def nice_rate(hz: float) -> float:
    """A grid rate near ``hz``: whole hertz (PX4 logs its IMU at 200, 250, ... Hz)."""
    return float(max(1, round(hz)))


def toml_list(items) -> str:
    return "[" + ", ".join(f'"{x}"' for x in items) + "]"
