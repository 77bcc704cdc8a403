"""What the detectors that read a log's own topics (`Detector.raw_topics`: px4_estimator, health)
share: the raw channels by topic and instance, a sample series placed on the analysis grid, the
persistence a duration takes at a source's rate, a channel held at given times, the log's
parameters, and the checks they could not run in words (the frozen-sensor check's too)."""

from __future__ import annotations

import math
import re
from collections.abc import Container, Mapping

import numpy as np

_CHANNEL = re.compile(r"^/?(?P<topic>[^/]+)_(?P<instance>\d+)/(?P<field>.+)$")


def split_topics(raw: Mapping, known: Container[str]) -> dict[tuple[str, int], dict]:
    """(topic, instance) -> {field: Channel} of the raw channels (``/<topic>_<instance>/<field>``,
    a ULog's names) of the ``known`` topics."""
    topics: dict[tuple[str, int], dict] = {}
    for name, channel in raw.items():
        match = _CHANNEL.match(name)
        if match is None or match.group("topic") not in known:
            continue
        key = (match.group("topic"), int(match.group("instance")))
        topics.setdefault(key, {})[match.group("field")] = channel
    return topics


def on_grid(run, t_ns: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The samples on the run's grid: each at the first step at or after its time (the max of those
    that fall on one step), NaN on steps without a sample."""
    statistic = np.full(run.n_steps, np.nan)
    if t_ns.size == 0 or run.n_steps == 0:
        return statistic
    step, landed = grid_steps(run, t_ns)
    keep = landed & np.isfinite(values)
    np.fmax.at(statistic, step[keep], values[keep])
    return statistic


def grid_steps(run, t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the grid step each time falls on: the first at or after it, whether it lands on the grid:
    not after its last step nor more than a step before its first)."""
    t = (np.asarray(t_ns) - run.start_ns) / 1e9
    step = np.searchsorted(run.t, t - 1e-9, side="left")
    return step, (step < run.n_steps) & (t >= run.t[0] - float(run.dt))


def persist_count(t_valid: np.ndarray, min_duration_s: float) -> int:
    """Consecutive samples over a threshold that span ``min_duration_s`` at the source's median
    sample period on the grid (1 without a duration or with fewer than 2 samples)."""
    if min_duration_s <= 0 or t_valid.size < 2:
        return 1
    period = float(np.median(np.diff(t_valid)))
    if not period > 0:
        return 1
    return int(math.ceil(float(min_duration_s) / period - 1e-6)) + 1


def held(channel, t_ns: np.ndarray) -> np.ndarray:
    """The channel's value held from its latest sample at or before each time (NaN before)."""
    i = np.searchsorted(channel.t, t_ns, side="right") - 1
    out = channel.values[np.maximum(i, 0)].astype(np.float64)
    out[i < 0] = np.nan
    return out


def log_parameter(parameters: Mapping, *names: str, positive: bool = True) -> tuple[float, str] | None:
    """(value, name) of the first of ``names`` the log sets to a usable value (finite, and > 0
    when ``positive``: PX4 writes -1 for "not set"), else None."""
    for name in names:
        try:
            value = float(parameters[name])
        except (KeyError, TypeError, ValueError):
            continue
        if math.isfinite(value) and (value > 0 or not positive):
            return value, name
    return None


def in_span(run, t_ns: np.ndarray) -> np.ndarray:
    """The samples (times ``t_ns``) inside the analysed span: from the grid's first step to one step
    after its last."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    if not run.n_steps:
        return np.zeros(t_ns.size, bool)
    first = run.start_ns + round(float(run.t[0]) * 1e9)
    last = run.start_ns + round((float(run.t[-1]) + float(run.dt)) * 1e9)
    return (t_ns >= first) & (t_ns <= last)


def skipped_lines(skipped: Mapping[str, str], prefix: str, shown: int = 3) -> list[str]:
    """The ``skipped`` checks (name -> reason) as one line per reason, naming its checks without
    ``prefix.`` ("motor_max.1, motor_max.2 and 6 more: actuator_outputs_0: ..."), in first-seen order."""
    by_reason: dict[str, list[str]] = {}
    for name, reason in skipped.items():
        by_reason.setdefault(reason, []).append(name.removeprefix(f"{prefix}."))
    lines = []
    for reason, names in by_reason.items():
        named = ", ".join(names[:shown]) if len(names) <= shown else (
            f"{', '.join(names[: shown - 1])} and {len(names) - shown + 1} more"
        )  # fmt: skip
        lines.append(f"{named}: {reason}")
    return lines
