"""Declared detector parameters: each detector states its parameters' types and ranges once.

The idea of scikit-learn's ``_parameter_constraints``: a detector class maps every parameter to a
list of constraints, and a value is valid when it satisfies at least one of them. The check runs
when the detector is created (right after the profile is parsed, before any log is read), and
`logscan detectors` prints the constraints as text.

    parameter_constraints = {
        "rho": [Interval(float, 0, None, closed="neither")],
        "window": [Interval(int, 1, None)],
        "variant": [Options("adaptive", "baseline")],
        "threshold": [Interval(float, 0, None, closed="neither"), None],
    }

A bound that keeps a setting from hiding faults says why (``why``): a false-alarm rate or
probability whose design rate falls below `MIN_DESIGN_RATE_PER_HOUR`, or a multiplier over the
bound stated for that parameter, is refused with that reason (issue 31: ``rho = 1e308`` made a
faulty log "no alarms"). `logscan detectors` and docs/detectors.md show the bound and the reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

_INT64 = 2**63

# The lowest false-alarm rate a detector may be designed for: below it a test practically never
# alarms, whatever the fault (a setting that low hides faults and is refused).
MIN_DESIGN_RATE_PER_HOUR = 1e-12
# The slowest test a per-test probability is judged at: one test every 100 s (a 1 Hz GNSS in a
# 100-update window); a faster log only raises the rate an alpha gives.
SLOWEST_TESTS_PER_HOUR = 36.0
MIN_ALPHA = 3e-14  # MIN_DESIGN_RATE_PER_HOUR / SLOWEST_TESTS_PER_HOUR = 2.8e-14, rounded up


def _is_int(value: Any) -> bool:
    """An integer numpy can hold (int64): 10**400 in a profile is no window length."""
    return isinstance(value, int) and not isinstance(value, bool) and -_INT64 <= value < _INT64


def _is_real(value: Any) -> bool:
    if isinstance(value, int) and not isinstance(value, bool):
        return abs(value) < 2**1024  # within float range (math.isfinite would raise beyond it)
    return isinstance(value, float) and math.isfinite(value)


@dataclass(frozen=True)
class Interval:
    """A number in [low, high] (either end None: unbounded). kind int accepts integers only; kind
    float accepts any finite real number (an integer included). closed: "both", "left", "right" or
    "neither". ``why``: the reason for a bound that keeps the setting from hiding faults, said
    wherever the constraint is (refusals, `logscan detectors`, docs/detectors.md)."""

    kind: type
    low: float | None = None
    high: float | None = None
    closed: str = "both"
    why: str = ""

    def accepts(self, value: Any) -> bool:
        if not (_is_int(value) if self.kind is int else _is_real(value)):
            return False
        if self.low is not None:
            if value < self.low or (value == self.low and self.closed in ("right", "neither")):
                return False
        if self.high is not None:
            if value > self.high or (value == self.high and self.closed in ("left", "neither")):
                return False
        return True

    def __str__(self) -> str:
        noun = "an integer" if self.kind is int else "a number"
        if self.low is None and self.high is None:
            return noun
        left = "[" if self.closed in ("both", "left") and self.low is not None else "("
        right = "]" if self.closed in ("both", "right") and self.high is not None else ")"
        low = "-inf" if self.low is None else f"{self.low:g}"
        high = "inf" if self.high is None else f"{self.high:g}"
        text = f"{noun} in {left}{low}, {high}{right}"
        return f"{text} ({self.why})" if self.why else text


def budget_bound() -> Interval:
    """A false-alarm budget in alarms per hour: at least `MIN_DESIGN_RATE_PER_HOUR`."""
    return Interval(
        float,
        MIN_DESIGN_RATE_PER_HOUR,
        None,
        why=f"a budget under {MIN_DESIGN_RATE_PER_HOUR:g} false alarms per hour designs a test that never "
        "alarms: it would hide faults",
    )


def alpha_bound() -> Interval:
    """A false-alarm probability per test: at least `MIN_ALPHA`, under 1."""
    return Interval(
        float,
        MIN_ALPHA,
        1,
        closed="left",
        why=f"below {MIN_ALPHA:g} a test run every 100 s designs for under {MIN_DESIGN_RATE_PER_HOUR:g} false "
        "alarms per hour: it would hide faults",
    )


def multiplier_bound(low: float, high: float, what: str, *, closed: str = "right", kind: type = float) -> Interval:
    """A threshold multiplier (or count) in (low, high]: over ``high`` it hides faults; ``what``
    says what a larger value would hide."""
    return Interval(kind, low, high, closed=closed, why=f"over {high:g} {what}: it would hide faults")


@dataclass(frozen=True)
class Options:
    """One of the given strings."""

    choices: tuple[str, ...]

    def __init__(self, *choices: str) -> None:
        object.__setattr__(self, "choices", tuple(choices))

    def accepts(self, value: Any) -> bool:
        return isinstance(value, str) and value in self.choices

    def __str__(self) -> str:
        return "one of " + ", ".join(repr(c) for c in self.choices)


@dataclass(frozen=True)
class Boolean:
    """true or false."""

    def accepts(self, value: Any) -> bool:
        return isinstance(value, bool)

    def __str__(self) -> str:
        return "true or false"


@dataclass(frozen=True)
class RealList:
    """A list of finite numbers (its length is checked against the model at run time)."""

    def accepts(self, value: Any) -> bool:
        return isinstance(value, (list, tuple)) and all(_is_real(v) for v in value)

    def __str__(self) -> str:
        return "a list of numbers"


@dataclass(frozen=True)
class StringList:
    """A list of strings (names checked against the model at run time)."""

    def accepts(self, value: Any) -> bool:
        return isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value)

    def __str__(self) -> str:
        return "a list of names"


# consecutive exceedances an alarm needs (a detector's n_persist)
PERSIST = multiplier_bound(1, 10_000, "consecutive exceedances before an alarm", closed="both", kind=int)


def satisfies(value: Any, constraints: list) -> bool:
    """Whether ``value`` meets at least one constraint (None in the list admits None)."""
    return any(value is None if c is None else c.accepts(value) for c in constraints)


def describe_constraints(constraints: list) -> str:
    """Text of a parameter's constraints: "a number in (0, inf) or None"."""
    return " or ".join("None" if c is None else str(c) for c in constraints)
