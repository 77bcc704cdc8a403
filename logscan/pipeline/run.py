"""The pipeline of one log: `prepare` (profile, read, align, each needed filter run once) and `detect`.

    profile = load_profile_for(path, profile_path)           # the file, or the log's embedded one
    detectors = create_detectors(profile)                      # parameters checked: no log read yet
    prepared = prepare(path, profile, needs_of(detectors))    # read only the needed topics, align, filter
    analysis = detect(prepared, detectors)                    # DetectorResults, scores against truth

With `logscan.fleet` this is the only module that sees every layer. Training and evaluation call
`prepare` and then fit or score; no module outside `detectors/` names a detector: each declares
what it needs (`Detector.needs`) and the pipeline runs the union of those needs.
"""

from __future__ import annotations

import os
import shlex
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from logscan.docs import doc_url
from logscan.errors import InputError, LogscanError, ProfileError
from logscan.needs import Needs
from logscan.pipeline.loops import RECOVERY_NEEDS, detect_loops, prepare_loops, recover_analysis
from logscan.pipeline.stages import FILTERS, LoadedProfile, Prepared, create_detectors, needs_of
from logscan.training.tables import apply_tables, read_tables_document, tables_path

Progress = Callable[[str], None]


# The large per-step series a detector declares it reads (`Detector.reads`): each is freed once no
# detector still to run reads it. What runs after the detectors (incidents, coverage, the summary)
# reads none of them.
RELEASABLE_TRACE = ("x_prior", "x_post", "P_prior_diag", "P_post_diag", "y", "S_diag", "K", "S", "P_prior", "P_post")
# "z": the measurement groups' samples; "redundant": the [redundant] groups' readings
RELEASABLE_RUN = ("onboard_state", "onboard_variance", "u", "z", "mode", "redundant")
RELEASABLE = frozenset(RELEASABLE_TRACE + RELEASABLE_RUN)


def load_profile_for(path: str | os.PathLike, profile_path: str | os.PathLike | None) -> LoadedProfile:
    """The profile of a log: the file given, else the one the log embeds (a metadata-only read), else
    the built-in profile of a log that names itself (a PX4 ULog: `logscan.profiles.builtin`)."""
    from logscan.profiles import load_profile, parse_profile
    from logscan.readers import read_embedded_profile

    if profile_path is not None:
        profile = load_profile(profile_path)
        return LoadedProfile(profile, profile.to_toml(), str(profile_path))
    embedded = read_embedded_profile(path)
    if not embedded:
        found = builtin_profile_for(path, with_log=True)
        if found is not None:
            built, log, extra = found
            try:
                profile = parse_profile(built.text, source=f"{path} (built-in profile {built.name})")
            except ProfileError:
                if not built.model_not_run:
                    raise
                # the log's topics could not complete the profile: say why, keep its text to edit
                error = InputError(
                    built.model_not_run,
                    path=str(path),
                    hint=f"`logscan init-profile {shlex.quote(str(path))} -o profile.toml` writes it to complete",
                )
                error.profile_text = built.text
                raise error from None
            notes = [f"built-in profile {built.name}: {note}" for note in built.notes]
            loaded = LoadedProfile(profile, built.text, f"built-in {built.name}", notes, log, extra)
            loaded.model_not_run = built.model_not_run
            return loaded
        raise ProfileError(
            "no profile: the log embeds none",
            path=str(path),
            hint=f"pass --profile PROFILE.toml (see {doc_url('profiles.md')})",
        )
    return LoadedProfile(parse_profile(embedded, source=f"{path} (embedded profile)"), embedded, "embedded")


def builtin_profile_for(path: str | os.PathLike, *, with_log: bool = False):
    """The built-in profile (`logscan.profiles.builtin.BuiltProfile`) of a log that names itself (a
    PX4 ULog, a ROS log), else None; reads only the topics the built-in profile may use, plus
    those any detector reads from the log itself (`Detector.raw_topics`) and the report's states.
    ``with_log``: (profile, the log read, those extra topics), so the analysis need not read it
    again."""
    from logscan.profiles import builtin, ros
    from logscan.readers import detect_format, read_log
    from logscan.readers.csv_reader import csv_log_name

    fmt = None if path is None else detect_format(path)
    extra = _extra_topics()
    if fmt in builtin.ROS_FORMATS:  # a ROS log: its topic list first, then only the topics the profile may use
        schemas = builtin.topic_schemas(path, fmt)
        if not any(ros.is_ros_topic(*value) for value in schemas.values()):
            return None
        # the extra topics the file has (its topic list names them all: the others are covered too)
        log = read_log(path, topics=set(ros.ros_candidate_topics(schemas)) | (extra & set(schemas)))
        built = ros.ros_profile(log) if builtin.identify(log) == "ros" else None
    elif fmt == "ulog" or (fmt == "csv-dir" and csv_log_name(Path(path))):  # a ULog, or ulog2csv's pieces of one
        log = read_log(path, topics=set(builtin.PX4_TOPICS) | extra)
        built = builtin.px4_profile(log) if builtin.identify(log) == "px4" else None
    else:
        return None
    if built is None or not with_log:
        return built
    return built, log, extra


def _extra_topics() -> frozenset[str]:
    """Every topic a registered detector reads from the log itself, and the report's states."""
    from logscan.detectors.registry import default_registry
    from logscan.report.run_context import STATE_TOPICS
    from logscan.timebase.clock import GNSS_UTC_CHANNELS

    registry = default_registry()
    extra = frozenset(STATE_TOPICS) | frozenset(GNSS_UTC_CHANNELS)
    return raw_topics_of([registry.get(name) for name in registry.names()]) | extra


def filter_free(detectors: Sequence, loaded: LoadedProfile, path) -> list:
    """``detectors``, less those that need a filter when the profile's model cannot run on the log
    (`LoadedProfile.model_not_run`: the verdict lists the model as not checked); an InputError
    when none is left."""
    if not loaded.model_not_run:
        return list(detectors)
    kept = [d for d in detectors if not d.needs(None).filters]
    if not kept:
        names = ", ".join(d.name for d in detectors)
        raise InputError(
            f"{loaded.model_not_run}; {names} need{'s' if len(detectors) == 1 else ''} its filter",
            path=str(path),
            hint="run the checks without a filter (-d health -d px4_estimator), or pass --profile with another model",
        )
    return kept


def raw_topics_of(detectors: Sequence) -> frozenset[str]:
    """The source topics the detectors read from the log itself (`Detector.raw_topics`)."""
    return frozenset(topic for detector in detectors for topic in getattr(detector, "raw_topics", ()))


def raw_channels(log, topics: frozenset[str]) -> dict:
    """The log's channels under ``topics`` (``/topic/field`` or ``topic/field``), as read."""
    if not topics:
        return {}
    return {
        name: channel
        for name, channel in log.channels.items()
        if name.lstrip("/").split("/", 1)[0] in topics or name in topics
    }


def prepare(
    path: str | os.PathLike,
    loaded: LoadedProfile,
    needs: Needs | Callable[[Any], Needs],
    *,
    use_header_stamp: bool = False,
    progress: Progress | None = None,
    notice: Progress | None = None,
    start_s: float | None = None,
    end_s: float | None = None,
    raw_topics: frozenset[str] = frozenset(),
    truth_path: str | os.PathLike | None = None,
) -> Prepared:
    """Read only the topics the profile needs (and the detectors' ``raw_topics``, kept unaligned in
    ``Prepared.raw``), align them, and run each filter the needs ask for exactly once. ``needs``
    may be a function of the aligned run (needs can follow what the log holds, e.g. K and S only
    when it carries no on-board variances). ``notice`` hears the one
    line a user should see even without progress (the first run's compile). ``start_s``/``end_s``
    (seconds since the log's start) analyse a window of it. Raises LogscanError on bad input."""
    from logscan.align import align
    from logscan.log import MAX_SPAN_S
    from logscan.models import get_model
    from logscan.readers import read_log
    from logscan.report.run_context import STATE_TOPICS, run_context
    from logscan.timebase.clock import GNSS_UTC_CHANNELS, clock_of

    step = progress or (lambda message: None)
    path = str(path)
    profile = loaded.profile
    model = get_model(profile.vehicle.model, profile.vehicle.params)
    model.process_noise_scale = loaded.process_noise_scale  # read by every EKF run on it (pack_run)
    compiling = _start_compile(model, needs, notice)
    step("reading")
    # the autopilot's states for the report, and a ULog's GNSS time (its UTC), when the log has them
    context_topics = set(STATE_TOPICS) | set(GNSS_UTC_CHANNELS)
    log, loaded.log = loaded.log, None  # a built-in profile's log, read once (`load_profile_for`)
    if log is None or use_header_stamp or not set(raw_topics) | context_topics <= loaded.log_extra_topics:
        wanted = profile.topics() | set(raw_topics) | context_topics
        log = read_log(path, topics=wanted, use_header_stamp=use_header_stamp)
    _attach_truth(log, path, truth_path)
    profile.check_channels(log)
    step("aligning")
    run = align(log, profile, start_s=start_s, end_s=end_s)
    if run.n_steps < 2:
        raise LogscanError(
            "too few samples on the analysis grid to filter",
            path=path,
            hint=f"check the profile's channels and rate_hz against `logscan inspect {shlex.quote(path)}`",
        )
    raw = raw_channels(log, raw_topics)  # kept as read: the detectors that asked for them read them
    context = run_context(run, model, log)  # the report's context, from the samples about to go
    prepared = Prepared(path=path, log=log, loaded=loaded, model=model, run=run, context=context, raw=raw)
    prepared.clock = clock_of(log, run.start_ns)  # dated while the GNSS time is still there
    if profile.loops:
        prepared.loops = prepare_loops(prepared, log, start_s=start_s, end_s=end_s, step=step)
    log.release_samples()  # the run holds what the filters and detectors read from here on
    wanted = needs(run) if callable(needs) else needs
    if loaded.model_not_run and wanted.filters:  # the filter-free detectors only (`filter_free`)
        raise InputError(loaded.model_not_run, path=path, hint="pass --profile with a model this log can drive")
    if profile.recovery is not None:
        wanted = wanted | RECOVERY_NEEDS
    prepared.warnings.extend(loaded.notes)  # first: what the profile is built from frames what follows
    span_warning = log.span_warning()
    if span_warning and run.n_steps * run.dt <= MAX_SPAN_S:  # outlying times dropped at alignment
        prepared.warnings.extend(w for w in log.source.warnings if w != span_warning)
    else:
        prepared.warnings.extend(log.source.warnings)
    prepared.warnings.extend(run.warnings)
    if log.source.partial:
        prepared.warnings.append(f"partial read: {log.source.partial_reason}")
    for name, parts in wanted.filters.items():
        if name not in FILTERS:
            raise ProfileError(
                f"a detector needs the filter {name!r}, which this logscan does not have",
                hint=f"known filters: {', '.join(FILTERS)}",
            )
        step("filtering")
        compiling.wait()
        prepared.traces[name] = FILTERS[name](model, run, frozenset(parts))
    ekf = prepared.trace
    for episode in ekf.divergence_episodes if ekf is not None else ():
        prepared.warnings.append(f"filter diverged: {episode}")
    return prepared


def _attach_truth(log, path: str, truth_path) -> None:
    """Ground truth from ``truth_path`` (--truth), else the log's own, else `<log>.truth.json`
    beside it; UTC event times turned into the log's seconds (`logscan.verdict.truth`)."""
    from logscan.verdict.truth import in_log_time, read_truth_file, truth_beside

    source = truth_path if truth_path is not None else (truth_beside(path) if log.truth is None else None)
    if source is not None:
        log.truth = read_truth_file(source)
    if log.truth is not None:
        log.truth = in_log_time(log.truth, log.start_ns, str(source or path))


def _start_compile(model, needs, notice: Progress | None):
    """The EKF kernel's first compile, beside the reading (logscan.filters.warmup), when a
    detector may need the EKF and the cache lacks the model's kernel."""
    from logscan.filters.warmup import COMPILING_NOTE, Compile, start_compile

    if isinstance(needs, Needs) and "ekf" not in needs.filters:
        return Compile(cold=False)
    compiling = start_compile(model)
    if compiling.cold and notice is not None:
        notice(COMPILING_NOTE)
    return compiling


def detect(
    prepared: Prepared,
    detectors: Sequence,
    *,
    grace_s: float = 1.0,
    progress: Progress | None = None,
    free_series: bool = False,
    sensor_views: bool = False,
):
    """Run the detectors on a prepared log, merge their alarm fragments into incidents, say what
    could not be checked, and score the alarms when the log carries ground truth. A detector that
    raises is named in ``analysis.failures``; the others' results are kept. ``free_series``: free
    each large series once no detector still to run reads it (`release_unread`; the prepared log
    then serves no further detector). ``sensor_views``: pack the EKF's innovations, when it kept
    them, for the report (`Prepared.innovations`, `logscan.report.sensor_views`)."""
    from logscan.pipeline.analysis import Analysis
    from logscan.verdict.coverage import unchecked_reasons, unjudged_flight
    from logscan.verdict.incidents import DEFAULT_GAP_S, find_incidents, merge_fragments

    step = progress or (lambda message: None)
    free_series = free_series and prepared.profile.recovery is None  # recovery re-runs the filters
    analysis = Analysis(prepared=prepared, warnings=list(prepared.warnings))
    # when a fault of a kind could be seen at all: from the filter's states, before any is freed
    from logscan.verdict.observability import observability_for

    analysis.observability, why = observability_for(prepared)
    analysis.warnings += [why] if why else []
    policy = prepared.profile.alarm_policy
    if policy is not None and policy.suspends:
        policy = policy.suspend(prepared.run.t, prepared.run.ground)
    # the suspension holds back the model-based statistics only (`Detector.run`): said when one runs,
    # a warning, or the log is not fully checked when it kept them from most of the flight
    unjudged = unjudged_flight(policy, prepared.run) if any(not d.raw_topics for d in detectors) else None
    if unjudged is not None and not unjudged[1]:
        analysis.warnings.append(unjudged[0])
        analysis.unjudged = unjudged[0]  # the report says it where "every check ran" would be
    # the detectors that read the samples first (the frozen-sensor check), so the report's pack of
    # innovations can then take the samples' buffer (`_pack_innovations`); results in the given order
    order = sorted(range(len(detectors)), key=lambda i: not _reads_samples(detectors[i]))
    results: dict[int, Any] = {}
    packed = not sensor_views
    for position, index in enumerate(order):
        detector, still_to_run = detectors[index], [detectors[i] for i in order[position:]]
        if not packed and not any(_reads_samples(d) for d in still_to_run):
            _pack_innovations(prepared, still_to_run, reuse_samples=free_series)
            packed = True
        if free_series:  # the report's pack, still to come, reads the innovations
            release_unread(prepared, still_to_run, keep=frozenset() if packed else frozenset({"y", "S_diag"}))
        step(f"detector {detector.name}")
        try:
            result = detector.run(
                prepared.run,
                prepared.trace,
                model=prepared.model,
                log_name=prepared.path,
                traces=prepared.traces,
                alarm_policy=policy,
                truth=prepared.log.truth,  # simulated logs' ground truth, None for real logs
                raw=prepared.raw,
                metadata=prepared.log.source.metadata,
            )
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - one detector must not take the others down
            analysis.failures.append(detector_failure(detector.name, exc))
            continue
        results[index] = result
    if not packed:  # every detector reads the samples
        _pack_innovations(prepared, [], reuse_samples=False)
    analysis.results = [results[i] for i in sorted(results)]
    analysis.warnings[:0] = consistency_warnings(prepared)  # first: they question every verdict below
    gap_s = policy.merge_gap_s if policy is not None else DEFAULT_GAP_S
    merge_fragments(analysis.results, gap_s)
    groups = prepared.trace.group_names if prepared.trace is not None else list(prepared.run.groups)
    analysis.incidents = find_incidents(analysis.results, prepared.trace, groups, gap_s)
    analysis.unchecked = unchecked_reasons(prepared, analysis.results)
    if unjudged is not None and unjudged[1]:
        analysis.unchecked.append(unjudged[0])
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


def consistency_warnings(prepared: Prepared) -> list[str]:
    """One warning per measurement group whose median NIS is far from the chi-square median of its
    size (see NIS_MISMATCH); the ratio is given per output."""
    import numpy as np
    from scipy.special import chdtri  # chi-square quantiles without scipy.stats (46 MB to import)

    from logscan.training.calibration import calibrate_command

    trace = prepared.trace
    if trace is None or trace.nis_group is None:
        return []
    out = []
    for g, (name, size) in enumerate(zip(trace.group_names, trace.group_sizes.tolist())):
        used = trace.updated[:, g] & np.isfinite(trace.nis_group[:, g])
        if int(used.sum()) < NIS_MIN_UPDATES or not size:
            continue
        ratio = float(np.median(trace.nis_group[used, g])) / float(chdtri(size, 0.5))
        if ratio > NIS_MISMATCH:
            out.append(
                f"group {name!r}: median NIS {ratio:.3g} times its chi-square median (about 1 expected): model or "
                "profile mismatch, check units, signs and frames of its channels, or its noise_std "
                f"({doc_url('troubleshooting.md')}; `{calibrate_command(prepared.profile)}`, then --tables tables.json)"
            )
        else:
            out.extend(_blind_warning(prepared, g, name, size, used))
    return out


def _blind_warning(prepared: Prepared, g: int, name: str, size: int, used) -> list[str]:
    """The "blind" warning of group ``g`` when its mean NIS per output is below NIS_BLIND over the
    judged updates (all of ``used`` when fewer than NIS_MIN_UPDATES are judged)."""
    import numpy as np

    from logscan.training.calibration import calibrate_command, judged_steps

    judged = judged_steps(prepared.profile, prepared.run)
    if judged is not None and int((used & judged).sum()) >= NIS_MIN_UPDATES:
        used = used & judged
    level = float(np.mean(prepared.trace.nis_group[used, g])) / size
    if not level < NIS_BLIND:
        return []
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


def _reads_samples(detector) -> bool:
    """Whether a detector reads the groups' samples (undeclared reads: it may)."""
    return detector.reads is None or "z" in detector.reads


def _pack_innovations(prepared: Prepared, detectors: Sequence, reuse_samples: bool) -> None:
    """`Prepared.innovations` from the EKF trace's innovations and the groups' samples; with
    ``reuse_samples``, into the samples' own buffer when no detector reads them (they are dropped)."""
    import numpy as np

    from logscan.filters.ekf import samples_side_by_side
    from logscan.report.sensor_views import pack_innovations

    trace, run = prepared.trace, prepared.run
    if trace is None or trace.y is None or trace.S_diag is None:
        return
    samples = None
    if reuse_samples and all(d.reads is not None and "z" not in d.reads for d in detectors):
        samples = samples_side_by_side(run, trace.group_names, trace.group_offsets, trace.group_sizes)
    prepared.innovations = pack_innovations(run, trace, samples)
    if samples is not None:  # the buffer now holds the pack: no group may read it as samples
        for group in (*run.groups.values(), *run.redundant.values()):
            if isinstance(group.z, np.ndarray) and group.z.base is samples:
                group.z = None


def release_unread(prepared: Prepared, still_to_run: Sequence, keep: frozenset[str] = frozenset()) -> None:
    """Free the large series none of ``still_to_run`` declares it reads (all of them declare), but
    those in ``keep``."""
    wanted: set[str] = set(keep)
    for detector in still_to_run:
        if detector.reads is None:
            return
        wanted |= detector.reads
    for trace in prepared.traces.values():
        for name in RELEASABLE_TRACE:
            if name not in wanted and getattr(trace, name, None) is not None:
                setattr(trace, name, None)
    run = prepared.run
    for name in ("onboard_state", "onboard_variance", "u", "mode"):
        if name not in wanted and getattr(run, name) is not None:
            setattr(run, name, None)
    if "z" not in wanted:
        for group in run.groups.values():
            group.z = group.fresh = group.channel_fresh = None
    if "redundant" not in wanted:
        for group in run.redundant.values():
            group.z = group.fresh = group.channel_fresh = None


def detector_failure(name: str, exc: BaseException):
    """The line and exit code of a detector that raised: its own error (its exit code), or a bug
    in that detector (exit 3), blamed on the plugin package when it comes from one."""
    from logscan.detectors.registry import default_registry
    from logscan.errors import ExitCode
    from logscan.pipeline.analysis import DetectorFailure

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
    from logscan.results import events_from_truth
    from logscan.verdict.scoring import score_by_detector

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


def analyze_log(
    path: str | os.PathLike,
    profile_path: str | os.PathLike | None = None,
    *,
    use_header_stamp: bool = False,
    detector_names: Sequence[str] | None = None,
    grace_s: float = 1.0,
    progress: Progress | None = None,
    notice: Progress | None = None,
    start_s: float | None = None,
    end_s: float | None = None,
    free_series: bool = False,
    sensor_views: bool = False,
    tables: str | os.PathLike | None = None,
    truth: str | os.PathLike | None = None,
):
    """One log end to end: profile, detectors (checked before the log is read), prepare, detect;
    ``tables``: trained tables (`logscan train`; default: the profile's ``tables`` key);
    ``start_s``/``end_s``: a window of the log (seconds since its start); ``free_series``: see
    `detect`; ``sensor_views``: keep the EKF's innovations for the report's measured-vs-predicted
    figures (`logscan.report.sensor_views`), when a detector runs the EKF; ``truth``: a ground-truth JSON
    to score against (default: the log's own, or `<log>.truth.json` beside it)."""
    from logscan.training.calibration import process_noise_scale, uncalibrable_groups

    loaded = load_profile_for(path, profile_path)
    detectors = filter_free(create_detectors(loaded, detector_names), loaded, path)
    trained = tables_path(None if tables is None else str(tables), loaded.profile, log=path)
    if trained is not None:  # the trained detectors, and the filter's calibrated noise in the profile
        detectors = apply_tables(detectors, trained, loaded.profile)
        calibration = read_tables_document(trained).get("calibration")
        loaded.process_noise_scale = process_noise_scale(calibration)
        loaded.uncalibrated = uncalibrable_groups(calibration)
    options = {"use_header_stamp": use_header_stamp, "start_s": start_s, "end_s": end_s}
    needs = _with_innovations(needs_of(detectors)) if sensor_views else needs_of(detectors)
    raw = raw_topics_of(detectors)
    prepared = prepare(
        path, loaded, needs, progress=progress, notice=notice, raw_topics=raw, truth_path=truth, **options
    )
    return detect(
        prepared, detectors, grace_s=grace_s, progress=progress, free_series=free_series, sensor_views=sensor_views
    )


def _with_innovations(needs: Callable[[Any], Needs]) -> Callable[[Any], Needs]:
    """``needs`` plus the EKF's innovations, when the EKF runs at all."""

    def wanted(run) -> Needs:
        base = needs(run)
        return base | Needs.of(ekf=("y",)) if base.wants("ekf") else base

    return wanted
