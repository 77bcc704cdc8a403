"""Hierarchical profiles: further control loops (``[loops.<name>]``) and the ``[recovery]`` table.

A profile's top level is one loop (the primary; ``[vehicle] loop`` names it). Each further loop is a
table with the keys of a top-level profile (``vehicle``, ``inputs``, ``measurements`` and the
optional ``mode``, ``alarms``, ``detectors``), parsed and checked against its own model exactly as a
profile is; the pipeline runs the shared filters on each loop at its own rate. ``[recovery]`` asks
for checkpointing and roll-forward recovery of the loops' estimates during anomalies
(`logscan.recovery`); its keys are documented in docs/profiles.md.
"""

from __future__ import annotations

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
)
RECOVERY_METHODS = ("refilter", "rollforward", "replace")
#: ``[recovery] detector = "oracle"``: anomalies from the log's ground truth, for evaluation only
ORACLE = "oracle"
PRIMARY_LOOP = "main"  # the top level's loop name when ``[vehicle] loop`` is not given


@dataclass
class RecoverySpec:
    """``[recovery]``: which alarms drive recovery and how (see `logscan.recovery`).

    ``detector``: a registered detector's name, ``"oracle"`` (ground truth), or None (the alarms of
    every detector that ran). ``allowed_error``: "loop.state" -> the largest tolerable error E of
    that state (its T_max is the first recovery duration whose bound exceeds E).
    """

    detector: str | None = None
    method: str = "refilter"
    checkpoint_period_s: float = 0.0  # 0: every sample of the slowest loop
    detection_time_s: float = 0.25  # checkpoint margin: the detector's latency
    k_sigma: float = 3.0
    allowed_error: dict[str, float] = field(default_factory=dict)
    hold_s: float = 0.5  # the flagged sensors must agree again this long to end an anomaly
    max_duration_s: float = 60.0

    def to_dict(self) -> dict[str, Any]:
        out = {key: getattr(self, key) for key in RECOVERY_KEYS if key not in ("detector", "allowed_error")}
        if self.detector is not None:
            out["detector"] = self.detector
        if self.allowed_error:
            out["allowed_error"] = dict(self.allowed_error)
        return out


def parse_loops(checker, raw: Any, source: str, check_model: bool) -> dict:
    """``[loops]``: loop name -> Profile of that loop; problems go to ``checker`` prefixed with
    the loop's table. ``check_model``: also check each loop against its model."""
    from logscan.profiles.bind import check_against_model

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
        if profile is not None and check_model and not inner.problems:
            check_against_model(profile, None, inner.problems)
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
    values: dict[str, Any] = {}
    if "detector" in data:
        values["detector"] = checker.string(data, "detector", where)
    if "method" in data:
        method = checker.string(data, "method", where)
        if method is not None and method not in RECOVERY_METHODS:
            checker.add(f"{where} method", f"must be one of {', '.join(RECOVERY_METHODS)}, got {method!r}")
        values["method"] = method
    for key, strict in (("checkpoint_period_s", False), ("detection_time_s", False), ("hold_s", False)):
        values[key] = checker.number(data, key, where, minimum=0, strict=strict)
    for key in ("k_sigma", "max_duration_s"):
        values[key] = checker.number(data, key, where, minimum=0, strict=True)
    errors = checker.table(data.get("allowed_error", {}), f"{where} allowed_error") or {}
    values["allowed_error"] = {}
    for state, _ in errors.items():
        loop = state.split(".", 1)[0]
        if "." not in state or loop not in loop_names:
            checker.add(
                f"{where} allowed_error", f"{state!r}: expected 'loop.state' with a loop among {sorted(loop_names)}"
            )
            continue
        values["allowed_error"][state] = checker.number(errors, state, f"{where} allowed_error", minimum=0, strict=True)
    if len(checker.problems) > before:
        return None
    return RecoverySpec(**{k: v for k, v in values.items() if v is not None or k == "detector"})
