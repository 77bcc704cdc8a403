"""Threshold multipliers tuned on logs (`logscan train --tune`): filter once, threshold many times.

A detector declares the multipliers it can be tuned on and the statistics each one thresholds
(`Detector.tunable`, e.g. encoded_ekf: rho -> e_x, rho_v -> e_v, rho_s -> e_s; the alarms of
other statistics, such as its rejected-sample checks, do not depend on them and are not counted). Every training log
is prepared (read, aligned, filtered) once; each value of TUNE_GRID is then a detector run on those
prepared runs, all multipliers at the value at once (each statistic depends on its own only). The
rule (docs/algorithms.md section 1.7): the smallest grid value with no alarm of that multiplier's
statistics on the healthy logs, plus TUNE_MARGIN; the labelled logs (those whose ground truth lists
faults) are scored at every value, and their F1 breaks ties: when several values would be chosen
the same way, i.e. among the values from that choice up to TUNE_MARGIN more, the best F1 wins (the
smallest on equal F1). The F1 curve is kept for the tables and the report.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from logscan.results import events_from_truth
from logscan.verdict.scoring import score_log

TUNE_GRID = tuple(float(v) for v in np.round(np.arange(1.0, 20.01, 0.5), 2))
TUNE_MARGIN = 1.0


def _alarms_by_statistic(detector, prepared) -> dict[str, list]:
    result = detector.run(
        prepared.run,
        prepared.trace,
        model=prepared.model,
        traces=prepared.traces,
        alarm_policy=prepared.profile.alarm_policy,
        raw=getattr(prepared, "raw", {}),
        metadata=prepared.log.source.metadata,
    )
    out: dict[str, list] = {}
    for alarm in result.alarms:
        out.setdefault(alarm.signal, []).append(alarm)
    return out


def _f1(labelled: Sequence, alarms_per_log: list[dict], statistics: Sequence[str], grace_s: float) -> float | None:
    tp = fp = fn = 0
    for prepared, by_check in zip(labelled, alarms_per_log):
        truth = prepared.log.truth or {}
        events = events_from_truth(truth.get("events", []), path=prepared.path)
        alarms = [a for name in statistics for a in by_check.get(name, [])]
        transients = events_from_truth(truth.get("transients", []), path=prepared.path)
        score = score_log(events, alarms, grace_s=grace_s, transients=transients)
        tp, fp, fn = tp + score.tp, fp + score.fp, fn + score.fn
    if tp == 0:
        return 0.0 if (fp or fn) else None
    return 2.0 * tp / (2.0 * tp + fp + fn)


def tune(detectors: Sequence, healthy: Sequence, labelled: Sequence = (), grace_s: float = 1.0) -> dict:
    """{detector: {parameter: {"value", "smallest_without_false_alarms", "false_alarms", "f1"}}} for
    every detector of ``detectors`` that declares multipliers (see the module docstring); the
    prepared logs come from `logscan.pipeline.preparation`."""
    out: dict = {}
    for detector in detectors:
        tunable = dict(getattr(detector, "tunable", {}) or {})
        if not tunable or not healthy:
            continue
        false_alarms = {param: [] for param in tunable}
        f1 = {param: [] for param in tunable}
        for value in TUNE_GRID:
            trial = detector.with_params(**{param: value for param in tunable})
            on_healthy = [_alarms_by_statistic(trial, p) for p in healthy]
            on_labelled = [_alarms_by_statistic(trial, p) for p in labelled]
            for param, checks in tunable.items():
                false_alarms[param].append(sum(len(by.get(c, [])) for by in on_healthy for c in checks))
                f1[param].append(_f1(labelled, on_labelled, checks, grace_s) if labelled else None)
        chosen = {}
        for param in tunable:
            counts = false_alarms[param]
            # the smallest value from which no larger one alarms either (a count can rise again)
            free = next((i for i in range(len(counts)) if all(c == 0 for c in counts[i:])), None)
            if free is None:
                chosen[param] = {"value": None, "note": f"alarms on the healthy logs up to {TUNE_GRID[-1]:g}"}
                continue
            base = TUNE_GRID[free] + TUNE_MARGIN
            ties = [i for i, v in enumerate(TUNE_GRID) if base - 1e-9 <= v <= base + TUNE_MARGIN + 1e-9]
            pick = min(ties, key=lambda i: (-(f1[param][i] or 0.0), TUNE_GRID[i])) if ties else None
            value = TUNE_GRID[pick] if pick is not None else base
            chosen[param] = {
                "value": float(value),
                "smallest_without_false_alarms": TUNE_GRID[free],
                "grid": list(TUNE_GRID),
                "false_alarms": counts,
                "f1": f1[param],
            }
        out[detector.name] = chosen
    return out


def tuned_params(tuning: dict | None, name: str) -> dict:
    """The tuned multipliers of detector ``name`` (those a value was found for)."""
    entry = (tuning or {}).get(name) or {}
    return {param: v["value"] for param, v in entry.items() if v.get("value") is not None}


def tuning_lines(tuning: dict | None) -> list[str]:
    """What `logscan train --tune` prints."""
    lines = []
    for name, params in (tuning or {}).items():
        for param, v in params.items():
            if v.get("value") is None:
                lines.append(f"  {name}.{param}: not tuned ({v.get('note', '')})")
                continue
            i = v["grid"].index(v["value"])
            f1 = v["f1"][i]
            lines.append(
                f"  {name}.{param} = {v['value']:g} (no false alarm on the healthy logs from "
                f"{v['smallest_without_false_alarms']:g}, + margin {TUNE_MARGIN:g}"
                + (f"; F1 on the labelled logs {f1:.2f}" if f1 is not None else "")
                + ")"
            )
    return lines
