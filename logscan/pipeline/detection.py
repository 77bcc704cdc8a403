"""Run the detectors on a prepared log and turn their results into the verdict's parts: incidents,
what was not checked, the filter's consistency warnings, scores against ground truth (`detect`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

from logscan.detectors.registry import default_registry
from logscan.docs import doc_url
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
    analysis.warnings[:0] = consistency_warnings(prepared, analysis.results)  # first: they question every verdict
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


# A group's NIS far from its chi-square law on a whole log: the filter's model of it is wrong. The
# median NIS over its updates against the chi-square median of its size (robust: a fault over less
# than half of the log does not move it). Above NIS_MISMATCH times, the samples disagree with the
# prediction far beyond their noise (units, signs, frames, a wrong channel); below 1 / NIS_MISMATCH**2
# its noise_std dwarfs the data's scatter, so a fault of that size hides. Checked only with enough
# updates to mean something.
NIS_MISMATCH = 10.0


NIS_MIN_UPDATES = 20


# A group whose mean NIS per output over the judged updates is below NIS_BLIND is blind: its test
# is looser than the data by more than 1 / sqrt(NIS_BLIND) (1.8x) in std, so a fault of that size
# hides and the verdict says so (healthy: [NIS_BLIND, 1 / NIS_BLIND], about 1 expected).
NIS_BLIND = 0.3
# A blind group's NIS scaled to a mean of 1 per output that passes its chi-square TAIL_ALPHA point on
# more updates than a chi-square law would by chance (binomial P < TAIL_P) has a scatter that varies
# over the log: no one noise_std fits, and lowering it (the usual advice) alarms on the larger
# stretches (the real Husky drive: 81 of 3951 wheel yaw rate updates against 4 expected).
TAIL_ALPHA = 0.001
TAIL_P = 0.001


def consistency_warnings(prepared: Prepared, results: Sequence[DetectorResult] = ()) -> list[str]:
    """One warning per measurement group whose median NIS is far from the chi-square median of its
    size (see NIS_MISMATCH); the ratio is given per output. A group far above it whose own checks
    alarmed (in ``results``) may be faulty over most of the log rather than mismatched: said so,
    and calibrating it is advised only on healthy logs (it would widen the noise over the fault)."""
    import numpy as np
    from scipy.special import chdtri  # chi-square quantiles without scipy.stats (46 MB to import)

    trace = prepared.trace
    if trace is None or trace.nis_group is None:
        return []
    out = []
    judged = judged_steps(prepared.profile, prepared.run, prepared.filter_from)
    groups = list(trace.group_names)
    alarmed = {group_of(a.signal, groups) for r in results for a in r.alarms}
    for g, (name, size) in enumerate(zip(trace.group_names, trace.group_sizes.tolist())):
        nis = trace.nis_group[:, g]  # a column view: a mask picks from it a few times faster than [used, g]
        used = trace.updated[:, g] & np.isfinite(nis)
        if int(used.sum()) < NIS_MIN_UPDATES or not size:
            continue
        ratio = float(np.median(nis[used])) / float(chdtri(size, 0.5))
        if ratio > NIS_MISMATCH and name in alarmed:
            out.append(
                f"group {name!r}: median NIS {ratio:.3g} times its chi-square median (about 1 expected), and its "
                "checks alarmed: a fault over much of the log (the incidents below), or a model or profile "
                "mismatch (units, signs, frames, noise_std) if the log is healthy; calibrate only on healthy logs "
                f"({doc_url('troubleshooting.md')})"
            )
        elif ratio > NIS_MISMATCH:
            out.append(
                f"group {name!r}: median NIS {ratio:.3g} times its chi-square median (about 1 expected): model or "
                "profile mismatch, check units, signs and frames of its channels, or its noise_std "
                f"({doc_url('troubleshooting.md')}; `{calibrate_command(prepared.profile)}`, then --tables tables.json)"
            )
        else:
            out.extend(_blind_warning(prepared, g, name, size, used, judged))
    return out


def _blind_warning(prepared: Prepared, g: int, name: str, size: int, used, judged) -> list[str]:
    """The "blind" warning of group ``g`` when its mean NIS per output is below NIS_BLIND over the
    ``judged`` updates (`judged_steps`; all of ``used`` when fewer than NIS_MIN_UPDATES are judged)."""
    import numpy as np

    if judged is not None and int((used & judged).sum()) >= NIS_MIN_UPDATES:
        used = used & judged
    trace = prepared.trace
    assert trace is not None and trace.nis_group is not None  # `consistency_warnings` checked
    nis = trace.nis_group[:, g][used]
    level = float(np.mean(nis)) / size
    if not level < NIS_BLIND:
        return []
    tail = _heavy_tail(nis, size, level)
    if tail is not None:
        return [
            f"group {name!r} is blind most of the time: mean NIS per output {level:.3g} over {nis.size} updates "
            f"(about 1 expected, {NIS_BLIND:g} at the least), but its NIS is not one scaled chi-square: fitted to "
            f"that mean, {tail[0]} of them would pass its {TAIL_ALPHA:.1%} point ({tail[1]:.2g} expected). Its "
            "scatter varies over the log (quiet stretches and larger ones: at rest and moving, or a fault), so no "
            "one noise_std fits it: a smaller one alarms on the larger stretches, and a fault smaller than the "
            "present one hides in the quiet ones"
        ]
    kept = name in getattr(prepared.loaded, "uncalibrated", frozenset())
    return [
        f"group {name!r} is blind: mean NIS per output {level:.3g} over {int(used.sum())} updates (about 1 "
        f"expected, {NIS_BLIND:g} at the least): its noise_std is {1.0 / np.sqrt(level):.3g} times the scatter "
        "the filter sees, so a fault of that size hides; "
        + (
            "the tables' calibration found no noise_std that brings it to 1 (see their training report)"
            if kept
            else f"lower noise_std: `{calibrate_command(prepared.profile)}`, then analyze with --tables tables.json"
        )
    ]


def _heavy_tail(nis, size: int, level: float) -> tuple[int, float] | None:
    """(how many updates, how many expected) pass the chi-square TAIL_ALPHA point of ``size`` once
    the NIS is scaled to a mean of 1 per output, when that count is beyond chance for a chi-square
    law (binomial P(K >= k) < TAIL_P: a scatter that varies, not one noise); else None."""
    import numpy as np
    from scipy.special import bdtrc, chdtri

    k = int(np.count_nonzero(nis / level > chdtri(size, TAIL_ALPHA)))
    if k == 0 or not bdtrc(k - 1, nis.size, TAIL_ALPHA) < TAIL_P:
        return None
    return k, nis.size * TAIL_ALPHA


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
