"""Checks of recovery's inputs against each other: loops, anomalies' targets, allowed-error states."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from logscan.errors import ProfileError
from logscan.recovery.records import Anomaly, LoopRun


def check_loops(loops: Sequence[LoopRun]) -> None:
    """ValueError unless the loops have unique names and each trace is its run's, with full P_post."""
    if not loops:
        raise ValueError("recovery needs at least one loop")
    names = [lp.name for lp in loops]
    if len(set(names)) != len(names) or not all(isinstance(n, str) and n for n in names):
        raise ValueError(f"loop names must be unique non-empty strings, got {names}")
    for lp in loops:
        tr = lp.trace
        if tr.P_post is None:
            raise ValueError(f"loop {lp.name!r}: the trace has no full P_post (run_ekf(..., full_P=True))")
        if tr.n_steps != lp.run.n_steps or tr.x_post.shape[1] != lp.model.n_states:
            raise ValueError(
                f"loop {lp.name!r}: the trace ({tr.n_steps} steps, {tr.x_post.shape[1]} states) is not of "
                f"this run and model ({lp.run.n_steps} steps, {lp.model.n_states} states)"
            )
        if list(tr.group_names) != list(lp.run.groups):
            raise ValueError(f"loop {lp.name!r}: the trace's groups {tr.group_names} are not the run's")
        if lp.run.n_steps and np.any(np.diff(np.asarray(lp.run.t, dtype=np.float64)) <= 0):
            raise ValueError(f"loop {lp.name!r}: grid times must increase")


def check_anomalies(anomalies: Sequence[Anomaly], loops: Sequence[LoopRun]) -> None:
    """ValueError for an anomaly with non-finite times, an end before its start, or a target that
    names an unknown loop or group."""
    groups = {lp.name: set(lp.run.groups) for lp in loops}
    for a in anomalies:
        if not (math.isfinite(a.t_detect) and math.isfinite(a.t_end)) or a.t_end < a.t_detect:
            raise ValueError(
                f"anomaly at {a.t_detect!r} s: times must be finite with t_end >= t_detect (t_end {a.t_end!r})"
            )
        for loop, flagged in (a.targets or {}).items():
            if loop not in groups:
                raise ValueError(
                    f"anomaly at {a.t_detect:g} s targets unknown loop {loop!r} (loops: {', '.join(groups)})"
                )
            unknown = sorted(set(flagged) - groups[loop])
            if unknown:
                raise ValueError(
                    f"anomaly at {a.t_detect:g} s flags group(s) {', '.join(unknown)} that loop {loop!r} lacks "
                    f"(groups: {', '.join(sorted(groups[loop]))})"
                )
        if a.targets is not None and not any(a.targets.values()):
            raise ValueError(
                f"anomaly at {a.t_detect:g} s is specific but flags no group (use targets=None for generic)"
            )


def allowed_states(allowed: Mapping[str, float], loops: Sequence[LoopRun]) -> dict[str, dict[int, float]]:
    """loop -> state index -> E from the settings' "loop.state" keys; ProfileError naming the
    loops' states for a key that matches none."""
    out: dict[str, dict[int, float]] = {}
    for key, E in allowed.items():
        match = [
            (lp.name, list(lp.model.state_names).index(key[len(lp.name) + 1 :]))
            for lp in loops
            if key.startswith(lp.name + ".") and key[len(lp.name) + 1 :] in lp.model.state_names
        ]
        if not match:
            known = ", ".join(f"{lp.name}.{s}" for lp in loops for s in lp.model.state_names)
            raise ProfileError(f"recovery allowed_error names {key!r}, no loop state", hint=f"states: {known}")
        loop, index = match[0]
        out.setdefault(loop, {})[index] = float(E)
    return out
