"""`recover`: checkpointing and roll-forward recovery of every loop's estimate during each anomaly.

Per anomaly, in time order (docs/algorithms.md section 5):
 1. k1 = the latest consistent checkpoint with t_detect - t_k1 > detection time + the slowest loop's
    period, outside every earlier anomaly;
 2. every affected loop (a specific anomaly's flagged loops; every loop for a generic one) re-runs
    the shared filter from k1 (`logscan.recovery.rerun`) up to the max_duration_s horizon: without
    the flagged groups (refilter, specific), without any measurement (rollforward, generic, replace);
 3. the anomaly ends at the flagged groups' first sample that agrees with the recovered prediction
    and holds for hold_s (`logscan.recovery.agreement`): the span ends at that sample, the hold only
    confirms it (a generic anomaly: every group, only after the alarms last showed it). After the
    alarms last showed the anomaly (`Anomaly.last_seen`: an alarm's end minus its statistic's
    window), only samples that show it keep the span open: one that disagrees without showing it
    ends the span (the recovered estimate did not re-agree), one that agrees ends it unless the
    anomaly shows again within hold_s; a generic anomaly ends hold_s after that time at the latest.
    Cut at max_duration_s. The record says why (`end_reasons`). At a span's last step, ended by a
    sample that no longer shows the anomaly, the recovered estimate takes that sample in;
 4. the recovered estimate, its k-sigma bound, T_max and the worst-case bound
    (`logscan.recovery.bounds`) fill the span [k1, end] of each affected loop.
An anomaly detected inside the previous one's recovered span merges with it (recovered again as
one, its groups joined).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from logscan.recovery.agreement import agreed_at, agreement_status, held_inputs, keep_bound, released_at
from logscan.recovery.anomalies import join
from logscan.recovery.bounds import k_sigma_bound, t_max, worst_case
from logscan.recovery.checkpoints import (
    Checkpoints,
    consistent_checkpoints,
    loop_times,
    select_checkpoint,
    slowest_period,
)
from logscan.recovery.records import (
    Anomaly,
    AnomalyRecord,
    LoopRecovery,
    LoopRun,
    Recovery,
    RecoverySettings,
)
from logscan.recovery.rerun import full_P, replace_mask, rerun, take_in_last
from logscan.recovery.validate import allowed_states, check_anomalies, check_loops
from logscan.traces import EkfTrace


@dataclass
class _Context:
    loops: list[LoopRun]
    times: list[np.ndarray]
    checkpoints: Checkpoints
    margin_s: float
    settings: RecoverySettings
    allowed: dict[str, dict[int, float]]  # loop -> state index -> E


@dataclass
class _LoopPart:
    """One loop's re-run for one anomaly: slice [k1, k_stop], its trace and flagged groups."""

    loop: LoopRun
    t: np.ndarray  # the slice's times (common frame)
    k1: int
    part: EkfTrace  # the re-run of the slice
    flagged: tuple[str, ...]


def recover(
    loops: Sequence[LoopRun], anomalies: Sequence[Anomaly], settings: RecoverySettings | None = None
) -> Recovery:
    """Recover every loop's estimate during ``anomalies``; see the module docstring."""
    loops = list(loops)
    settings = settings or RecoverySettings()
    check_loops(loops)
    check_anomalies(anomalies, loops)
    times = loop_times(loops)
    ctx = _Context(
        loops,
        times,
        consistent_checkpoints(loops, settings.checkpoint_period_s, settings.consistency_tol_s),
        settings.detection_time_s + slowest_period(loops),
        settings,
        allowed_states(settings.allowed_error, loops),
    )
    out = {lp.name: _empty(lp, t) for lp, t in zip(loops, times)}
    records: list[AnomalyRecord] = []
    blocked: list[tuple[float, float]] = []
    queue = sorted(anomalies, key=lambda a: (a.t_detect, a.t_end))
    i = 0
    while i < len(queue):
        anomaly, record, fills, j = _recover_merging(queue, i, ctx, blocked)
        for name, k1, x, bound, worst in fills:
            span = slice(k1, k1 + x.shape[0])
            out[name].x_recovered[span], out[name].bound[span], out[name].worst_case[span] = x, bound, worst
        records.append(record)
        blocked.append((anomaly.t_detect - ctx.margin_s, _span_end(record, anomaly)))
        i = j
    return Recovery(out, records, settings)


def _recover_merging(queue: list[Anomaly], i: int, ctx: _Context, blocked):
    """(anomaly, record, fills, next index): queue[i] recovered, merged with every later anomaly
    detected inside its recovered span. A loop's span then ends only when its sensors agree after
    the latest detection that flags it (the consistent checkpoint lies before the first)."""
    anomaly, j = queue[i], i + 1
    latest = {lp.name: anomaly.t_detect for lp in ctx.loops if anomaly.targets is None or anomaly.targets.get(lp.name)}
    record, fills = _recover_one(anomaly, ctx, blocked, latest)
    while j < len(queue) and queue[j].t_detect <= _span_end(record, anomaly):
        nxt = queue[j]
        for lp in ctx.loops:
            if nxt.targets is None or nxt.targets.get(lp.name):
                latest[lp.name] = nxt.t_detect
        anomaly = join(anomaly, nxt)
        j += 1
        record, fills = _recover_one(anomaly, ctx, blocked, latest)
    record.merged = j - i
    return anomaly, record, fills, j


def _span_end(record: AnomalyRecord, anomaly: Anomaly) -> float:
    return record.t_recovered_end if record.t_recovered_end is not None else anomaly.t_end


def _empty(loop: LoopRun, t: np.ndarray) -> LoopRecovery:
    shape = (loop.run.n_steps, loop.model.n_states)
    nan = np.full(shape, np.nan)
    return LoopRecovery(loop.name, list(loop.model.state_names), t, nan, nan.copy(), nan.copy())


def _recover_one(anomaly: Anomaly, ctx: _Context, blocked, latest: dict[str, float]) -> tuple[AnomalyRecord, list]:
    """The record of one anomaly and its fills (loop, k1, x, bound, worst case); ``latest``: loop ->
    the latest detection flagging it (merged anomalies)."""
    s = ctx.settings
    affected = [lp for lp in ctx.loops if anomaly.targets is None or anomaly.targets.get(lp.name)]
    record = AnomalyRecord(
        anomaly.t_detect,
        anomaly.t_end,
        None if anomaly.targets is None else {k: tuple(v) for k, v in anomaly.targets.items() if v},
        s.method,
        tuple(lp.name for lp in affected),
    )
    index = select_checkpoint(ctx.checkpoints, anomaly.t_detect, ctx.margin_s, blocked)
    if index is None:
        record.note = (
            f"not recovered: no consistent checkpoint more than {ctx.margin_s:g} s before "
            f"{anomaly.t_detect:g} s and outside earlier anomalies"
        )
        return record, []
    record.t_checkpoint = float(ctx.checkpoints.t[index])
    record.checkpoint_steps = ctx.checkpoints.step_of(index)
    t_cap = anomaly.t_detect + s.max_duration_s
    parts = [_rerun_loop(lp, record.checkpoint_steps[lp.name], t_cap, anomaly, ctx) for lp in affected]
    ends, agreed, reasons, honest = _loop_ends(anomaly, parts, s, latest)
    record.t_agreed = None if any(a is None for a in agreed) else max(agreed)
    take_in = {}
    for p, end, reason, sample in zip(parts, ends, reasons, honest):
        t_log_end = float(ctx.times[ctx.loops.index(p.loop)][-1])
        if end >= t_cap and t_log_end >= t_cap:
            record.capped, reason, sample = True, f"cut at max_duration_s = {s.max_duration_s:g} s", False
        if end > t_log_end and t_log_end < t_cap:
            record.note = reason = "the anomaly lasts until the end of the log"
            sample = False
        take_in[p.loop.name] = sample
        record.loop_ends[p.loop.name] = min(end, t_cap, t_log_end)
        record.end_reasons[p.loop.name] = reason
    end = max(record.loop_ends.values())
    record.t_recovered_end = end
    record.rollforward_s = end - record.t_checkpoint
    record.alarm_kept = end > anomaly.t_end
    fills = [_fill(p, record.loop_ends[p.loop.name], ctx, take_in[p.loop.name]) for p in parts]
    for p in parts:
        duration = record.loop_ends[p.loop.name] - anomaly.t_detect
        for state, T in _t_max(p, anomaly, ctx).items():
            record.t_max[state] = T
            if T is not None and duration > T:
                record.outlasted += (state,)
    return record, fills


def _rerun_loop(loop: LoopRun, k1: int, t_cap: float, anomaly: Anomaly, ctx: _Context) -> _LoopPart:
    t_loop = ctx.times[ctx.loops.index(loop)]
    k_stop = max(k1, int(np.searchsorted(t_loop, t_cap + 1e-9, side="right")) - 1)
    groups = tuple(loop.run.groups)
    flagged = groups if anomaly.targets is None else tuple(anomaly.targets[loop.name])
    excluded = flagged if (anomaly.targets is not None and ctx.settings.method == "refilter") else groups
    part = rerun(loop, k1, k_stop, excluded)
    return _LoopPart(loop, t_loop[k1 : k_stop + 1], k1, part, flagged)


def _loop_ends(anomaly: Anomaly, parts: list[_LoopPart], s: RecoverySettings, latest) -> tuple[list, ...]:
    """Per loop: (end of its span, uncut; when its flagged groups agreed again, None if that did
    not end it; why; whether a sample that no longer shows the anomaly ended it). A specific
    anomaly's span ends at the first sample after the loop's latest detection that agrees and
    holds for hold_s (the hold only confirms it). After the alarms last showed the anomaly
    (`Anomaly.last_seen`: an alarm's end minus its window) only samples that show it keep the span
    open: it ends at the first that does not, unless one shows it again within hold_s
    (`released_at`); a generic anomaly's at most hold_s after its alarms last showed it on any
    loop. inf if nothing ends it."""
    budget = (s.budget_per_hour, s.proof_hours)
    generic = anomaly.targets is None
    ends, agreed, reasons, honest = [], [], [], []
    for p in parts:
        t_from = latest.get(p.loop.name, anomaly.t_detect)
        t_seen = max(anomaly.last_seen(p.loop.name), t_from)
        status = agreement_status(p.loop, p.k1, p.part, p.flagged, s.agreement_quantile, budget)
        t_agreed = None if generic else agreed_at(p.t, status, t_from, s.hold_s)
        end, reason = np.inf, ""
        held = f"{', '.join(p.flagged)} agreed with the recovered estimate again, held {s.hold_s:g} s"
        if t_agreed is not None:
            end, reason = t_agreed, held
        released = released_at(p.t, status, t_seen, s.hold_s)
        if released is not None and released[0] < end:
            end, ok = released
            t_agreed, reason = (end, held) if ok else (None, _not_reagreed(p, end, budget, s.hold_s))
        sample = bool(np.isfinite(end))
        t_last = max(anomaly.last_seen_anywhere(), t_from)
        if generic and t_last + s.hold_s < end:
            t_agreed, end, reason = None, t_last + s.hold_s, _after_alarm(anomaly, t_last, s.hold_s)
            sample = False
        ends.append(end)
        agreed.append(t_agreed)
        reasons.append(reason)
        honest.append(sample)
    return ends, agreed, reasons, honest


def _after_alarm(anomaly: Anomaly, t_seen: float, hold_s: float) -> str:
    if t_seen >= anomaly.t_end:
        return f"{hold_s:g} s after the detector's alarm"
    return f"{hold_s:g} s after the detector's alarm last showed the anomaly (its end minus its window, {t_seen:.2f} s)"


def _not_reagreed(p: _LoopPart, t: float, budget: tuple[float, float], hold_s: float) -> str:
    bounds = ", ".join(f"{g} {keep_bound(p.loop, g, budget):.1f}" for g in p.flagged)
    return (
        f"did not re-agree: from {t:.2f} s, after the detector's alarm last showed the anomaly, {p.loop.name} "
        f"{', '.join(p.flagged)} showed no anomaly (NIS within the false-alarm budget's bound, {bounds}) but "
        f"disagreed with the recovered estimate within {hold_s:g} s: the recovered estimate is the one off"
    )


def _fill(p: _LoopPart, end: float, ctx: _Context, take_in: bool = False):
    """(loop, k1, x, bound, worst case) over the loop's steps k1..end; ``take_in``: the sample at
    the end no longer shows the anomaly, so the recovered estimate there takes it in (`take_in_last`)."""
    s = ctx.settings
    J = max(1, int(np.searchsorted(p.t, end + 1e-9, side="right")))
    x, P = p.part.x_post[:J], full_P(p.part)[:J]
    if take_in and J >= 2:
        x, P = take_in_last(p.loop, p.k1, p.part, J)
    bound = k_sigma_bound(P, s.k_sigma)
    tr = p.loop.trace
    if s.method == "replace" and set(p.flagged) != set(p.loop.run.groups):
        # the paper's element replacement: roll-forward values where K g != 0, the EKF's elsewhere
        gains = rerun(p.loop, p.k1, p.k1 + J - 1, (), store_gain=True)
        mask = replace_mask(gains, p.flagged)
        span = slice(p.k1, p.k1 + J)
        ekf_bound = s.k_sigma * np.sqrt(np.maximum(np.asarray(tr.P_post_diag[span], dtype=np.float64), 0.0))
        x = np.where(mask, x, tr.x_post[span])
        bound = np.where(mask, bound, ekf_bound)
    u = held_inputs(np.asarray(p.loop.run.u[p.k1 : p.k1 + J], dtype=np.float64))
    worst = worst_case(p.loop.model, p.loop.run.dt, p.part.x_post[:J], u, tr.P_post[p.k1], tr.Q, s.k_sigma)
    return p.loop.name, p.k1, x, bound, worst


def _t_max(p: _LoopPart, anomaly: Anomaly, ctx: _Context) -> dict[str, float | None]:
    """ "loop.state" -> T_max of the loop's states with an allowed error, from the bound over the
    whole re-run."""
    allowed = ctx.allowed.get(p.loop.name, {})
    if not allowed:
        return {}
    found = t_max(p.t, k_sigma_bound(p.part.P_post, ctx.settings.k_sigma), allowed, anomaly.t_detect)
    names = p.loop.model.state_names
    return {f"{p.loop.name}.{names[i]}": value for i, value in found.items()}
