"""The in-memory log: named numeric channels with integer-nanosecond timestamps and source facts."""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

MAX_NS = 2**62  # int64 nanoseconds with room for sums and differences (146 years past 1970)
_INT64 = np.dtype(np.int64)
_FLOAT64 = np.dtype(np.float64)


@dataclass(slots=True)  # no dict per channel: a ULog read makes thousands
class Channel:
    """One numeric signal: ``t`` int64 nanoseconds (sorted as read), ``values`` float64, same length."""

    name: str
    t: np.ndarray
    values: np.ndarray
    unit: str | None = None

    def __post_init__(self) -> None:
        # arrays already of the stored types are kept as they are (what np.asarray would return),
        # without its call or an errstate block: a reader builds thousands of channels per log
        t, values = self.t, self.values
        if type(t) is not np.ndarray or (t.dtype is not _INT64 and t.dtype != _INT64):
            self.t = t = np.asarray(t, dtype=np.int64)
        if type(values) is not np.ndarray or (values.dtype is not _FLOAT64 and values.dtype != _FLOAT64):
            # a float32 signalling NaN (a flipped bit) becomes a quiet NaN, an invalid sample like
            # any other NaN: numpy's "invalid value encountered in cast" would say nothing more
            with np.errstate(invalid="ignore"):
                self.values = values = np.asarray(values, dtype=np.float64)
        if t.shape != values.shape or t.ndim != 1:
            raise ValueError(
                f"channel {self.name!r}: t and values must be 1-D of equal length, "
                f"got {self.t.shape} and {self.values.shape}"
            )

    def __len__(self) -> int:
        return int(self.t.size)

    @classmethod
    def held(cls, name: str, t: np.ndarray, values: np.ndarray, unit: str | None = None) -> Channel:
        """A channel of a log held for block mode's windows (`logscan.pipeline.held_window`): its
        ``values`` as given, float32 where float32 holds every one exactly (half the bytes); never an
        analysis's (each window's channels are float64 again)."""
        channel = object.__new__(cls)
        channel.name, channel.t, channel.values, channel.unit = name, t, values, unit
        return channel

    @classmethod
    def sharing_time(cls, names: list[str], t: np.ndarray, rows: np.ndarray) -> list[Channel]:
        """One channel per name, its values the matching row of ``rows`` (float64, one row per name,
        as long as ``t``), all at the same ``t`` (int64): a reader's topic of many fields. The checks
        of `__post_init__` are made once for the lot (a ULog log has 2,000 channels or more)."""
        if not (
            type(t) is np.ndarray
            and t.dtype == _INT64
            and t.ndim == 1
            and type(rows) is np.ndarray
            and rows.dtype == _FLOAT64
            and rows.shape == (len(names), t.size)
        ):
            return [cls(name, t, row) for name, row in zip(names, rows, strict=True)]
        made = []
        new = object.__new__
        for name, row in zip(names, rows):
            channel = new(cls)
            channel.name, channel.t, channel.values, channel.unit = name, t, row, None
            made.append(channel)
        return made


@dataclass
class TopicInfo:
    """What a source topic (MCAP channel, CSV file, ULog message) held."""

    name: str
    message_count: int = 0
    encoding: str = ""
    schema: str = ""
    first_ns: int | None = None
    last_ns: int | None = None
    fields: list[str] = field(default_factory=list)

    @property
    def rate_hz(self) -> float:
        if self.first_ns is None or self.last_ns is None or self.message_count < 2:
            return 0.0
        span = (self.last_ns - self.first_ns) / 1e9
        return (self.message_count - 1) / span if span > 0 else 0.0

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "message_count": self.message_count,
            "rate_hz": round(self.rate_hz, 6),
            "encoding": self.encoding,
            "schema": self.schema,
            "first_ns": self.first_ns,
            "last_ns": self.last_ns,
            "fields": list(self.fields),
        }


@dataclass
class Skipped:
    """Something the reader did not turn into channels, and why (counted, never silent)."""

    what: str
    why: str
    count: int = 1

    def to_dict(self) -> dict[str, Any]:
        return {"what": self.what, "why": self.why, "count": self.count}


@dataclass
class SourceInfo:
    """Facts about the file a log came from."""

    path: str
    format: str  # "mcap", "csv", "csv-dir", "ulog"
    topics: dict[str, TopicInfo] = field(default_factory=dict)
    skipped: list[Skipped] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    partial: bool = False  # the file was read only up to a corrupt or truncated point
    partial_reason: str = ""
    time_unit: str = "ns"  # unit the source's timestamps were in (inferred for CSV)
    time_source: str = "log_time"
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    # channels the log holds that the read left out (not asked for, where a reader knows their
    # names: a CSV's columns, a read ULog topic's fields): a misspelt name is matched against them too
    unread: list[str] = field(default_factory=list)

    def skip(self, what: str, why: str, count: int = 1) -> None:
        """Count a skipped item, merging repeats of the same (what, why)."""
        for item in self.skipped:
            if item.what == what and item.why == why:
                item.count += count
                return
        self.skipped.append(Skipped(what, why, count))


MAX_SPAN_S = 86_400.0  # a log spanning more than a day is most likely several logs, or a wrong time unit


@dataclass(eq=False)
class WholeTimes:
    """A topic's message times across a whole file of which only a window was read
    (`Log.read_as_window`): ``count`` messages from ``first`` to ``last`` ns, the times themselves
    read again from the file when asked: ``batches()``, sorted and unique (a time logged twice once),
    a batch at a time, each after the one before; ``fetch(lo, hi)``, those from ``lo`` to ``hi``.
    ``runs``: what alignment found in them (`logscan.timebase.time_runs.TimeRuns`), kept with them
    for the file's next window."""

    count: int
    first: int
    last: int
    batches: Callable[[], Iterator[np.ndarray]]
    fetch: Callable[[int, int], np.ndarray]
    runs: Any = None

    @property
    def size(self) -> int:
        return self.count


@dataclass
class Log:
    """Channels by name plus where they came from; optional ground truth and embedded profile.

    Every reader builds its Log with the channels it read; a time span over MAX_SPAN_S adds a
    warning to ``source.warnings`` then (naming the channels that start first and end last).
    """

    channels: dict[str, Channel]
    source: SourceInfo
    truth: dict[str, Any] | None = None  # {"events": [{"start", "end", "kind", "target", ...}], ...}
    profile_text: str | None = None  # TOML of a profile embedded in the log

    def __post_init__(self) -> None:
        self._span_ns: tuple[int | None, int | None] | None = None  # kept by release_samples
        self._sample_counts: dict[str, int] = {}  # likewise
        self._span_text: str | None = None  # likewise
        # channel -> its topic's message times across the whole file (`WholeTimes`), when only a
        # window of it was read (`read_as_window`): alignment takes the grid's span and phase from them
        self.whole_times: dict[str, WholeTimes] = {}
        # channels -> their whole-file runs, dense span and outlying times (`_Aligner._whole_span`):
        # found once for a window and its filter's lead-in, which align the same channels
        self.whole_spans: dict[tuple[str, ...], tuple] = {}
        # the time zero a window read cut its samples from (`read_as_window`): alignment's must be it
        self.window_zero_ns: int | None = None
        warning = self.span_warning()
        if warning and warning not in self.source.warnings:
            self.source.warnings.append(warning)

    def release_samples(self, names: Iterable[str] | None = None) -> None:
        """Drop the samples of the channels ``names`` (None: every channel), keeping names, units,
        sample counts and the log's span (taken before the first is dropped): once a log is
        aligned, its raw samples (a 1-hour 100 Hz log: ~300 MB) are not read again; alignment may
        drop a channel's as soon as it has held it for the last time."""
        if self._span_ns is None:  # the first release: the span and its warning, of every sample
            self._span_ns = (self.start_ns, self.end_ns)
            self._span_text = self.span_warning()
        dropped = list(self.channels) if names is None else [name for name in names if name in self.channels]
        if names is None:  # aligned for the last time: a window's whole-file times go too
            self.whole_times, self.whole_spans = {}, {}
        empty_t, empty_v = np.empty(0, dtype=np.int64), np.empty(0, dtype=np.float64)
        channels = dict(self.channels)  # a new dict: whoever holds the old one keeps its samples
        for name in dropped:
            channel = channels[name]
            self._sample_counts.setdefault(name, len(channel))
            channels[name] = Channel(name, empty_t, empty_v, channel.unit)
        self.channels = channels

    def read_as_window(
        self, span_ns: tuple[int, int], whole_times: dict[str, WholeTimes], zero_ns: int | None = None
    ) -> None:
        """This log holds a window of its file (`logscan.readers.mcap.window`): its span and its
        channels' times across the whole file come from the file's index, not the samples read;
        ``zero_ns``: the time zero the window was cut from (None: the span's first time)."""
        partial = self.span_warning()  # of the samples read: not the log's
        if partial in self.source.warnings:
            self.source.warnings.remove(partial)
        self._span_ns = span_ns
        self.whole_times = whole_times
        self.window_zero_ns = span_ns[0] if zero_ns is None else zero_ns
        timed = [name for name in self.channels if name in whole_times and whole_times[name].size]
        if self.duration_s > MAX_SPAN_S and timed:  # named as the whole read names them
            first = min(timed, key=lambda name: whole_times[name].first)
            last = max(timed, key=lambda name: whole_times[name].last)
            self._span_text = _span_text(self.duration_s, first, last)
            if self._span_text not in self.source.warnings:
                self.source.warnings.append(self._span_text)

    def span_warning(self) -> str | None:
        """A warning when the log spans more than MAX_SPAN_S, else None."""
        if self.duration_s <= MAX_SPAN_S:
            return None
        if self._span_text is not None:  # samples released: the text computed while they were here
            return self._span_text
        timed = {name: c for name, c in self.channels.items() if len(c)}
        if not timed:
            return _span_text(self.duration_s, None, None)
        ends = {name: _extremes(channel.t) for name, channel in timed.items()}  # each channel's once
        first = min(timed, key=lambda name: ends[name][0])
        last = max(timed, key=lambda name: ends[name][1])
        return _span_text(self.duration_s, first, last)

    @classmethod
    def without_samples(cls, spans: dict[str, tuple[int, int | None, int | None]], source: SourceInfo) -> Log:
        """A log whose channels were read and counted but not kept (``spans``: name -> (samples,
        first ns, last ns)), as `release_samples` leaves one: what a streaming reader returns."""
        empty_t, empty_v = np.empty(0, dtype=np.int64), np.empty(0, dtype=np.float64)
        log = cls.__new__(cls)
        log.channels = {name: Channel(name, empty_t, empty_v) for name in spans}
        log.source, log.truth, log.profile_text = source, None, None
        # a channel with samples has its first and last times
        timed = cast(dict[str, tuple[int, int, int]], {name: span for name, span in spans.items() if span[0]})
        log._sample_counts = {name: span[0] for name, span in spans.items()}
        log._span_ns = None
        log._span_text = None
        log.whole_times, log.whole_spans = {}, {}
        log.window_zero_ns = None
        if timed:
            first = min(timed, key=lambda name: timed[name][1])
            last = max(timed, key=lambda name: timed[name][2])
            log._span_ns = (timed[first][1], timed[last][2])
            log._span_text = _span_text(log.duration_s, first, last)
        warning = log.span_warning()
        if warning and warning not in source.warnings:
            source.warnings.append(warning)
        return log

    @property
    def start_ns(self) -> int | None:
        return self._span()[0]

    @property
    def origin_ns(self) -> int | None:
        """Time zero of the log's own clock, the same whichever topics were read: a ULog's start
        timestamp (the logger's start), else the first sample read (`start_ns`)."""
        start_us = self.source.metadata.get("ulog.log", {}).get("start_timestamp_us")
        try:
            origin = int(start_us) * 1000 if start_us is not None else None
        except ValueError:
            origin = None
        if origin is None or origin <= 0:
            return self.start_ns  # no logger start: the first sample read
        lasts = [t.last_ns for t in self.source.topics.values() if t.last_ns is not None]
        if origin > MAX_NS or (lasts and origin > max(lasts)):
            # a damaged header (2**64 - 1 us is 1.8e22 ns, no int64): a logger start after every
            # message of the file is no time zero; the first sample read is
            warning = (
                f"the ULog header's start timestamp ({start_us} us) lies after every message of the file: "
                "time zero is the first sample read"
            )
            if warning not in self.source.warnings:
                self.source.warnings.append(warning)
            return self.start_ns
        # kept even when a topic has samples before it (an appended log's early messages): time
        # zero must not move with the topics a profile or detector reads
        return origin

    @property
    def end_ns(self) -> int | None:
        return self._span()[1]

    def _span(self) -> tuple[int | None, int | None]:
        """(first, last) time of the log: kept (`release_samples`, `read_as_window`), else of the
        samples held, one pass over each distinct time array (a ULog's 2,000 channels share a
        hundred), else of the topics' first and last times (None where nothing tells)."""
        if self._span_ns is not None:
            return self._span_ns
        extremes = [_extremes(t) for t in _distinct_times(self.channels)]
        if extremes:
            return min(first for first, _ in extremes), max(last for _, last in extremes)
        topics = self.source.topics.values()
        firsts = [t.first_ns for t in topics if t.first_ns is not None]
        lasts = [t.last_ns for t in topics if t.last_ns is not None]
        return (min(firsts) if firsts else None), (max(lasts) if lasts else None)

    @property
    def duration_s(self) -> float:
        start, end = self._span()
        if start is None or end is None:
            return 0.0
        return (end - start) / 1e9

    def channel(self, name: str) -> Channel:
        """The channel called ``name``; a KeyError names close matches."""
        try:
            return self.channels[name]
        except KeyError:
            import difflib

            close = difflib.get_close_matches(name, list(self.channels), n=3, cutoff=0.5)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise KeyError(f"no channel {name!r} in {self.source.path}{hint}") from None

    def summary(self) -> dict[str, Any]:
        """JSON-ready facts used by `inspect --json` and report headers."""
        return {
            "file": self.source.path,
            "format": self.source.format,
            "start_ns": self.start_ns,
            "end_ns": self.end_ns,
            "duration_s": round(self.duration_s, 9),
            "time_unit": self.source.time_unit,
            "time_source": self.source.time_source,
            "partial": self.source.partial,
            "partial_reason": self.source.partial_reason,
            "topics": {name: info.to_dict() for name, info in self.source.topics.items()},
            "channels": {
                name: {"samples": self._sample_counts.get(name, len(ch)), "unit": ch.unit}
                for name, ch in self.channels.items()
            },
            "skipped": [s.to_dict() for s in self.source.skipped],
            "warnings": list(self.source.warnings),
            "has_truth": self.truth is not None,
            "has_profile": self.profile_text is not None,
        }


# Told the bytes of a time array each step of `_extremes` has read: a reader that keeps its arrays
# on disk (`logscan.readers.spill`) gives their pages back as the log's span is found
TIMES_READ: list[Callable[[int], None]] = []
TIMES_CHUNK = 1 << 20  # elements per step of a pass over a whole array of a log (`read_in_chunks`)


def _extremes(t: np.ndarray) -> tuple[int, int]:
    """(min, max) of a non-empty time array, in one pass a chunk at a time."""
    if t.size <= TIMES_CHUNK:  # one chunk: without the generator (a ULog read has a hundred arrays)
        times_read(t.nbytes)
        return int(np.minimum.reduce(t)), int(np.maximum.reduce(t))
    parts = [(np.minimum.reduce(part), np.maximum.reduce(part)) for part in read_in_chunks(t, TIMES_CHUNK)]
    return int(min(low for low, _ in parts)), int(max(high for _, high in parts))


def read_in_chunks(array: np.ndarray, size: int = TIMES_CHUNK, overlap: int = 0) -> Iterator[np.ndarray]:
    """``array`` ``size`` elements at a time, each chunk with the ``overlap`` elements after it (a
    pair across a border is seen in the chunk before it), the bytes of each told to `TIMES_READ`
    once it is used: a long log's arrays held on disk are not touched whole at once."""
    for lo in range(0, max(array.size - overlap, 0), size):
        part = array[lo : lo + size + overlap]
        yield part
        times_read(part.nbytes)


def times_read(size: int) -> None:
    """Tell `TIMES_READ` that a pass over a time array has read ``size`` more bytes of it."""
    for told in TIMES_READ:
        told(size)


def _distinct_times(channels: dict[str, Channel]) -> list[np.ndarray]:
    """The channels' non-empty ``t`` arrays, each once: a reader gives a topic's channels one shared
    array (a ULog topic of 100 fields), so the log's span takes its min and max once."""
    distinct = {id(c.t): c.t for c in channels.values()}
    return [t for t in distinct.values() if t.size]


def _span_text(duration_s: float, first: str | None, last: str | None) -> str:
    ends = f" (from {first} to {last})" if first is not None else ""
    return (
        f"the log spans {duration_s / 86_400.0:.1f} days{ends}: more than a day, so it may join "
        "several logs or read a time column in the wrong unit; analyse each log on its own, or state "
        "the time unit (e.g. a column named time_s)"
    )


# --- the autopilot's own logged messages (a ULog's `ulog.messages` metadata) -----------------------

MAX_MESSAGES = 200
MESSAGE_LEVELS = ("EMERGENCY", "ALERT", "CRITICAL", "ERROR", "WARNING")
_MESSAGE = re.compile(r"^\s*(?P<t>[-+0-9.eE]+) s \[(?P<level>[A-Z]+)\] (?P<text>.*)$", re.S)


@dataclass
class LoggedMessage:
    """One message the autopilot logged: time (s since the log's start, and as the log's ns), level,
    text."""

    t: float
    level: str
    text: str
    t_ns: int = 0


def logged_messages(
    metadata: dict, start_ns: int, levels: tuple[str, ...] = MESSAGE_LEVELS, limit: int | None = MAX_MESSAGES
) -> list[LoggedMessage]:
    """The log's own messages of ``levels`` (default: WARNING and above), in time order, at most
    ``limit``: a ULog's ``ulog.messages`` metadata (on the clock of its channels)."""
    out = []
    for line in (metadata or {}).get("ulog.messages", {}).values():
        match = _MESSAGE.match(str(line))
        if match is None or match.group("level") not in levels:
            continue
        try:
            t_ns = round(float(match.group("t")) * 1e6) * 1000  # written in microseconds
        except ValueError:
            continue
        out.append(LoggedMessage((t_ns - start_ns) / 1e9, match.group("level"), match.group("text").strip(), t_ns))
        if limit is not None and len(out) >= limit:
            break
    return out
