"""A window's checks of the vehicle's own reports (`Detector.raw_topics`: health, px4_estimator)
led in before it, as its filter is (`logscan.pipeline.lead_in`).

Those checks hold an alarm for a while before they raise it (a battery under its empty voltage
for a second, at its own rate) and join exceedances a hold-off apart. Judged from a window's first
step only, what began before it starts again there: `--start 2 --end 6` of the real robologs ULog
lost the battery alarm the whole log has in it (below empty from before the window). So they run
on the full grid's steps from up to MAX_LEAD_IN_S before the window (what a window reads of an
indexed MCAP file, `logscan.pipeline.preparation`) to its end, with their alarms seen from the
window's first step on (`logscan.alarms` rule 6), and their series cut to the window.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from logscan.align.aligned import AlignedRun
from logscan.pipeline.lead_in import MAX_LEAD_IN_S
from logscan.results import AlarmPolicy, Band, DetectorResult, NotChecked


def led_grid(run: AlignedRun) -> AlignedRun | None:
    """The full grid's steps from MAX_LEAD_IN_S before ``run`` (a window) to its last, as a run
    without samples (the raw-topic checks read the log's topics, not the aligned run); None when
    ``run`` starts at the full grid's first step."""
    if run.first_step <= 0 or run.n_steps == 0:
        return None
    first = max(run.first_step - int(np.ceil(MAX_LEAD_IN_S / run.dt)), 0)
    k = np.arange(first, run.first_step + run.n_steps)
    t = run.grid_origin_s + k * run.dt  # the full grid's times, as `align` computes them
    n = t.size
    return AlignedRun(
        t=t,
        dt=run.dt,
        start_ns=run.start_ns,
        u=np.empty((n, 0)),
        u_fresh=np.ones(n, dtype=bool),
        input_channels=[],
        groups={},
        window=run.window,
        first_step=first,
        grid_origin_s=run.grid_origin_s,
    )


def seen_from_window(policy: AlarmPolicy | None, run: AlignedRun) -> AlarmPolicy:
    """``policy`` (or the default floors) with its alarms seen from ``run``'s first step on, or
    from the later time ``policy`` already sees them from (a block's own first step)."""
    policy = policy or AlarmPolicy()
    from_s = float(run.t[0]) if policy.alarms_from_s is None else max(float(run.t[0]), policy.alarms_from_s)
    return replace(policy, alarms_from_s=from_s)


def cut_to_window(result: DetectorResult, lead: AlignedRun, run: AlignedRun) -> DetectorResult:
    """``result`` (on ``lead``) with its series, bands and judged masks on ``run``'s steps only (its
    alarms are already seen from there). A statistic with samples before the window and none in it
    had nothing to judge there: not checked, as a window alone would have said (not "never
    computed", which would leave the window not fully checked); the facts in its info that carry a
    time (logged messages) only those in the window."""
    rows = slice(run.first_step - lead.first_step, run.first_step - lead.first_step + run.n_steps)
    span = (float(run.t[0]), float(run.t[-1]) + run.dt)
    return cut_rows(result, rows, span, "no sample in the --start/--end window")


def cut_rows(result: DetectorResult, rows: slice, span: tuple[float, float], empty: str | None) -> DetectorResult:
    """``result`` with its series, bands and judged masks on the grid (``rows.stop`` steps) on its
    ``rows`` only (the steps of the times ``span``), and the facts in its info that carry a time only
    those in ``span``; arrays not on the grid are left as they are. A statistic with samples
    outside ``rows`` and none in them: dropped, with the not-checked reason ``empty`` when one is
    given."""

    def cut(values):
        return values[rows] if values is not None and np.shape(values)[:1] == (rows.stop,) else values

    series = result.series
    for name in [n for n, v in series.items() if np.isfinite(v).any() and not np.isfinite(cut(v)).any()]:
        for named in (result.series, result.thresholds, result.judged, result.judged_fraction, result.judged_counts):
            named.pop(name, None)
        if empty is not None:
            result.not_checked.append(NotChecked(f"{name}: {empty}"))
    first, last = span[0] - 1e-9, span[1]
    for key, value in result.info.items():
        if isinstance(value, list) and value and all(isinstance(v, dict) and "time" in v for v in value):
            result.info[key] = [v for v in value if first <= float(v["time"]) <= last]
    result.series = {name: cut(values) for name, values in result.series.items()}
    result.extras = {name: cut(values) for name, values in result.extras.items()}
    result.judged = {name: cut(values) for name, values in result.judged.items()}
    result.thresholds = {name: Band(upper=cut(b.upper), lower=cut(b.lower)) for name, b in result.thresholds.items()}
    return result
