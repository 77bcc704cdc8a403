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
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

_INT64 = 2**63


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
    "neither"."""

    kind: type
    low: float | None = None
    high: float | None = None
    closed: str = "both"

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
        return f"{noun} in {left}{low}, {high}{right}"


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


def satisfies(value: Any, constraints: list) -> bool:
    """Whether ``value`` meets at least one constraint (None in the list admits None)."""
    return any(value is None if c is None else c.accepts(value) for c in constraints)


def describe_constraints(constraints: list) -> str:
    """Text of a parameter's constraints: "a number in (0, inf) or None"."""
    return " or ".join("None" if c is None else str(c) for c in constraints)
