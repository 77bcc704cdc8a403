"""The further control loops of a hierarchical profile (``[loops.<name>]``), each prepared and
checked like a log of its own: its model, its rate, its inputs and sensors, the shared filters run
on it once, and its own detectors (from its ``[detectors]`` table, else the registry's defaults).

`logscan.pipeline.preparation` calls `prepare_loops` on the log it read once (the profile's topics
include every loop's channels) before the samples are released; `detect` runs `detect_loops`
(handing it itself: this module sits below the pipeline and never imports it) and the recovery
stage reads the loops' traces (`logscan.recovery`).
"""

from __future__ import annotations

import shlex
from collections.abc import Callable
from typing import Any

from logscan.align import align
from logscan.detectors.base import END_DELAY_KEY
from logscan.errors import LogscanError
from logscan.models import get_model
from logscan.needs import Needs
from logscan.pipeline.stages import FILTERS, LoadedProfile, Prepared, create_detectors, needs_of
from logscan.profiles.loops import ORACLE
from logscan.recovery import LoopRun, RecoverySettings, anomalies_from_alarms, anomalies_from_truth, recover
from logscan.report.recovery_view import recovery_view, true_states
from logscan.verdict.incidents import group_of

#: what recovery needs of every loop's EKF: the full covariance at the checkpoints
RECOVERY_NEEDS = Needs.of(ekf=("P",))


def loop_detectors(loaded) -> list:
    """The detectors a loop runs (its own [detectors] table, else the defaults)."""
    return create_detectors(loaded)


def prepare_loops(primary, log, *, start_s=None, end_s=None, step: Callable[[str], None]) -> dict:
    """Loop name -> Prepared for every further loop of ``primary.profile`` (aligned and filtered)."""
    profile = primary.profile
    extra = RECOVERY_NEEDS if profile.recovery is not None else Needs()
    loops = {}
    for name, loop in profile.loops.items():
        loaded = LoadedProfile(loop, text="", source=f"{primary.loaded.source} [loops.{name}]")
        model = get_model(loop.vehicle.model, loop.vehicle.params)
        step(f"aligning loop {name}")
        run = align(log, loop, start_s=start_s, end_s=end_s)
        if run.n_steps < 2:
            raise LogscanError(
                f"loop {name!r}: too few samples on its analysis grid to filter",
                path=primary.path,
                hint=f"check [loops.{name}]'s channels and rate_hz: `logscan inspect {shlex.quote(primary.path)}`",
            )
        prepared = Prepared(path=primary.path, log=log, loaded=loaded, model=model, run=run)
        prepared.warnings.extend(f"loop {name}: {w}" for w in run.warnings)
        wanted = needs_of(loop_detectors(loaded))(run) | extra
        for filter_name, parts in wanted.filters.items():
            step(f"filtering loop {name}")
            prepared.traces[filter_name] = FILTERS[filter_name](model, run, frozenset(parts))
        for episode in prepared.trace.divergence_episodes if prepared.trace is not None else ():
            prepared.warnings.append(f"loop {name}: filter diverged: {episode}")
        loops[name] = prepared
    return loops


def detect_loops(prepared, *, detect: Callable[..., Any], grace_s: float, progress=None) -> dict:
    """Loop name -> the Analysis of that loop (its detectors on its own run, by ``detect``: the
    pipeline's per-log detection step, `logscan.pipeline.detection`, which calls this)."""
    return {
        name: detect(loop, loop_detectors(loop.loaded), grace_s=grace_s, progress=progress)
        for name, loop in prepared.loops.items()
    }


def loop_runs(prepared) -> list:
    """Every loop of a prepared log, the primary first, as the recovery engine takes them."""
    pairs = [(prepared.profile.loop_name, prepared), *prepared.loops.items()]
    return [LoopRun(name, one.model, one.run, one.trace) for name, one in pairs]


def _sensor_alarms(alarms: list, groups: list[str]) -> list:
    """The alarms without those of a statistic over every sensor (``nis.all``) that an alarm naming
    a sensor overlaps: that one says which sensors to leave out, the sum only that something is off
    (kept alone, it would make the anomaly generic: every sensor left out)."""
    named = [a for a in alarms if group_of(a.signal, groups) is not None]
    return named + [
        a
        for a in alarms
        if group_of(a.signal, groups) is None and not any(n.start <= a.end and a.start <= n.end for n in named)
    ]


def _end_delays(results: list, detector: str | None) -> dict[tuple[str, str], float]:
    """(detector, statistic) -> the end delay each chosen detector declared (`Detector.end_delays`)."""
    return {
        (r.detector, signal): float(delay)
        for r in results
        if detector in (None, r.detector)
        for signal, delay in (r.info.get(END_DELAY_KEY) or {}).items()
        if delay is not None
    }


def recover_analysis(analysis):
    """The profile's [recovery] over every loop: the anomalies of its detector's alarms (or of the
    ground truth, `detector = "oracle"`), each recovered from a consistent checkpoint
    (`logscan.recovery.recover`). None, with a warning, when the oracle has no truth to read."""
    spec = analysis.profile.recovery
    settings = RecoverySettings(**spec.settings)
    loops = loop_runs(analysis.prepared)
    if any(loop.trace is None or loop.trace.P_post is None for loop in loops):
        analysis.warnings.append("recovery skipped: a loop's filter kept no covariance (no EKF ran)")
        return None
    if spec.detector == ORACLE:
        if analysis.prepared.log.truth is None:
            analysis.warnings.append('recovery skipped: detector = "oracle" needs the log\'s ground truth')
            return None
        anomalies = anomalies_from_truth(analysis.events, settings.detection_time_s, loops)
    else:
        analyses = {loops[0].name: analysis, **analysis.loops}
        alarms = {
            loop.name: _sensor_alarms(
                [a for r in analyses[loop.name].results if spec.detector in (None, r.detector) for a in r.alarms],
                list(loop.run.groups),
            )
            for loop in loops
        }
        delays = {loop.name: _end_delays(analyses[loop.name].results, spec.detector) for loop in loops}
        anomalies = anomalies_from_alarms(alarms, loops, end_delays=delays)
    recovery = recover(loops, anomalies, settings)
    truths = true_states(analysis.path, analysis.prepared.log.truth, loops)  # a simulated log's
    analysis.recovery_view = recovery_view(loops, recovery, settings.k_sigma, truths)  # before the series go
    return recovery
