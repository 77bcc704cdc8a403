"""Time columns of CSV logs: which column is the time, the unit its name states, the unit its
numbers imply (`infer_time_unit`), and the check that a stated unit fits the numbers
(`check_stated_unit`: ``time_s`` holding epoch nanoseconds is refused, naming the unit they fit).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from logscan.errors import InputError

_UNIT_WORDS = {
    "s": "s", "sec": "s", "secs": "s", "second": "s", "seconds": "s",
    "ms": "ms", "msec": "ms", "msecs": "ms", "millis": "ms", "milliseconds": "ms",
    "us": "us", "usec": "us", "usecs": "us", "µs": "us", "micros": "us", "microseconds": "us",
    "ns": "ns", "nsec": "ns", "nsecs": "ns", "nanos": "ns", "nanoseconds": "ns",
}  # fmt: skip
_TIME_RE = re.compile(
    r"^%?(?P<base>time|timestamp|t|stamp)"
    r"(?:(?:[\s_\-.]+[\[(]?|[\s_\-.]*[\[(])\s*(?P<unit>"
    + "|".join(sorted(_UNIT_WORDS, key=len, reverse=True))
    + r")\s*[\])]?)?$",
    re.IGNORECASE,
)
NS_PER_UNIT = {"s": 1_000_000_000, "ms": 1_000_000, "us": 1_000, "ns": 1}

# Plausibility windows of the unit inference (seconds).
_EPOCH_MIN_S, _EPOCH_MAX_S = 946_684_800.0, 4_102_444_800.0  # 2000-01-01 .. 2100-01-01
_RELATIVE_MAX_S = 1.0e6  # time since boot / since the log's start: under ~11.6 days
_PERIOD_MIN_S, _PERIOD_MAX_S = 1.0e-7, 1.0e4
_TYPICAL_PERIOD_LOG10 = -1.5  # ~30 Hz, the middle of what vehicle logs sample at
# A stated unit is refused when the column read in it is past 2100 as epoch time (median), spans more
# than a year (median step x rows) or samples faster than 1 MHz (median step): the name is wrong.
_YEAR_S = 365.25 * 86_400.0
_STATED_MAX_SPAN_S = _YEAR_S
_STATED_MIN_PERIOD_S = 1.0e-6
_UNIT_NAMES = {"s": "seconds", "ms": "milliseconds", "us": "microseconds", "ns": "nanoseconds"}
MAX_TIME_NS = 2**63 - 1  # times are int64 ns


@dataclass
class TimeUnit:
    """How a time column's numbers become nanoseconds, and why."""

    unit: str  # s, ms, us, ns
    origin: str  # "epoch", "relative" or "stated"
    reason: str


def time_column_unit(name: str) -> tuple[bool, str | None]:
    """(is a time column, unit stated by its name or None) for a column header."""
    match = _TIME_RE.match(name.strip())
    if not match:
        return False, None
    unit = match.group("unit")
    return True, (_UNIT_WORDS[unit.lower()] if unit else None)


def infer_time_unit(values: np.ndarray) -> TimeUnit:
    """Infer the unit of raw time numbers from their median step and magnitude.

    A unit is plausible when the median step is a sampling period between 0.1 us and ~3 h, and the
    values are either a relative time under ~11.6 days or epoch time between 2000 and 2100.
    Fractional numbers prefer the coarsest plausible unit (seconds); integers take the plausible
    unit whose period is closest to ~30 Hz in log scale (ties go to the coarser unit).
    """
    finite = _finite(values)
    if finite.size == 0:
        return TimeUnit("s", "relative", "no finite time values; assumed seconds")
    steps = _positive(np.diff(finite if _ascending(finite) else np.sort(finite)))
    step = _median(steps) if steps.size else 0.0
    low, high = float(finite.min()), float(finite.max())
    integers = bool(np.all(finite == np.round(finite)))

    plausible: list[tuple[str, str, float]] = []
    for unit in ("s", "ms", "us", "ns"):
        scale = NS_PER_UNIT[unit] / 1e9
        period = step * scale
        if step and not _PERIOD_MIN_S <= period <= _PERIOD_MAX_S:
            continue
        if abs(high) * scale <= _RELATIVE_MAX_S and abs(low) * scale <= _RELATIVE_MAX_S:
            plausible.append((unit, "relative", period))
        elif _EPOCH_MIN_S <= low * scale and high * scale <= _EPOCH_MAX_S:
            plausible.append((unit, "epoch", period))
    facts = f"median step {step:g}, values {low:g} .. {high:g}"
    if not plausible:
        return TimeUnit("s", "relative", f"{facts} fit no unit; assumed seconds")
    if integers and step:
        unit, origin, period = min(plausible, key=lambda item: abs(np.log10(item[2]) - _TYPICAL_PERIOD_LOG10))
    else:
        unit, origin, period = plausible[0]
    rate = f", ~{1 / period:.4g} Hz" if period else ""
    return TimeUnit(unit, origin, f"{facts} ({origin} time{rate})")


def check_stated_unit(values: np.ndarray, name: str, unit: str, path: Path) -> None:
    """InputError when the numbers of the time column ``name`` contradict the unit its name states
    (see _STATED_MAX_SPAN_S), saying what they look like and what to rename the column to."""
    finite = _finite(values)
    if finite.size == 0:
        return
    scale = NS_PER_UNIT[unit] / 1e9
    in_order = _ascending(finite)
    middle = _sorted_median(finite) if in_order else float(np.median(finite))
    times = _fitting_times(finite, MAX_TIME_NS // NS_PER_UNIT[unit], in_order)  # the rows read as times
    times = times if in_order else np.sort(times)
    steps = _positive(np.diff(times))
    step = _median(steps) if steps.size else 0.0
    span = step * (times.size - 1) * scale  # the span its sampling implies: blind to a few wild rows
    if abs(middle) * scale > _EPOCH_MAX_S:
        problem = f"a median of {middle:.3g} {unit} is {abs(middle) * scale / _YEAR_S:.3g} years"
    elif span > _STATED_MAX_SPAN_S:
        problem = f"{times.size} samples {step:.3g} {unit} apart span {span / _YEAR_S:.3g} years"
    elif step and step * scale < _STATED_MIN_PERIOD_S:
        problem = f"a median step of {step:.3g} {unit} is {1 / (step * scale):.3g} Hz"
    else:
        return
    guess = infer_time_unit(finite)
    plausible = guess.unit != unit and "fit no unit" not in guess.reason
    base = _TIME_RE.match(name.strip()).group("base")
    reading = guess.reason.rsplit("(", 1)[-1].rstrip(")")  # e.g. "epoch time, ~100 Hz"
    looks = f"; read as {_UNIT_NAMES[guess.unit]} they are {reading}" if plausible else ""
    rename = f"rename it to '{base}_{guess.unit}'" if plausible else "name it time_s, time_ms, time_us or time_ns"
    raise InputError(
        f"time column {name!r} states {_UNIT_NAMES[unit]} but {problem}{looks}", path=str(path), hint=rename
    )


# A time column is nearly always finite and in order: then it is used as it is, not copied and
# sorted (the same numbers: np.median of sorted values is the mean of their middle one or two).


def _finite(values: np.ndarray) -> np.ndarray:
    finite = np.isfinite(values)
    return values if finite.all() else values[finite]


def _ascending(values: np.ndarray) -> bool:
    return values.size < 2 or bool((values[1:] >= values[:-1]).all())


def _positive(steps: np.ndarray) -> np.ndarray:
    """The steps > 0 (all of them, uncopied, when every step is)."""
    positive = steps > 0
    return steps if positive.all() else steps[positive]


def _fitting_times(finite: np.ndarray, limit: int, in_order: bool) -> np.ndarray:
    """The finite times whose magnitude is under ``limit`` (all of them, uncopied, when they are: an
    ascending column's ends say so without a pass over it)."""
    if in_order and -limit < float(finite[0]) and float(finite[-1]) < limit:
        return finite
    fits = np.abs(finite) < limit
    return finite if fits.all() else finite[fits]


def _median(own: np.ndarray) -> float:
    """np.median of ``own`` (size >= 1, no NaN: steps between finite times; a temporary of the
    caller's, partitioned in place), bit for bit: the mean of the middle one or two after one
    partition at them (np.median copies, and partitions at the last element too to find NaNs: 4x
    the time on a million steps)."""
    half = own.size // 2
    if own.size % 2:
        own.partition(half)
        return float(np.mean(own[half : half + 1]))
    own.partition((half - 1, half))
    return float(np.mean(own[half - 1 : half + 1]))


def _sorted_median(values: np.ndarray) -> float:
    """np.median of ascending ``values`` (size >= 1), bit for bit: the mean of its middle one or two."""
    half = values.size // 2
    return float(np.mean(values[half - 1 : half + 1] if values.size % 2 == 0 else values[half : half + 1]))
