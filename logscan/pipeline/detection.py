"""Run the detectors on a prepared log and turn their results into the verdict's parts: incidents,
what was not checked, the filter's consistency warnings, scores against ground truth (`detect`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

from logscan.detectors.registry import default_registry
from logscan.errors import ExitCode, LogscanError
from logscan.memory import return_freed_pages
from logscan.pipeline.analysis import Analysis, DetectorFailure
from logscan.pipeline.loops import detect_loops, recover_analysis
from logscan.pipeline.preparation import Progress
from logscan.pipeline.raw_lead import cut_to_window, led_grid, seen_from_window
from logscan.pipeline.release import (
    pack_innovations_for,
    reads_samples,
    release_unread,
    run_order,
)
from logscan.pipeline.stages import Prepared
from logscan.results import AlarmPolicy, events_from_truth
from logscan.training.calibration import calibrate_command, judged_steps, suspended_policy
from logscan.verdict.coverage import (
    Coverage,
    filter_coverage,
    heard_groups,
    judged_seconds,
    judged_share,
    judged_span,
    log_end_lines,
    own_steps,
    read_in_part,
    stopped_groups,
)
from logscan.verdict.incidents import (
    DEFAULT_GAP_S,
    alarm_onsets,
    find_incidents,
    group_of,
    input_gaps,
    inputs_of,
    merge_fragments,
    sizes_of,
)
from logscan.verdict.input_fault import kinematic_evidence
from logscan.verdict.nis_consistency import NisConsistency, nis_consistency
from logscan.verdict.observability import observability_for
from logscan.verdict.scoring import score_by_detector

if TYPE_CHECKING:
    from logscan.results import DetectorResult


def detect(
    prepared: Prepared,
    detectors: Sequence,
    *,
    grace_s: float = 1.0,
    progress: Progress | None = None,
    free_series: bool = False,
    sensor_views: bool = False,
    judged_from_s: float | None = None,
):
    """Run the detectors on a prepared log, merge their alarm fragments into incidents, say what
    could not be checked, and score the alarms when the log carries ground truth. A detector that
    raises is named in ``analysis.failures``; the others' results are kept. ``free_series``: free
    each large series once no detector still to run reads it (`release_unread`; the prepared log
    then serves no further detector). ``sensor_views``: pack the EKF's innovations, when it kept
    them, for the report (`Prepared.innovations`, `logscan.report.sensor_views`); ``judged_from_s``: `_alarm_policy`."""
    step = progress or (lambda message: None)
    free_series = free_series and prepared.profile.recovery is None  # recovery re-runs the filters
    analysis = Analysis(prepared=prepared, warnings=list(prepared.warnings))
    # when a fault of a kind could be seen at all: from the filter's states, before any is freed
    analysis.observability, why = observability_for(prepared)
    analysis.warnings += [why] if why else []
    policy = _alarm_policy(prepared, judged_from_s)
    gaps = input_gaps(prepared.trace, prepared.run)  # before the detectors free the inputs
    analysis.kinematic = kinematic_evidence(prepared.model, prepared.trace, prepared.run)  # and the innovations
    from_s = None if policy is None else policy.alarms_from_s  # a block's first step
    stopped = stopped_groups(prepared.run, None if policy is None else policy.suspended, from_s)  # and the samples
    heard = heard_groups(prepared.run, from_s)
    # the suspension holds back the model-based statistics only (`Detector.run`): said when one runs,
    # a warning, or the log is not fully checked when it kept them from most of the flight
    share = judged_share(policy, prepared.run) if any(not d.raw_topics for d in detectors) else None
    if share is not None and not share.over:
        analysis.warnings.append(share.line())
        analysis.unjudged = share.line()  # the report says it where "every check ran" would be
    analysis.results = _run_detectors(prepared, detectors, policy, analysis, free_series, sensor_views, step)
    analysis.warnings[:0] = _consistency(analysis, judged_from_s)  # first: they question every verdict
    gap_s = policy.merge_gap_s if policy is not None else DEFAULT_GAP_S
    merge_fragments(analysis.results, gap_s)
    groups = prepared.trace.group_names if prepared.trace is not None else list(prepared.run.groups)
    analysis.suspended = policy.suspended if policy is not None else None
    analysis.incidents, analysis.input_gaps = _incidents(analysis, groups, gap_s, gaps), gaps
    coverage = _coverage(prepared, policy, (stopped, heard), share)
    lines, unjudged = coverage.lines(analysis.results, judged_span(prepared.run))
    analysis.unchecked = read_in_part(prepared) + lines
    analysis.coverage = replace(coverage, said=frozenset(lines + [unjudged] if unjudged else lines))
    if prepared.loaded.model_not_run:  # its filter's detectors were not run (`filter_free`)
        model = prepared.profile.vehicle.model
        analysis.unchecked.insert(0, f"the {model} model (logscan's filter): {prepared.loaded.model_not_run}")
    if prepared.loops:  # a hierarchical profile: every further loop checked by its own detectors
        analysis.loops = detect_loops(prepared, detect=detect, grace_s=grace_s, progress=progress)
        for name, loop in analysis.loops.items():  # what a loop could not check is the log's
            analysis.unchecked += [f"loop {name}: {reason}" for reason in loop.unchecked]
            analysis.failures += [replace(f, message=f"loop {name}: {f.message}") for f in loop.failures]
            analysis.warnings += [w if w.startswith(f"loop {name}") else f"loop {name}: {w}" for w in loop.warnings]
    _score(analysis, [d.name for d in detectors], grace_s)
    if prepared.profile.recovery is not None:
        step("recovery")
        analysis.recovery = recover_analysis(analysis)
    return analysis


def _consistency(analysis: Analysis, judged_from_s: float | None) -> list[str]:
    """The consistency warnings of the run's own steps (a block's after its lead-in: the log's judge
    the blocks' sum, `block_fold`), its groups' NIS kept in ``analysis.consistency``."""
    prepared = analysis.prepared
    first = 0 if judged_from_s is None else own_steps(prepared.run.t, judged_from_s)
    analysis.consistency = _group_nis(prepared, first)
    lines = consistency_lines(analysis.consistency, prepared, analysis.results)
    if analysis.consistency is not None:
        analysis.consistency.said = frozenset(lines)
    return lines


def _incidents(analysis: Analysis, groups, gap_s: float, gaps) -> list:
    """The analysis's incidents (`find_incidents`); its kinematic evidence then cut to the alarms'
    steps, what a suppression's second look reads, not the whole log's."""
    prepared = analysis.prepared
    onsets = alarm_onsets(analysis.results, prepared.run.t, analysis.suspended)
    sizes, inputs, kinematic = sizes_of(prepared), inputs_of(prepared), analysis.kinematic
    incidents = find_incidents(analysis.results, prepared.trace, groups, gap_s, sizes, onsets, gaps, inputs, kinematic)
    if kinematic is not None:
        analysis.kinematic = kinematic.within([a for r in analysis.results for a in r.alarms])
    return incidents


def _coverage(prepared: Prepared, policy, sensors, share) -> Coverage:
    """The run's coverage in figures; ``sensors``: (`stopped_groups`, `heard_groups`), found before
    the detectors free the samples."""
    specs = getattr(prepared.profile, "measurements", None)
    facts = filter_coverage(prepared.run, prepared.trace, specs, None if policy is None else policy.alarms_from_s)
    stopped, heard = sensors
    judged_s = judged_seconds(policy, prepared.run)
    return Coverage(facts, share, stopped, judged_s, heard, tuple(log_end_lines(prepared)))


def _alarm_policy(prepared: Prepared, judged_from_s: float | None):
    """The profile's [alarms] policy on this run (`suspended_policy`); ``judged_from_s``: its alarms
    seen from then on (`logscan.alarms` rule 6), the steps before a lead-in (`logscan.pipeline.blocks`)."""
    policy = suspended_policy(prepared.profile, prepared.run, prepared.filter_from)
    return policy if judged_from_s is None else replace(policy or AlarmPolicy(), alarms_from_s=float(judged_from_s))


def _run_detectors(
    prepared: Prepared, detectors: Sequence, policy, analysis, free_series: bool, sensor_views: bool, step
):
    """The detectors' results, in the given order; a detector that raises is named in
    ``analysis.failures`` (those that read the samples first, then in the given order). They run
    in `run_order`: those that read the samples first (the frozen-sensor check), so the report's
    pack of innovations can then take the samples' buffer (`pack_innovations_for`), then so that
    each large series is freed as early as it can be."""
    order = run_order(prepared, detectors)
    listed = sorted(range(len(detectors)), key=lambda i: not reads_samples(detectors[i], prepared))
    results: dict[int, DetectorResult] = {}
    failed: dict[int, DetectorFailure] = {}
    packed = not sensor_views
    for position, index in enumerate(order):
        detector, still_to_run = detectors[index], [detectors[i] for i in order[position:]]
        if not packed and not any(reads_samples(d, prepared) for d in still_to_run):
            pack_innovations_for(prepared, still_to_run, reuse_samples=free_series)
            packed = True
        if free_series:  # the report's pack, still to come, reads the innovations and the samples
            release_unread(prepared, still_to_run, keep=frozenset() if packed else frozenset({"y", "S_diag", "z"}))
        return_freed_pages()  # what the filter or the last detector freed
        step(f"detector {detector.name}")
        try:
            result = _run_one(detector, prepared, policy)
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - one detector must not take the others down
            failed[index] = detector_failure(detector.name, exc)
            continue
        results[index] = result
    return_freed_pages()
    if not packed:  # every detector reads the samples
        pack_innovations_for(prepared, [], reuse_samples=False)
    analysis.failures += [failed[i] for i in listed if i in failed]
    return [results[i] for i in sorted(results)]


def _run_one(detector, prepared: Prepared, policy) -> DetectorResult:
    """One detector's result on the prepared run; a window's checks of the vehicle's own reports
    run from before it, their alarms seen from its first step (`logscan.pipeline.raw_lead`)."""
    lead = led_grid(prepared.run) if getattr(detector, "raw_topics", ()) else None
    result = detector.run(
        prepared.run if lead is None else lead,
        prepared.trace,
        model=prepared.model,
        log_name=prepared.path,
        traces=prepared.traces,
        alarm_policy=policy if lead is None else seen_from_window(policy, prepared.run),
        truth=prepared.log.truth,  # simulated logs' ground truth, None for real logs
        raw=prepared.raw,
        metadata=prepared.log.source.metadata,
    )
    return result if lead is None else cut_to_window(result, lead, prepared.run)


def consistency_warnings(prepared: Prepared, results: Sequence[DetectorResult] = ()) -> list[str]:
    """The filter's consistency warnings of the whole run (`NisConsistency.lines`)."""
    return consistency_lines(_group_nis(prepared), prepared, results)


def _group_nis(prepared: Prepared, first: int = 0) -> NisConsistency | None:
    """Each group's NIS at its updates from step ``first`` on, and which the [alarms] policy judges."""
    return nis_consistency(prepared.trace, judged_steps(prepared.profile, prepared.run, prepared.filter_from), first)


def consistency_lines(
    consistency: NisConsistency | None, prepared: Prepared, results: Sequence[DetectorResult]
) -> list[str]:
    """``consistency``'s warnings (`NisConsistency.lines`): a group whose checks alarmed (in
    ``results``) may be faulty over most of the log rather than mismatched; the calibrate command
    and the groups calibration kept at their noise are the profile's and tables'."""
    if consistency is None:
        return []
    groups = consistency.group_names()
    alarmed = {group_of(a.signal, groups) for r in results for a in r.alarms}
    uncalibrated: frozenset = getattr(prepared.loaded, "uncalibrated", frozenset())
    return consistency.lines(alarmed, calibrate_command(prepared.profile), uncalibrated)


def detector_failure(name: str, exc: BaseException):
    """The line and exit code of a detector that raised: its own error (its exit code), or a bug
    in that detector (exit 3), blamed on the plugin package when it comes from one."""
    origin = default_registry().origin(name) or "not registered"
    if isinstance(exc, LogscanError):
        return DetectorFailure(name, f"detector {name!r} ({origin}) failed: {exc.one_line()}", int(exc.exit_code))
    owner = "logscan" if origin == "built-in" else f"the {origin}"
    return DetectorFailure(
        name,
        f"detector {name!r} ({origin}) failed: {type(exc).__name__}: {exc} (a bug in {owner}; that "
        "detector's results are missing, the other detectors ran)",
        int(ExitCode.INTERNAL),
    )


def rescore(analysis, grace_s: float = 1.0) -> None:
    """Score the analysis again (its alarms changed: `logscan.verdict.suppressions`)."""
    names = [r.detector for r in analysis.results] + [f.detector for f in analysis.failures]
    _score(analysis, names, grace_s)


def _score(analysis, detector_names: list[str], grace_s: float) -> None:
    """Scores against the log's ground truth, when it has some."""
    prepared = analysis.prepared
    truth = prepared.log.truth
    if truth is None:
        return
    analysis.events = events_from_truth(truth.get("events", []), path=prepared.path)
    if prepared.run.window is not None:  # a window scores only the faults it overlaps
        first, last = float(prepared.run.t[0]), float(prepared.run.t[-1])
        analysis.events = [e for e in analysis.events if e.end_or_inf >= first and e.t_start <= last]
    analysis.scores = score_by_detector(
        analysis.events,
        analysis.alarms,
        duration_s=analysis.duration_s,
        grace_s=grace_s,
        transients=events_from_truth(truth.get("transients", []), path=prepared.path),
        detectors=detector_names,
        log=prepared.path,
    )
