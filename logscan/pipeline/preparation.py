"""Prepare one log for its detectors: its profile (the file given, the log's embedded one, or a
built-in one), then read only the topics it needs, align them and run each filter the detectors
need exactly once (`prepare`)."""

from __future__ import annotations

import os
import shlex
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from logscan.align import align
from logscan.detectors.registry import default_registry
from logscan.docs import doc_url
from logscan.errors import CorruptLogError, InputError, LogscanError, ProfileError
from logscan.filters.warmup import (
    COMPILING_NOTE,
    Compile,
    head_start,
    kernel_cached,
    start_compile,
)
from logscan.log import MAX_SPAN_S, Log
from logscan.memory import collector_paused, return_freed_pages
from logscan.models import get_model
from logscan.needs import Needs
from logscan.pipeline.held_window import held_window, widened
from logscan.pipeline.lead_in import SETTLED_OVER_S, carry_freshness, filter_start, lead_in_start
from logscan.pipeline.loops import RECOVERY_NEEDS, prepare_loops
from logscan.pipeline.release import TRUTH_DRAWN_WITH
from logscan.pipeline.stages import COUNTS_STEPS, FILTERS, LoadedProfile, Prepared
from logscan.pipeline.step_counter import counted_steps
from logscan.profiles import builtin, load_profile, parse_profile, ros
from logscan.profiles.schema import MAX_DELAY_S
from logscan.profiles.starter import STARTER_FORMATS
from logscan.readers import detect_format, read_embedded_profile, read_log, spill
from logscan.readers.common import ReadWindow
from logscan.readers.csv_reader import csv_log_name
from logscan.report.run_context import STATE_TOPICS, run_context
from logscan.timebase.clock import GNSS_UTC_CHANNELS, clock_of
from logscan.verdict.observability import compile_kernel as compile_verdict_kernel
from logscan.verdict.observability import judged_spans
from logscan.verdict.observability_kernel import signature_evidence
from logscan.verdict.truth import in_log_time, read_truth_file, truth_beside

if TYPE_CHECKING:
    from logscan.align import AlignedRun

Progress = Callable[[str], None]
Fraction = Callable[[int, int], None]  # (done, total) of the step under way, e.g. bytes read
# what is read besides the profile's topics: the autopilot's states for the report, and a ULog's
# GNSS time (its UTC), when the log has them
CONTEXT_TOPICS = frozenset(STATE_TOPICS) | frozenset(GNSS_UTC_CHANNELS)


def load_profile_for(
    path: str | os.PathLike, profile_path: str | os.PathLike | None, embedded: str | None = None
) -> LoadedProfile:
    """The profile of a log: the file given, else the one the log embeds (a metadata-only read;
    ``embedded``: its text, already read), else the built-in profile of a log that names itself (a
    PX4 ULog: `logscan.profiles.builtin`)."""
    if profile_path is not None:
        profile = load_profile(profile_path)
        return LoadedProfile(profile, profile.to_toml(), str(profile_path), list(profile.notes))
    embedded = embedded or read_embedded_profile(path)
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
        raise ProfileError("no profile: the log embeds none", path=str(path), hint=_no_profile_hint(path))
    profile = parse_profile(embedded, source=f"{path} (embedded profile)")
    return LoadedProfile(profile, embedded, "embedded", list(profile.notes))


def _no_profile_hint(path: str | os.PathLike) -> str:
    """What to do about a log without a profile: pass one, written first by `logscan init-profile`
    where it writes a starter (a CSV log, an MCAP), as docs/inputs.md recommends."""
    see = f"see {doc_url('profiles.md')}"
    if detect_format(path) not in STARTER_FORMATS:
        return f"pass --profile PROFILE.toml ({see})"
    init = f"logscan init-profile {shlex.quote(str(path))} -o profile.toml"
    return f"`{init}` writes a starter one to edit; then pass --profile profile.toml ({see})"


def builtin_profile_for(path: str | os.PathLike, *, with_log: bool = False):
    """The built-in profile (`logscan.profiles.builtin.BuiltProfile`) of a log that names itself (a
    PX4 ULog, a ROS log), else None; reads only the topics the built-in profile may use, plus
    those any detector reads from the log itself (`Detector.raw_topics`) and the report's states.
    ``with_log``: (profile, the log read, those extra topics), so the analysis need not read it
    again."""
    fmt = None if path is None else detect_format(path)
    extra = _extra_topics()
    if fmt in builtin.ROS_FORMATS:  # a ROS log: its topic list first, then only the topics the profile may use
        schemas = builtin.topic_schemas(path, fmt)
        if not any(ros.is_ros_topic(*value) for value in schemas.values()):
            return None
        # the extra topics the file has (its topic list names them all: the others are covered too);
        # held for block mode's windows when the analysis takes it (`held_window`): a long bag on disk
        log = read_log(path, topics=set(ros.ros_candidate_topics(schemas)) | (extra & set(schemas)), held=with_log)
        try:
            built = ros.ros_profile(log) if builtin.identify(log) == "ros" else None
        finally:
            spill.give_back()  # the pages the profile read of a long bag held on disk
    elif fmt == "ulog" or (fmt == "csv-dir" and csv_log_name(Path(path))):  # a ULog, or ulog2csv's pieces of one
        # held for block mode's windows when the analysis takes it (`held_window`): half the bytes
        log = read_log(path, topics=set(builtin.PX4_TOPICS) | extra, held=with_log)
        try:
            built = builtin.px4_profile(log) if builtin.identify(log) == "px4" else None
        except InputError:  # a topic it needs is missing: from the log, or from what damage left of it
            _raise_if_damaged(log, path)
            raise
        finally:
            spill.give_back()  # the pages the profile read of a long log held on disk
    else:
        return None
    if built is None:
        _raise_if_damaged(log, path)
    if built is None or not with_log:
        return built
    return built, log, extra


def _raise_if_damaged(log: Log, path) -> None:
    """A damaged log of which no sample was read: its built-in profile could not be made because of
    the damage (not a missing profile or topic), said as the reader found it. A log read but for its
    cut last message keeps the error of what it lacks."""
    if log.source.partial and not any(len(channel) for channel in log.channels.values()):
        raise CorruptLogError(
            f"damaged log, too little read to build its built-in profile: {log.source.partial_reason}",
            path=str(path),
            hint="copy the file again if it was cut or changed in transfer; else pass --profile to analyse what "
            "is left",
        )


def _extra_topics() -> frozenset[str]:
    """Every topic a registered detector reads from the log itself, and the report's states."""
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
    needs: Needs | Callable[[AlignedRun], Needs],
    *,
    use_header_stamp: bool = False,
    progress: Progress | None = None,
    notice: Progress | None = None,
    start_s: float | None = None,
    end_s: float | None = None,
    raw_topics: frozenset[str] = frozenset(),
    truth_path: str | os.PathLike | None = None,
    fraction: Fraction | None = None,
    ahead: Sequence[Callable[[], None]] = (),
    read_plans: dict | None = None,
    judged_from_s: float | None = None,
) -> Prepared:
    """Read only the topics the profile needs (and the detectors' ``raw_topics``, kept unaligned in
    ``Prepared.raw``), align them, and run each filter the needs ask for exactly once. ``needs``
    may be a function of the aligned run (needs can follow what the log holds, e.g. K and S only
    when it carries no on-board variances). ``notice`` hears the one line a user should see even
    without progress (the first run's compile). ``start_s``/``end_s``
    (seconds since the log's start) analyse a window of it. ``fraction`` hears the bytes read, a
    block at a time (`logscan.readers.read_log`'s ``progress``). ``ahead``: functions that compile
    the detectors' kernels, called on the first run in the process that compiles the EKF's, after
    it (`logscan.filters.warmup.kernel_compilers`). ``read_plans``: what a window's read learnt of
    the file for the next window of it (`ReadWindow.plans`: block mode's); ``judged_from_s``: the
    context from then on (a block's own steps). Raises LogscanError on bad input."""
    step = progress or (lambda message: None)
    path = str(path)
    profile = loaded.profile
    model = get_model(profile.vehicle.model, profile.vehicle.params)
    model.process_noise_scale = loaded.process_noise_scale  # read by every EKF run on it (pack_run)
    compiling = _start_compile(model, needs, notice, ahead)
    step("reading")
    log, run, lead = _read_and_align(
        path, loaded, raw_topics, use_header_stamp, fraction, (start_s, end_s), truth_path, step, plans=read_plans
    )
    if run.n_steps < 2:
        raise LogscanError(
            "too few samples on the analysis grid to filter",
            path=path,
            hint=f"check the profile's channels and rate_hz against `logscan inspect {shlex.quote(path)}`",
        )
    wanted = _wanted(needs, run, loaded, path)
    raw = raw_channels(log, raw_topics)  # kept as read: the detectors that asked for them read them
    labels = profile.mode.labels if profile.mode is not None else None
    # the report's context, from the samples about to go; a simulated log's true states only for a
    # page that draws them: the one filter's envelopes, or a further loop's (its detectors may)
    truth = bool(profile.loops) or wanted.wants(TRUTH_DRAWN_WITH)
    context = run_context(run, model, log, labels, with_truth=truth, from_s=judged_from_s)
    prepared = Prepared(path=path, log=log, loaded=loaded, model=model, run=run, context=context, raw=raw)
    prepared.clock = clock_of(log, run.start_ns)  # dated while the GNSS time is still there
    if profile.loops:
        prepared.loops = prepare_loops(prepared, log, start_s=start_s, end_s=end_s, step=step)
    log.release_samples()  # the run holds what the filters and detectors read from here on
    return_freed_pages()
    prepared.warnings += [*loaded.notes, *_read_warnings(log, run)]  # the profile's notes frame the rest
    _run_filters(prepared, wanted, compiling, step, fraction, lead)
    return prepared


def _wanted(needs: Needs | Callable[[AlignedRun], Needs], run: AlignedRun, loaded: LoadedProfile, path: str) -> Needs:
    """The filters and trace parts to run on the aligned run: the detectors' needs, and the full P
    for a profile's [recovery]."""
    wanted = needs(run) if callable(needs) else needs
    if loaded.model_not_run and wanted.filters:  # the filter-free detectors only (`filter_free`)
        raise InputError(loaded.model_not_run, path=path, hint="pass --profile with a model this log can drive")
    return wanted | RECOVERY_NEEDS if loaded.profile.recovery is not None else wanted


def _read(
    path: str,
    loaded: LoadedProfile,
    raw_topics: frozenset[str],
    use_header_stamp: bool,
    fraction: Fraction | None,
    window: ReadWindow | None,
) -> Log:
    """The log with the topics the profile needs, the detectors' ``raw_topics`` and the report's
    context: the built-in profile's log when it already holds them (read once), else read now
    (of an indexed MCAP file, only the chunks ``window`` needs). A block's ``window`` (one with
    ``plans``) of another format is cut from one read of the whole log (`held_window`)."""
    log, loaded.log = loaded.log, None  # a built-in profile's log, read once (`load_profile_for`)
    if log is not None and (use_header_stamp or not set(raw_topics) | CONTEXT_TOPICS <= loaded.log_extra_topics):
        log = None  # it lacks a topic the analysis reads
    topics = loaded.profile.topics() | set(raw_topics) | CONTEXT_TOPICS

    def read(window: ReadWindow | None = None) -> Log:
        if log is not None:
            return log
        return read_log(path, topics=topics, use_header_stamp=use_header_stamp, progress=fraction, window=window)

    if window is not None and window.plans is not None and detect_format(path) != "mcap":
        return held_window(str(path), window, frozenset(topics), read)  # a block of a log read whole
    return widened(read(window))


def _read_and_align(
    path: str,
    loaded: LoadedProfile,
    raw_topics: frozenset[str],
    use_header_stamp: bool,
    fraction: Fraction | None,
    window: tuple[float | None, float | None],
    truth_path,
    step: Progress,
    *,
    whole: bool = False,
    plans: dict | None = None,
) -> tuple[Log, AlignedRun, AlignedRun | None]:
    """The log read (of an indexed MCAP file, only the chunks the ``window`` needs, unless
    ``whole``) and aligned on the window, and on the lead-in before it (`_lead_run`). A window's
    read that the whole read would align otherwise is read again whole: its time zero is not its
    first message (an outlying first sample), or a profile channel is not in the chunks read."""
    profile = loaded.profile
    start_s, end_s = window
    lead_from = lead_in_start(start_s)
    read_window = _read_window(profile, start_s if lead_from is None else lead_from, end_s, plans)
    log = _read(path, loaded, raw_topics, use_header_stamp, fraction, None if whole else read_window)
    again = (path, loaded, raw_topics, use_header_stamp, fraction, window, truth_path, step)
    _attach_truth(log, path, truth_path)
    try:
        profile.check_channels(log)
    except ProfileError:
        if not log.whole_times:
            raise
        return _read_and_align(*again, whole=True)
    return_freed_pages()
    step("aligning")
    lead = _lead_run(log, profile, lead_from, start_s)
    framed = profile if lead is None else _with_origins(profile, lead)  # the lead-in's local frame
    run = align(log, framed, start_s=start_s, end_s=end_s, release=_released_once_held(log, profile, raw_topics))
    if log.whole_times and run.start_ns != log.window_zero_ns:
        return _read_and_align(*again, whole=True)
    return log, run, lead


def _lead_run(log: Log, profile, lead_from: float | None, start_s: float | None) -> AlignedRun | None:
    """The log aligned from ``lead_from`` to a second into the window from ``start_s``, for the
    window's filter to start from (`logscan.pipeline.lead_in`); None without a lead-in, or where
    that span holds no grid step before the window (the window's own alignment says what is
    wrong with it)."""
    if lead_from is None or start_s is None:
        return None
    try:
        return align(
            log, profile, start_s=lead_from, end_s=start_s + SETTLED_OVER_S + 2.0 / float(profile.vehicle.rate_hz)
        )
    except InputError:
        return None


def _with_origins(profile, lead: AlignedRun):
    """``profile`` with each geodetic group's origin, where it gives none, the lead-in's (its first
    fix there): the window's positions are then in the frame its filter's start is in."""
    origins = {name: group.origin for name, group in lead.groups.items() if group.origin is not None}
    specs = profile.measurements
    if not any(specs[name].origin is None for name in origins if name in specs):
        return profile
    measurements = {
        name: replace(spec, origin=list(origins[name])) if spec.origin is None and name in origins else spec
        for name, spec in specs.items()
    }
    return replace(profile, measurements=measurements)


def _read_window(profile, start_s: float | None, end_s: float | None, plans: dict | None) -> ReadWindow | None:
    """--start/--end as a read's window (None without either): a sample up to the longest delay a
    profile may give a sensor (`MAX_DELAY_S`) and two steps outside it may still be held, and the
    [alarms] ground channel as far around it as it can hold back steps inside it
    (`AlarmPolicy.margins_s`, `logscan.align.onto_grid`)."""
    if start_s is None and end_s is None:
        return None
    margins = [p.alarm_policy.margins_s() for p in (profile, *profile.loops.values()) if p.alarm_policy is not None]
    before_s, after_s = (max(m[0] for m in margins), max(m[1] for m in margins)) if margins else (0.0, 0.0)
    return ReadWindow(
        None if start_s is None else start_s - before_s,
        None if end_s is None else end_s + after_s,
        margin_s=MAX_DELAY_S + 2.0 / float(profile.vehicle.rate_hz),
        plans=plans,
    )


def _released_once_held(log: Log, profile, raw_topics: frozenset[str]) -> Callable[[str], bool] | None:
    """The channels alignment may drop the samples of once it has held them (`align`'s
    ``release``): none with further loops (they align the log again), else those under no topic
    read after alignment: the report's context, the ground truth's states, the ``raw_topics``."""
    if profile.loops:
        return None
    truth_topic = (log.truth or {}).get("true_state_topic")
    read_later = {*CONTEXT_TOPICS, *raw_topics, *([truth_topic] if isinstance(truth_topic, str) else [])}
    prefixes = tuple(topic.strip("/") + "/" for topic in read_later)
    exact = {topic.strip("/") for topic in read_later}

    def releasable(name: str) -> bool:
        bare = name.strip("/")
        return bare not in exact and not bare.startswith(prefixes)

    return releasable


def _read_warnings(log: Log, run: AlignedRun) -> list[str]:
    """What reading and aligning the log warned of, in that order."""
    warnings: list[str] = []
    span_warning = log.span_warning()
    if span_warning and run.n_steps * run.dt <= MAX_SPAN_S:  # outlying times dropped at alignment
        warnings.extend(w for w in log.source.warnings if w != span_warning)
    else:
        warnings.extend(log.source.warnings)
    warnings.extend(run.warnings)
    if log.source.partial:
        warnings.append(f"partial read: {log.source.partial_reason}")
    return warnings


def _run_filters(
    prepared: Prepared,
    wanted: Needs,
    compiling: Compile,
    step: Progress,
    fraction: Fraction | None,
    lead: AlignedRun | None = None,
) -> None:
    """Run each filter the needs ask for once, into ``prepared.traces``; the EKF's divergence
    episodes become warnings. ``fraction`` hears the steps a counting filter has done. ``lead``: a
    window's lead-in, the EKF's start (`logscan.pipeline.lead_in`)."""
    spill.give_back()  # the pages read of a log held on disk (a block's window of it): released
    for name, parts in wanted.filters.items():
        if name not in FILTERS:
            raise ProfileError(
                f"a detector needs the filter {name!r}, which this logscan does not have",
                hint=f"known filters: {', '.join(FILTERS)}",
            )
        step("filtering")
        if compiling.in_background:
            _compile_ahead(prepared, compiling)
        compiling.wait()
        if name not in COUNTS_STEPS:
            prepared.traces[name] = FILTERS[name](prepared.model, prepared.run, frozenset(parts))
            continue
        if name == "ekf" and lead is not None:
            prepared.lead_in = _filter_start(prepared, lead)
        start = {} if prepared.lead_in is None else prepared.lead_in.arguments()
        with counted_steps(prepared.run.n_steps, fraction) as steps_done:
            trace = FILTERS[name](prepared.model, prepared.run, frozenset(parts), steps_done=steps_done, **start)
        if start and trace.diverged.any():  # a restart returns to x0, P0: the model's prior, as in the whole run
            prepared.lead_in = None
            with counted_steps(prepared.run.n_steps, fraction) as steps_done:
                trace = FILTERS[name](prepared.model, prepared.run, frozenset(parts), steps_done=steps_done)
        prepared.traces[name] = trace
    ekf = prepared.trace
    for episode in ekf.divergence_episodes if ekf is not None else ():
        prepared.warnings.append(f"filter diverged: {episode}")


def _filter_start(prepared: Prepared, lead: AlignedRun):
    """The EKF's start at the window's first step from its lead-in (`logscan.pipeline.lead_in`),
    its warning (one that did not settle) among the prepared log's."""
    start = filter_start(prepared.model, lead, float(prepared.run.t[0]), lead.first_step == 0)
    if start is not None:
        carry_freshness(prepared.run, lead)
        prepared.warnings.extend([start.warning] if start.warning else [])
    return start


def _compile_ahead(prepared: Prepared, compiling: Compile) -> None:
    """While the EKF's kernel compiles in its own process (the first run), compile here the
    observability verdict's, when the log's ground truth asks for it, then those of the detectors'
    that process has not taken yet (they compile there after the EKF's: `_start_compile`). Only a
    head start: a compile that fails here is left to the kernel's first call, where the verdict (an
    aid, noted when it fails) or the one detector meets it, as without this."""
    model = prepared.model
    with collector_paused():
        if judged_spans(prepared) and not kernel_cached(signature_evidence, model.model_id):
            head_start(lambda: compile_verdict_kernel(model, prepared.run.dt))
        compiling.share()


def _attach_truth(log, path: str, truth_path) -> None:
    """Ground truth from ``truth_path`` (--truth), else the log's own, else `<log>.truth.json`
    beside it; UTC event times turned into the log's seconds (`logscan.verdict.truth`)."""
    source = truth_path if truth_path is not None else (truth_beside(path) if log.truth is None else None)
    if source is not None:
        log.truth = read_truth_file(source)
    if log.truth is not None:
        log.truth = in_log_time(log.truth, log.start_ns, str(source or path))


def _start_compile(model, needs, notice: Progress | None, ahead: Sequence[Callable[[], None]]):
    """The EKF kernel's first compile, beside the reading (logscan.filters.warmup), when a
    detector may need the EKF and the cache lacks the model's kernel; the detectors' kernels
    (``ahead``) then compile in the same process, after it."""
    if isinstance(needs, Needs) and "ekf" not in needs.filters:
        return Compile(cold=False)
    compiling = start_compile(model, after=ahead)
    if compiling.cold and notice is not None:
        notice(COMPILING_NOTE)
    return compiling
