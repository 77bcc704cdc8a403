"""What every built-in profile builder shares: the built profile, rates, TOML lists."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from logscan.log import times_read


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
    are: `np.unique` of a 1-hour 250 Hz IMU's took 0.3 s; their steps are counted a megasample at
    a time (`_step_counts`): a 24-hour IMU's steps and their sort took 350 MB at once."""
    t = np.asarray(t_ns, dtype=np.int64)
    counted = _step_counts(t)
    if counted is None:  # the median of all the steps at once
        steps = np.diff(t)
        if not bool((steps > 0).all()):
            t = np.unique(t)
            steps = np.diff(t)
        return 0.0 if t.size < 2 else float(1e9 / np.median(steps))
    steps, counts = counted
    if not steps.size:
        return 0.0
    # the middle step or two, as np.median of the steps takes them (their mean, in float64)
    total = int(counts.sum())
    ends = np.cumsum(counts)
    middle = [(total - 1) // 2, total // 2]
    return float(1e9 / np.median(steps[np.searchsorted(ends, middle, "right")]))


def _step_counts(t: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """(each distinct step between consecutive times of ``t``, sorted, and how many there are), a
    megasample at a time; None when a step is not positive (times out of order or logged twice) or
    the distinct steps are many (nanosecond stamps: counting them saves nothing)."""
    values, counts = [np.empty(0, np.int64)], [np.empty(0, np.int64)]
    distinct = 0
    for lo in range(0, max(t.size - 1, 0), _STEP_CHUNK):
        steps = np.diff(t[lo : lo + _STEP_CHUNK + 1])
        times_read(steps.nbytes)
        if not bool((steps > 0).all()):
            return None
        found = np.unique(steps, return_counts=True)
        values.append(found[0])
        counts.append(found[1])
        distinct += found[0].size
        if distinct > _STEP_CHUNK:  # merged once their pieces outgrow a chunk; too many still: at once
            merged = _merged(values, counts)
            if merged[0].size > _STEP_CHUNK // 4:
                return None
            values, counts, distinct = [merged[0]], [merged[1]], merged[0].size
    return _merged(values, counts)


def _merged(values: list[np.ndarray], counts: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The distinct ``values`` (sorted) and their ``counts`` summed."""
    distinct, where = np.unique(np.concatenate(values), return_inverse=True)
    summed = np.zeros(distinct.size, np.int64)
    np.add.at(summed, where.ravel(), np.concatenate(counts))
    return distinct, summed


_STEP_CHUNK = 1 << 20  # steps per pass of `_step_counts`


def nice_rate(hz: float) -> float:
    """A grid rate near ``hz``: whole hertz (PX4 logs its IMU at 200, 250, ... Hz)."""
    return float(max(1, round(hz)))


def toml_list(items) -> str:
    return "[" + ", ".join(f'"{x}"' for x in items) + "]"
