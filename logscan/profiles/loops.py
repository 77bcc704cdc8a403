"""Hierarchical profiles: further control loops (``[loops.<name>]``) and the ``[recovery]`` table.

A profile's top level is one loop (the primary; ``[vehicle] loop`` names it). Each further loop is a
table with the keys of a top-level profile (``vehicle``, ``inputs``, ``measurements`` and the
optional ``mode``, ``alarms``, ``detectors``), parsed and checked against its own model exactly as a
profile is; the pipeline runs the shared filters on each loop at its own rate. ``[recovery]`` asks
for checkpointing and roll-forward recovery of the loops' estimates during anomalies
(`logscan.recovery`); its keys are documented in docs/profiles.md.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

LOOP_KEYS = ("vehicle", "inputs", "measurements", "mode", "alarms", "detectors")
RECOVERY_KEYS = (
    "detector",
    "method",
    "checkpoint_period_s",
    "detection_time_s",
    "k_sigma",
    "allowed_error",
    "hold_s",
    "max_duration_s",
    "agreement_quantile",
    "consistency_tol_s",
    "budget_per_hour",
    "proof_hours",
)
RECOVERY_METHODS = ("refilter", "rollforward", "replace")
#: ``[recovery] detector = "oracle"``: anomalies from the log's ground truth, for evaluation only
ORACLE = "oracle"
PRIMARY_LOOP = "main"  # the top level's loop name when ``[vehicle] loop`` is not given


@dataclass
class RecoverySpec:
    """``[recovery]``: which alarms drive recovery, and the settings given (`logscan.recovery`'s
    RecoverySettings holds their defaults and checks their values; here only their types).

    ``detector``: a registered detector's name, ``"oracle"`` (ground truth), or None (the alarms of
    every detector that ran). ``settings["allowed_error"]``: "loop.state" -> the largest tolerable
    error E of that state (its T_max is the first recovery duration whose bound exceeds E).
    """

    detector: str | None = None
    settings: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return ({"detector": self.detector} if self.detector is not None else {}) | self.settings


def parse_loops(checker, raw: Any, source: str, check_model: Callable[..., None] | None) -> dict:
    """``[loops]``: loop name -> Profile of that loop; problems go to ``checker`` prefixed with
    the loop's table. ``check_model``: None, or the check of each loop against its model, called as
    ``check_model(profile, None, problems)`` (the caller passes `logscan.profiles.bind`'s
    check_against_model, so this module imports neither bind nor schema)."""
    data = checker.table(raw, "[loops]") or {}
    loops = {}
    for name, table in data.items():
        where = f"[loops.{name}]"
        sub = checker.table(table, where)
        if sub is None:
            continue
        if not name.isidentifier():
            checker.add(where, "a loop name must be a plain identifier (letters, digits, _)")
            continue
        checker.keys(sub, where, LOOP_KEYS, required=("vehicle", "measurements"))
        inner = type(checker)()
        profile = inner.profile({k: v for k, v in sub.items() if k in LOOP_KEYS}, source)
        if profile is not None and check_model is not None and not inner.problems:
            check_model(profile, None, inner.problems)
        checker.problems.extend(f"{where} {problem}" for problem in inner.problems)
        if profile is not None and not inner.problems:
            loops[name] = replace(profile, vehicle=replace(profile.vehicle, loop=name))
    return loops


def parse_recovery(checker, raw: Any, loop_names: set[str]) -> RecoverySpec | None:
    """``[recovery]`` checked key by key; None with problems added to ``checker``."""
    where = "[recovery]"
    data = checker.table(raw, where)
    if data is None:
        return None
    checker.keys(data, where, RECOVERY_KEYS)
    before = len(checker.problems)
    detector = checker.string(data, "detector", where)
    settings: dict[str, Any] = {}
    if "method" in data:
        method = checker.string(data, "method", where)
        if method is not None and method not in RECOVERY_METHODS:
            checker.add(f"{where} method", f"must be one of {', '.join(RECOVERY_METHODS)}, got {method!r}")
        settings["method"] = method
    for key in ("checkpoint_period_s", "detection_time_s", "hold_s"):
        settings[key] = checker.number(data, key, where, minimum=0, strict=False)
    for key in ("k_sigma", "max_duration_s", "consistency_tol_s", "budget_per_hour", "proof_hours"):
        settings[key] = checker.number(data, key, where, minimum=0, strict=True)
    settings["agreement_quantile"] = checker.number(
        data, "agreement_quantile", where, minimum=0, strict=True, maximum=1
    )
    if "allowed_error" in data:
        errors = checker.table(data["allowed_error"], f"{where} allowed_error") or {}
        settings["allowed_error"] = {}
        for state in errors:
            if "." not in state or state.split(".", 1)[0] not in loop_names:
                checker.add(
                    f"{where} allowed_error", f"{state!r}: expected 'loop.state' with a loop among {sorted(loop_names)}"
                )
                continue
            settings["allowed_error"][state] = checker.number(
                errors, state, f"{where} allowed_error", minimum=0, strict=True
            )
    if len(checker.problems) > before:
        return None
    return RecoverySpec(detector, {key: value for key, value in settings.items() if key in data})
