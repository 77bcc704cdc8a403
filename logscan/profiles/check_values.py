"""The profile checker's value checks: tables, keys, numbers, rates, staleness limits, strings
and lists, each problem collected with where it is (`ValueChecker`)."""

from __future__ import annotations

import difflib
import math
from typing import Any

from logscan.profiles.problems import is_number, type_name
from logscan.profiles.schema import (
    MAX_STALE_S,
    MIN_RATE_HZ,
)

_STD_LIMITS = (1e-150, 1e150)  # a noise std whose square (the variance) is a normal float


def _choices(values) -> str:
    """``'a', 'b' or 'c'``."""
    quoted = [repr(v) for v in values]
    return quoted[0] if len(quoted) == 1 else f"{', '.join(quoted[:-1])} or {quoted[-1]}"


class ValueChecker:
    """Collects every problem of a profile (``problems``) while its values are read."""

    problems: list[str]

    def add(self, where: str, what: str) -> None:
        self.problems.append(f"{where}: {what}" if where else what)

    def table(self, data: Any, where: str) -> dict | None:
        if not isinstance(data, dict):
            self.add(where, f"expected a table, got {type_name(data)}")
            return None
        return data

    def keys(self, data: dict, where: str, allowed, required=()) -> None:
        for key in data:
            if key not in allowed:
                close = difflib.get_close_matches(key, allowed, n=1, cutoff=0.6)
                tip = f"did you mean {close[0]!r}?" if close else f"valid keys: {', '.join(allowed)}"
                self.add(where, f"unknown key {key!r} ({tip})")
        for key in required:
            if key not in data:
                self.add(where, f"missing required key {key!r}")

    def number(
        self, data: dict, key: str, where: str, *, minimum: float, strict: bool, allow_inf=False, maximum=math.inf
    ):
        """``data[key]`` as a finite float (``inf`` too with ``allow_inf``) above ``minimum`` (or
        equal, unless ``strict``) and at most ``maximum``; None when absent or with a problem."""
        if key not in data:
            return None
        value = data[key]
        if not is_number(value):
            self.add(f"{where} {key}", f"expected a number, got {type_name(value)}")
            return None
        try:
            value = float(value)
        except OverflowError:  # TOML integers have no size limit in tomllib: 10**400 is one
            self.add(f"{where} {key}", "must be a finite number, got an integer beyond float range")
            return None
        if math.isnan(value) or (math.isinf(value) and not (allow_inf and value > 0)):
            self.add(f"{where} {key}", f"must be a finite number, got {value!r}")
            return None
        if (strict and value <= minimum) or (not strict and value < minimum):
            op = ">" if strict else ">="
            self.add(f"{where} {key}", f"must be {op} {minimum:g}, got {value:g}")
            return None
        if value > maximum:
            self.add(f"{where} {key}", f"must be <= {maximum:g}, got {value:g}")
            return None
        return value

    def rate(self, data: dict, key: str, where: str) -> float | None:
        """A finite rate in Hz of at least MIN_RATE_HZ: a tiny one overflows the model's process noise
        (dt**4) or gives NaN grid steps. Too high a rate for the log's span is alignment's to refuse
        (its grid limit), naming the span and the steps."""
        value = self.number(data, key, where, minimum=0, strict=True)
        if value is not None and value < MIN_RATE_HZ:
            self.add(f"{where} {key}", f"must be >= {MIN_RATE_HZ:g} Hz (a {1 / MIN_RATE_HZ:g} s period), got {value:g}")
            return None
        return value

    def stale(self, data: dict, key: str, where: str) -> float | None:
        """A staleness limit: > 0 and at most MAX_STALE_S, or inf (never stale); a larger finite
        limit overflows int64 nanoseconds in alignment."""
        value = self.number(data, key, where, minimum=0, strict=True, allow_inf=True)
        if value is not None and math.isfinite(value) and value > MAX_STALE_S:
            self.add(f"{where} {key}", f"must be at most {MAX_STALE_S:.0f} s (or inf: never stale), got {value:g}")
            return None
        return value

    def string(self, data: dict, key: str, where: str) -> str | None:
        if key not in data:
            return None
        value = data[key]
        if not isinstance(value, str) or not value:
            self.add(f"{where} {key}", f"expected a non-empty string, got {type_name(value)}")
            return None
        return value

    def string_list(self, value: Any, where: str) -> list[str] | None:
        if not isinstance(value, list) or not value:
            self.add(where, f"expected a non-empty array of channel names, got {type_name(value)}")
            return None
        bad = [v for v in value if not isinstance(v, str) or not v]
        if bad:
            self.add(where, f"expected channel names (strings), got {type_name(bad[0])}")
            return None
        dup = sorted({v for v in value if value.count(v) > 1})
        if dup:
            self.add(where, f"channel {dup[0]!r} listed twice")
            return None
        return list(value)

    def float_list(self, data: dict, key: str, where: str, *, positive: bool) -> list[float] | None:
        """A number or an array of numbers (kept as given: scalar -> [x])."""
        if key not in data:
            return None
        value = data[key]
        items = value if isinstance(value, list) else [value]
        if not items or not all(is_number(v) for v in items):
            self.add(f"{where} {key}", f"expected a number or an array of numbers, got {type_name(value)}")
            return None
        try:
            out = [float(v) for v in items]
        except OverflowError:  # an integer beyond float range (tomllib reads any size)
            self.add(f"{where} {key}", "must be finite, got an integer beyond float range")
            return None
        if positive:
            bad = [v for v in out if not (v > 0 and math.isfinite(v))]
            if bad:
                self.add(f"{where} {key}", f"must be > 0 and finite, got {bad[0]:g}")
                return None
        elif not all(math.isfinite(v) for v in out):
            self.add(f"{where} {key}", f"must be finite, got {next(v for v in out if not math.isfinite(v))!r}")
            return None
        return out

    def noise_std(self, data: dict, where: str) -> list[float] | None:
        """``noise_std``: > 0 and within `_STD_LIMITS` (its square, the variance, a normal float);
        the bound by the group's range span needs the model (`bind`)."""
        noise = self.float_list(data, "noise_std", where, positive=True)
        if noise is None:
            return None
        smallest, largest = _STD_LIMITS
        if max(noise) > largest:
            self.add(f"{where} noise_std", f"{max(noise):g} would hide every fault of the group (at most {largest:g})")
        elif min(noise) < smallest:
            self.add(
                f"{where} noise_std", f"{min(noise):g} is too small: its square underflows (at least {smallest:g})"
            )
        else:
            return noise
        return None

    def _sized(self, values: list[float] | None, n: int, where: str, noun: str = "channels") -> list[float] | None:
        if values is None:
            return None
        if len(values) == 1:
            return values * n
        if len(values) != n:
            self.add(where, f"{len(values)} values for {n} {noun} (give one number or {n})")
            return None
        return values
