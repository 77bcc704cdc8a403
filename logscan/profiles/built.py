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
    """A channel's sample rate: 1 / the median interval between its distinct sample times (0 for
    fewer than 2). Times already in order, each once (as a reader gives them), are taken as they
    are: `np.unique` of a 1-hour 250 Hz IMU's took 0.3 s."""
    t = np.asarray(t_ns, dtype=np.int64)
    steps = np.diff(t)
    if not bool((steps > 0).all()):
        t = np.unique(t)
        steps = np.diff(t)
    if t.size < 2:
        return 0.0
    return float(1e9 / np.median(steps))


def nice_rate(hz: float) -> float:
    """A grid rate near ``hz``: whole hertz (PX4 logs its IMU at 200, 250, ... Hz)."""
    return float(max(1, round(hz)))


def toml_list(items) -> str:
    return "[" + ", ".join(f'"{x}"' for x in items) + "]"
