"""The run's context kept for the report: the vehicle's 2-D path and its mode intervals, small.

The aligned run's arrays are freed once the detectors have run (`logscan.pipeline.Prepared`), so
what the report shows beside the statistics is extracted right after alignment, decimated:

- the path: the measurement group the model maps directly onto its states named ``x`` and ``y``
  (a position sensor), or ``east`` and ``north`` (a GNSS group converted to metres about its first
  fix: a map without tiles), its samples where the group had a new one, at most ``MAX_PATH_POINTS``
  (half evenly in time, half the min/max per bucket of x and of y, so an excursion of one sample
  stays visible);
- the mode: the profile's ``[mode]`` channel as intervals of one value (``MAX_MODE_INTERVALS`` at
  most), or, when it changes more often (a continuous set-point), as a decimated series;
- the autopilot's own logged messages of level WARNING and above (a ULog's ``logged_messages``,
  ``MAX_MESSAGES`` at most), on the same time axis, and all its messages whatever their level
  (``MAX_LOG_MESSAGES`` at most; the reader keeps 500) for the report's folded message table; of a
  window (--start/--end), only those in it (`analysed_span`), as the verdict's list of them
  (`logscan.verdict.autopilot_messages`): the report is about what was judged;
- a ULog's parameters set away from their defaults and changed in flight (`logscan.report.parameters`);
- the autopilot's states as intervals: armed (PX4 ``vehicle_status.arming_state`` 2) and in
  failsafe (``vehicle_status.failsafe``), when the log carries them (`STATE_TOPICS`), cut to a
  window's span;
- a simulated log's true state (`logscan simulate` writes it on `TRUTH_STATE_TOPIC`, its ground
  truth names the topic and fields) on the grid, for the model's states it gives (`true_states`):
  the UBIKF's estimation error against its envelopes (`logscan.report.ubikf_truth_view`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from logscan.log import MAX_MESSAGES, LoggedMessage, logged_messages
from logscan.report.decimate import decimate_indices
from logscan.report.parameters import ParameterFacts, parameter_facts

MAX_PATH_POINTS = 1_000
MAX_MODE_INTERVALS = 200
MAX_MODE_POINTS = 1_000
# model states a path is drawn from, horizontal axis first: a model's own x-y plane, or the local
# north-east frame (an INS model; a geodetic group converted about its origin) drawn as a map
POSITION_PAIRS = (("x", "y"), ("east", "north"))
MAX_STATE_INTERVALS = 200
MAX_LOG_MESSAGES = 500
# every level a ULog message can have (pyulog's MessageLogging.log_level_str), most severe first
ALL_LEVELS = ("EMERGENCY", "ALERT", "CRITICAL", "ERROR", "WARNING", "NOTICE", "INFO", "DEBUG")
# the topic `logscan simulate` writes the true state on (its ground truth's ``true_state_topic``)
TRUTH_STATE_TOPIC = "/truth/state"
# topics read beside a profile's for the states drawn in the report (absent topics cost nothing)
STATE_TOPICS = ("vehicle_status_0", TRUTH_STATE_TOPIC)
ARMED_STATE = 2.0  # PX4 vehicle_status.arming_state: ARMING_STATE_ARMED
# a ULog message's level, as logscan.readers.ulog_reader writes it ("<s> s [<LEVEL>] <text>"), most severe first
# a ULog message as logscan.readers.ulog_reader writes it: "<seconds> s [<LEVEL>] <text>"


@dataclass
class Path2D:
    """Positions of the vehicle: times (s since the log's start), x and y, and their channels."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    channels: tuple[str, str]
    group: str
    columns: tuple[int, int] = (0, 1)  # the group's columns drawn across and up


@dataclass
class ModeTrack:
    """The mode / set-point channel: intervals of one value (start s, end s, value) when there are
    few, and always a decimated series (t, value) to draw it as a step line."""

    channel: str
    t: np.ndarray
    value: np.ndarray
    intervals: list[tuple[float, float, float]] = field(default_factory=list)  # empty: too many
    n_changes: int = 0
    labels: dict[float, str] = field(default_factory=dict)  # the profile's names of its values ([mode] labels)


@dataclass
class RunContext:
    path: Path2D | None = None
    mode: ModeTrack | None = None
    messages: list[LoggedMessage] = field(default_factory=list)
    t_span: tuple[float, float] | None = None  # the grid's first and last time: the shared time axis
    states: dict[str, list[tuple[float, float]]] = field(default_factory=dict)  # "armed" -> intervals (s)
    log_messages: list[LoggedMessage] = field(default_factory=list)  # every level, in time order
    n_log_messages: int = 0  # how many the log holds (log_messages may be fewer)
    parameters: ParameterFacts | None = None  # a ULog's parameters away from their defaults, and changed
    # a simulated log's true state on the grid, model state -> (N,) float64 (`true_states`); empty: no truth
    true_states: dict[str, np.ndarray] = field(default_factory=dict)
    window: tuple[float, float] | None = None  # a --start/--end window's analysed span (`analysed_span`)
    n_outside: int = 0  # messages of any level logged outside the window: counted, not kept


def _intervals(t: np.ndarray, on: np.ndarray, end: float) -> list[tuple[float, float]]:
    """The (start, end) times where ``on`` holds, each sample holding until the next (the last
    until ``end``)."""
    if t.size == 0:
        return []
    change = np.flatnonzero(np.diff(on.astype(np.int8)) != 0) + 1
    starts = np.concatenate([[0], change])
    stops = np.concatenate([change, [t.size]])
    out = []
    for a, b in zip(starts.tolist(), stops.tolist()):
        if on[a]:
            out.append((float(t[a]), float(t[b]) if b < t.size else end))
    return out[:MAX_STATE_INTERVALS]


def autopilot_states(channels: dict, start_ns: int, end_s: float) -> dict[str, list[tuple[float, float]]]:
    """{"armed": intervals, "failsafe": intervals} from PX4's vehicle_status channels among a log's
    ``channels`` (times in s since ``start_ns``); states the log lacks are left out."""
    out = {}
    for state, field_name, test in (
        ("armed", "arming_state", lambda v: v == ARMED_STATE),
        ("failsafe", "failsafe", lambda v: v != 0),
    ):
        channel = channels.get(f"/vehicle_status_0/{field_name}")
        if channel is None or len(channel) == 0:
            continue
        t = (np.asarray(channel.t, dtype=np.int64) - start_ns) / 1e9
        values = np.asarray(channel.values, dtype=np.float64)
        out[state] = _intervals(t, test(np.nan_to_num(values)), end_s)
    return out


def position_columns(run, model) -> tuple[str, int, int, tuple[str, str]] | None:
    """(group, column of the horizontal axis, column of the vertical one, their states): the first
    aligned group the model maps directly onto a pair of `POSITION_PAIRS`; None when none does."""
    states = list(getattr(model, "state_names", ()))
    for pair in POSITION_PAIRS:
        if not all(name in states for name in pair):
            continue
        wanted = [states.index(name) for name in pair]
        for name, group in run.groups.items():
            spec = getattr(model, "groups", {}).get(name)
            direct = list(getattr(spec, "direct_states", ()) or ())
            if all(i in direct for i in wanted) and group.z.ndim == 2 and group.z.shape[1] == len(direct):
                return name, direct.index(wanted[0]), direct.index(wanted[1]), pair
    return _geodetic_columns(run)


def _geodetic_columns(run) -> tuple[str, int, int, tuple[str, str]] | None:
    """A geodetic group converted about its first fix (a GNSS the model does not take as its
    position states, e.g. position plus a GNSS error state): its east and north columns, which the
    aligner names "<fields> east" / "<fields> north"."""
    for name, group in run.groups.items():
        if getattr(group, "origin", None) is None:
            continue
        axes = [channel.rsplit(" ", 1)[-1] for channel in group.channels]
        if "east" in axes and "north" in axes:
            return name, axes.index("east"), axes.index("north"), ("east", "north")
    return None


def _axis_names(group, cx: int, cy: int, pair: tuple[str, str]) -> tuple[str, str]:
    """The path's axis titles: the channels of a group drawn as logged (x, y), the local frame's
    axes of a geodetic group (its channels are degrees; its values metres about its origin)."""
    if pair == ("x", "y"):
        return group.channels[cx], group.channels[cy]
    about = "the first fix" if getattr(group, "origin", None) is not None else "the origin"
    return f"{pair[0]} (m from {about})", f"{pair[1]} (m from {about})"


def path_indices(x: np.ndarray, y: np.ndarray, idx: np.ndarray, max_points: int) -> np.ndarray:
    """``idx`` (the steps with a position) cut to about ``max_points``: half evenly in time (the
    shape), a quarter each on x's and y's extremes."""
    if idx.size <= max_points:
        return idx
    even = np.linspace(0, idx.size - 1, max_points // 2).round().astype(np.int64)
    quarter = max(max_points // 4, 16)
    extremes = np.union1d(decimate_indices(x[idx], quarter), decimate_indices(y[idx], quarter))
    return idx[np.union1d(even, extremes)]


def path_of(run, model, max_points: int = MAX_PATH_POINTS, first: int = 0) -> Path2D | None:
    """The decimated 2-D path of the position group from the run's step ``first`` on, or None (no
    such group, < 2 samples)."""
    found = position_columns(run, model)
    if found is None:
        return None
    name, cx, cy, pair = found
    group = run.groups[name]
    x, y = group.z[:, cx], group.z[:, cy]
    idx = np.flatnonzero(np.asarray(group.fresh, dtype=bool) & np.isfinite(x) & np.isfinite(y))
    idx = idx[idx >= first]
    if idx.size < 2:
        return None
    idx = path_indices(x, y, idx, max_points)
    names = _axis_names(group, cx, cy, pair)
    return Path2D(run.t[idx].copy(), x[idx].copy(), y[idx].copy(), names, name, (cx, cy))


def estimated_path(path: Path2D | None, innovations, t: np.ndarray, max_points: int = MAX_PATH_POINTS):
    """The filter's estimate of ``path``'s group: its prediction h(x_prior) at each update
    (`logscan.report.sensor_views.Innovations`), smooth where the fixes jump, decimated as the
    fixes are; None without the group's innovations."""
    predicted = (
        innovations.predicted(path.group, path.columns) if path is not None and innovations is not None else None
    )
    if predicted is None or path is None:
        return None
    t = innovations.times(path.group, t)  # block mode: the group's kept rows' own
    x, y = predicted[:, 0].astype(np.float64), predicted[:, 1].astype(np.float64)
    idx = np.flatnonzero(np.isfinite(x) & np.isfinite(y))
    if idx.size < 2:
        return None
    idx = path_indices(x, y, idx, max_points)
    return Path2D(t[idx].copy(), x[idx], y[idx], path.channels, path.group, path.columns)


def run_starts(value: np.ndarray) -> np.ndarray:
    """Start indices of the runs of one value (NaN runs included; NaN equals NaN here)."""
    nan = np.isnan(value)
    change = (value[1:] != value[:-1]) & ~(nan[1:] & nan[:-1])
    return np.concatenate([[0], np.flatnonzero(change) + 1])


def mode_of(
    run, max_intervals: int = MAX_MODE_INTERVALS, max_points: int = MAX_MODE_POINTS, first: int = 0
) -> ModeTrack | None:
    """The mode channel from the run's step ``first`` on as intervals and a decimated series, or None
    (no mode channel, never defined there)."""
    mode = getattr(run, "mode", None)
    if mode is None or run.n_steps <= first or not np.isfinite(mode[first:]).any():
        return None
    value = np.asarray(mode[first:], dtype=np.float64)
    t = run.t[first:]
    starts = run_starts(value)
    if starts.size < max_points // 2:  # a step line needs each run's start (and the end before a gap)
        before_gap = starts[np.isnan(value[starts]) & (starts > 0)] - 1
        idx = np.unique(np.concatenate([starts, before_gap, [value.size - 1]]))
    else:
        idx = decimate_indices(value, max_points, keep=starts, simplify_flat=True)
    track = ModeTrack(str(run.mode_channel or "mode"), t[idx].copy(), value[idx].copy(), n_changes=starts.size - 1)
    defined = np.flatnonzero(np.isfinite(value[starts]))
    if defined.size <= max_intervals:
        ends = np.append(starts[1:], value.size)[defined]  # a run ends where the next begins
        begins = starts[defined]
        t_edge = np.append(t, t[-1] + run.dt)
        track.intervals = list(zip(t_edge[begins].tolist(), t_edge[ends].tolist(), value[begins].tolist()))
    return track


def analysed_span(run) -> tuple[float, float] | None:
    """A window's (--start/--end) analysed span, s since the log's start: its grid's first step to
    one step after its last, as the raw-topic checks judge it (detectors/raw_topics.py `in_span`);
    None for the whole log."""
    if getattr(run, "window", None) is None:
        return None
    return float(run.t[0]), float(run.t[-1] + run.dt)


def _within(messages: list[LoggedMessage], span: tuple[float, float] | None, limit: int) -> list[LoggedMessage]:
    """The ``messages`` in ``span`` (all for None), the first ``limit`` of them."""
    return [m for m in messages if span is None or span[0] <= m.t <= span[1]][:limit]


def _clipped(states: dict[str, list[tuple[float, float]]], span: tuple[float, float] | None) -> dict:
    """Each state's intervals cut to ``span`` (unchanged for None); those outside it dropped."""
    if span is None:
        return states
    a, b = span
    return {name: [(max(s, a), min(e, b)) for s, e in spans if e >= a and s <= b] for name, spans in states.items()}


def _message_count(metadata: dict, kept: int) -> int:
    """The log's count of logged messages (a ULog's ``ulog.log`` facts), at least ``kept``."""
    try:
        return max(int((metadata or {}).get("ulog.log", {}).get("logged_messages", 0)), kept)
    except (TypeError, ValueError):
        return kept


def true_states(log, run, model) -> dict[str, np.ndarray]:
    """Model state -> its true value at each grid step (the latest truth sample at or before it,
    NaN before the first), for the states the log's ground truth gives: ``true_state_fields`` on
    ``true_state_topic``, as `logscan simulate` writes them; {} for a log without them."""
    truth = getattr(log, "truth", None) or {}
    topic, fields = truth.get("true_state_topic"), truth.get("true_state_fields") or ()
    states = set(getattr(model, "state_names", ()))
    channels = {name: log.channels.get(f"{topic}/{name}") for name in fields if name in states}
    channels = {name: channel for name, channel in channels.items() if channel is not None and len(channel)}
    grid_ns = run.start_ns + np.round(np.asarray(run.t, dtype=np.float64) * 1e9).astype(np.int64)
    out = {}
    # the fields of one truth message share its time array: searched once, for the index of each
    # step's latest sample (0 before the first) and the steps before the first (empty, usually)
    latest: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for name, channel in channels.items():
        if id(channel.t) not in latest:
            i = np.searchsorted(np.asarray(channel.t, dtype=np.int64), grid_ns, side="right") - 1
            before_first = np.flatnonzero(i < 0)
            latest[id(channel.t)] = (np.maximum(i, 0, out=i), before_first)
        index, before_first = latest[id(channel.t)]
        out[name] = np.asarray(channel.values, dtype=np.float64)[index]
        out[name][before_first] = np.nan
    return out


def run_context(
    run,
    model,
    log=None,
    mode_labels: dict[float, str] | None = None,
    with_truth: bool = True,
    from_s: float | None = None,
) -> RunContext:
    """The path and the mode of an aligned run (each None when the run has none; the mode's values
    named by ``mode_labels``, the profile's ``[mode] labels``), and, from its ``log`` (before its
    samples are released), the autopilot's messages and states and, ``with_truth``, a simulated
    log's true state. ``from_s``: only from this time on (a block's own steps after its lead-in:
    `logscan.report.context_join`), the true state excepted."""
    first = 0 if from_s is None else int(np.searchsorted(run.t, from_s - 1e-9))
    first = min(first, run.t.size - 1)
    context = RunContext(
        path=path_of(run, model, first=first),
        mode=mode_of(run, first=first),
        t_span=(float(run.t[first]), float(run.t[-1])),
    )
    if context.mode is not None and mode_labels:
        context.mode.labels = dict(mode_labels)
    if log is not None:
        metadata, span = log.source.metadata, analysed_span(run)
        if span is not None and first:
            span = (float(run.t[first]), span[1])
        context.window = span
        context.messages = _within(logged_messages(metadata, run.start_ns, limit=None), span, MAX_MESSAGES)
        every = logged_messages(metadata, run.start_ns, ALL_LEVELS, None)
        context.log_messages = _within(every, span, MAX_LOG_MESSAGES)
        n_log = _message_count(metadata, len(every))
        inside = n_log if span is None else sum(1 for m in every if span[0] <= m.t <= span[1])
        context.n_log_messages, context.n_outside = inside, n_log - inside
        context.parameters = parameter_facts(metadata, run.start_ns)
        context.states = _clipped(autopilot_states(log.channels, run.start_ns, context.t_span[1]), span)
        context.true_states = true_states(log, run, model) if with_truth else {}
    return context
