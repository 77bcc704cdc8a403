"""A window of a log read whole (`held_window`): block mode's read of a format that has no index to
read a window from (a PX4 ULog, a ROS 1 bag or rosbag2 folder, ulog2csv's CSV folder), when a
built-in profile has read it whole already to build itself.

That read is held once (`HeldLog`, kept in `ReadWindow.plans` for the file's next window) and
each block gets views of the samples it needs, as an indexed MCAP file's window read gives them
(`logscan.readers.mcap.window`): every sample from ``margin_s`` before the window to ``margin_s``
after it, and before that, per time array, the samples from where the hold of each of its channels
into the window starts (its last finite sample that is the last at its time, as alignment cleans
them); the log's span and each channel's times across the whole log (`WholeTimes`) come from the
whole read. Those times are the ones alignment would find in the whole log (`clean_samples`:
sorted, a time logged twice once, the non-finite samples out), so the grid's span and phase are
those of the analysis at once. The held samples are views, not copies: a window costs what the
block's analysis holds, not a second log. What differs from the analysis of the whole log at once
is block mode's (docs/algorithms.md section 8.1b).
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace

import numpy as np

from logscan.align.sample_hold import clean_samples, time_order
from logscan.log import TIMES_CHUNK, Channel, Log, WholeTimes, read_in_chunks
from logscan.readers import spill
from logscan.readers.common import ReadWindow, file_stat

_NS = 1_000_000_000
_BATCH = TIMES_CHUNK  # times per batch of `WholeTimes.batches`, values per step of `_finite_count`
_LOOK_BACK = 1024  # samples looked at per step back to a channel's last finite sample


@dataclass
class HeldLog:
    """A log read whole, held for the windows of it: the file's stat when read (a changed file is
    read again), the topics it was read for, and what `whole_times` found in it once: its channels'
    times across it, the channels without a finite sample (no hold starts in them) and the time
    arrays (their ids) out of order (a window holds all of theirs)."""

    log: Log
    stat: tuple
    topics: frozenset[str]
    times: dict[str, WholeTimes] = field(default_factory=dict)
    never_finite: frozenset[str] = frozenset()
    out_of_order: frozenset[int] = frozenset()
    span: tuple[int | None, int | None] | None = None  # the log's first and last time (ns)

    def __post_init__(self) -> None:
        if self.span is None:  # each a pass over every time array: once, not once per window
            self.span = (self.log.start_ns, self.log.end_ns)


def held_window(path: str, window: ReadWindow, topics: frozenset[str], read: Callable[[], Log]) -> Log:
    """The ``window`` of the log at ``path`` read whole for ``topics``: the one ``window.plans``
    holds, else ``read()``'s, held there for the next window."""
    plans = window.plans if window.plans is not None else {}
    held = plans.get(path)
    stat = file_stat(path)
    if not isinstance(held, HeldLog) or held.stat != stat or held.topics != topics:
        log = read()
        with spill.spilling(any(spill.on_disk(channel.t) for channel in log.channels.values())):
            found = whole_times(log)  # a long log held on disk: the cleaned times there too
            narrow(log)
            held = plans[path] = HeldLog(log, stat, topics, *found)
    return window_of(held, window)


def narrow(log: Log) -> None:
    """Hold each channel's values as float32 where float32 holds every one of them exactly (a ULog's
    float, 8 to 16-bit and small integer fields: most of a PX4 log, half the bytes), the others as
    float64 copies of their own (a topic's fields are rows of one array, kept whole by any row left);
    each window's channels are float64 again (`_cut`). In place: the log is the held read's alone.
    Channels read as float32 already (`read_log`'s ``held``) or kept on disk (`logscan.readers.spill`) are
    kept as they are."""
    channels = {}
    for name, channel in log.channels.items():
        values = channel.values
        if values.dtype == np.float32 or spill.on_disk(values):  # on disk: held without memory
            channels[name] = channel
            continue
        narrowed = values.astype(np.float32)
        exact = np.array_equal(narrowed, values, equal_nan=True)  # compared as float64: exactly
        channels[name] = Channel.held(name, channel.t, narrowed if exact else values.copy(), channel.unit)
    log.channels = channels


def widened(log: Log) -> Log:
    """``log`` with its channels float64 (in place): a log read to be held (`read_log`'s ``held``)
    but analysed whole after all; each topic's float32 array goes once its last channel is widened."""
    for name, channel in log.channels.items():
        if channel.values.dtype != np.float64:  # `Channel` casts, a signalling NaN made quiet without a warning
            log.channels[name] = Channel(name, channel.t, channel.values, channel.unit)
    return log


def whole_times(log: Log) -> tuple[dict[str, WholeTimes], frozenset[str], frozenset[int]]:
    """(each channel's times across ``log`` as alignment cleans them, as `WholeTimes`: the channels
    of one time array whose samples are all finite share one; the channels without a finite sample;
    the ids of the time arrays out of order)."""
    orders: dict = {}  # id of a time array -> its `time_order`, found once
    shared: dict[int, WholeTimes] = {}
    times: dict[str, WholeTimes] = {}
    never: list[str] = []
    for name, channel in log.channels.items():
        if not len(channel):
            never.append(name)
            continue
        key = id(channel.t)
        order = orders.get(key)
        if order is None:
            order = orders[key] = time_order(channel.t)
        finite = _finite_count(channel.values)
        if finite == len(channel):
            found = shared.get(key)
            if found is None:  # a copy when the times were out of order or logged twice: on disk too
                clean = order.t_clean
                found = shared[key] = _times_of(clean if clean is channel.t else spill.copied(clean))
            times[name] = found
        elif finite and order.sort is None and order.keep is None:  # in order: its finite samples' times
            times[name] = _times_of(_finite_times(channel.t, channel.values, finite))
        elif finite:
            cleaned = clean_samples(channel.t, channel.values, order)
            if cleaned.t.size:
                times[name] = _times_of(spill.copied(cleaned.t))
        else:
            never.append(name)
    return times, frozenset(never), frozenset(key for key, order in orders.items() if order.unsorted)


def _finite_count(values: np.ndarray) -> int:
    """How many of ``values`` are finite, `_BATCH` at a time: a long log's channel on disk is not
    touched whole at once, nor a mask of its length made."""
    return sum(int(np.count_nonzero(np.isfinite(part))) for part in read_in_chunks(values, _BATCH))


def _finite_times(t: np.ndarray, values: np.ndarray, count: int) -> np.ndarray:
    """The times of the ``count`` finite ``values`` (what `clean_samples` keeps of times in order,
    each once), `_BATCH` at a time into an array of `spill.empty`: a long log's channel is not
    copied whole as float64."""
    kept = spill.empty(count, t.dtype)
    at = 0
    for lo in range(0, t.size, _BATCH):
        part = t[lo : lo + _BATCH][np.isfinite(values[lo : lo + _BATCH])]
        kept[at : at + part.size] = part
        at += part.size
        spill.passed(part.nbytes + min(_BATCH, t.size - lo) * (t.itemsize + values.itemsize))
    return kept


def _times_of(unique: np.ndarray) -> WholeTimes:
    """Sorted, unique times as `WholeTimes`."""

    def batches() -> Iterator[np.ndarray]:
        return read_in_chunks(unique, _BATCH)

    def fetch(lo_ns: int, hi_ns: int) -> np.ndarray:
        return unique[np.searchsorted(unique, lo_ns, "left") : np.searchsorted(unique, hi_ns, "right")]

    return WholeTimes(int(unique.size), int(unique[0]), int(unique[-1]), batches, fetch)


def window_of(held: HeldLog, window: ReadWindow) -> Log:
    """The window of ``held``'s log (module docstring): a new `Log` of views of its samples, the
    channels of one time array sharing one, with its own copy of the source facts (an analysis
    adds warnings to them)."""
    spill.give_back()  # the block before's pages of a log held on disk
    whole = held.log
    origin = whole.origin_ns
    margin = round(window.margin_s * _NS)
    lo = None if window.start_s is None or origin is None else origin + round(window.start_s * _NS) - margin
    hi = None if window.end_s is None or origin is None else origin + round(window.end_s * _NS) + margin
    by_time: dict[int, list[Channel]] = {}
    for channel in whole.channels.values():
        by_time.setdefault(id(channel.t), []).append(channel)
    cuts: dict[str, Channel] = {}
    for group in by_time.values():
        bounds = _bounds(held, group, lo, hi)
        t = None if bounds is None else group[0].t[bounds[0] : bounds[1]]  # one view for the group
        cuts.update((channel.name, _cut(channel, bounds, t)) for channel in group)
    source = replace(
        whole.source,
        topics=dict(whole.source.topics),
        skipped=copy.deepcopy(whole.source.skipped),
        warnings=list(whole.source.warnings),
        unread=list(whole.source.unread),
    )
    channels = {name: cuts[name] for name in whole.channels}  # in the read's order
    log = Log(channels=channels, source=source, truth=whole.truth, profile_text=whole.profile_text)
    start, end = held.span or (None, None)
    if start is not None and end is not None and origin is not None:
        log.read_as_window((start, end), held.times, zero_ns=origin)
    return log


def _bounds(held: HeldLog, group: list[Channel], lo: int | None, hi: int | None) -> tuple[int, int] | None:
    """The samples of the channels ``group`` (one time array) a window from ``lo`` to ``hi`` ns
    needs, as (first, end) indices: from the earliest of their holds' starts (`_hold_start`); None
    for all of them: no window, or times out of order."""
    t = group[0].t
    if lo is None and hi is None or t.size < 2 or id(t) in held.out_of_order:
        return None
    end = t.size if hi is None else int(np.searchsorted(t, hi, "right"))
    if lo is None:
        return 0, end
    at = int(np.searchsorted(t, lo, "left"))
    starts = [_hold_start(t, c.values, at) for c in group if c.name not in held.never_finite]
    return min(starts, default=at), end


def _cut(channel: Channel, bounds: tuple[int, int] | None, t: np.ndarray | None) -> Channel:
    """``channel``'s samples within ``bounds``, at ``t`` (the view of its time array its group
    shares, as the read's channels of one topic share their array), its values float64: a view of
    the held ones, or a copy of those held as float32 (`narrow`)."""
    if bounds is None or t is None or bounds == (0, channel.t.size):
        if channel.values.dtype == np.float64:
            return channel
        t, values = channel.t, channel.values
    else:
        values = channel.values[bounds[0] : bounds[1]]
    cut = object.__new__(Channel)  # arrays already checked (`Channel.sharing_time`)
    cut.name, cut.unit, cut.t = channel.name, channel.unit, t
    with np.errstate(invalid="ignore"):  # a float32 signalling NaN made quiet, as `Channel` makes it
        cut.values = values.astype(np.float64, copy=False)
    return cut


def _hold_start(t: np.ndarray, values: np.ndarray, at: int) -> int:
    """The first index at the time of the last sample before index ``at`` that a hold into the
    window starts from: finite and the last at its time (cleaning keeps the last of a time logged
    twice); ``at`` when there is none."""
    end = at
    while end > 0:
        begin = max(end - _LOOK_BACK, 0)
        kept = np.isfinite(values[begin:end])
        kept[:-1] &= t[begin + 1 : end] != t[begin : end - 1]
        if end < t.size:
            kept[-1] &= t[end] != t[end - 1]
        found = np.flatnonzero(kept)
        if found.size:
            return int(np.searchsorted(t[:at], t[begin + found[-1]], "left"))
        end = begin
    return at
