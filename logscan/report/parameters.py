"""The PX4 parameters a report lists: those set away from their defaults, and those changed in flight.

A ULog holds every parameter's value at the start (``ulog.parameters``), the changes while logging
(``ulog.parameters_changed``) and, in newer PX4 logs, the system default of each parameter whose
value differs from it (``ulog.parameters_default``: PX4 writes a default only where it differs, so
that list is the answer). An older log carries no defaults: the report then lists the changes in
flight only, and says that the defaults are not in the log.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field

MAX_ROWS = 2_000  # a PX4 log holds ~1000 parameters: every row fits
_CHANGE = re.compile(r"^\s*(?P<t>[-+0-9.eE]+) s (?P<name>\S+) = (?P<value>.*)$", re.S)


@dataclass
class ParameterFacts:
    """A log's parameters as the report lists them.

    differ:       (name, value at the start, system default) of each parameter set away from its
                  default, by name; empty when the log has no defaults.
    changed:      (time s since the log's time zero, name, new value) of each change while logging.
    has_defaults: whether the log carries defaults (else ``differ`` cannot be known).
    n_parameters: how many parameters the log holds.
    """

    differ: list[tuple[str, str, str]] = field(default_factory=list)
    changed: list[tuple[float, str, str]] = field(default_factory=list)
    has_defaults: bool = False
    n_parameters: int = 0


def _same(a: str | None, b: str) -> bool:
    """Whether two parameter values (as the reader writes them: "4", "0.5") are equal."""
    if a is None:
        return False
    try:
        return float(a) == float(b)
    except ValueError:
        return a == b


def _changes(lines: Mapping, start_ns: int) -> list[tuple[float, str, str]]:
    out = []
    for line in lines.values():
        match = _CHANGE.match(str(line))
        if match is None:
            continue
        try:
            t_s = float(match.group("t")) - start_ns / 1e9  # written in the log's seconds
        except ValueError:
            continue
        out.append((t_s, match.group("name"), match.group("value").strip()))
    return sorted(out)[:MAX_ROWS]


def parameter_facts(metadata: Mapping | None, start_ns: int) -> ParameterFacts | None:
    """The parameters of a ULog's ``metadata`` (`logscan.readers.ulog_reader`), None when it has none
    (any other format)."""
    metadata = metadata or {}
    initial = metadata.get("ulog.parameters") or {}
    if not initial:
        return None
    defaults = metadata.get("ulog.parameters_default")
    differ = [
        (str(name), str(initial.get(name, "—")), str(default))
        for name, default in sorted((defaults or {}).items())
        if not _same(initial.get(name), str(default))
    ]
    changes = _changes(metadata.get("ulog.parameters_changed") or {}, start_ns)
    return ParameterFacts(differ[:MAX_ROWS], changes, defaults is not None, len(initial))


def value_text(value: str) -> str:
    """A parameter value as shown: a float in 7 significant digits (PX4 stores float32, which the
    reader writes in full: 0.15150000154972076 is 0.1515), an integer or text as it is."""
    if "." not in value and "e" not in value.lower():
        return value
    try:
        return f"{float(value):.7g}"
    except ValueError:
        return value


def parameter_rows(facts: ParameterFacts | None, clock) -> dict | None:
    """The report's folded parameter tables: ``{"differ": [{name, value, default}], "changed":
    [{time, t0, name, value}], "has_defaults", "n"}``; None without parameters. ``t0`` in the time
    axis' units (`logscan.timebase.clock.Clock.axis_value`), where a click zooms."""
    if facts is None:
        return None
    return {
        "differ": [{"name": n, "value": value_text(v), "default": value_text(d)} for n, v, d in facts.differ],
        "changed": [
            {"time": clock.short(t), "t0": repr(clock.axis_value(t)), "name": n, "value": value_text(v)}
            for t, n, v in facts.changed
        ],
        "has_defaults": facts.has_defaults,
        "n": facts.n_parameters,
    }
