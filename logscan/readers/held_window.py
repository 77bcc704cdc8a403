"""A window of a log read whole (`held_window`): block mode's read of a format that has no index to
read a window from (a ULog, a ROS 1 bag, a CSV log), when a built-in profile has read it whole
already to build itself.

That read is held once (`HeldLog`, kept in `ReadWindow.plans` for the file's next window) and
each block gets views of the samples it needs, as an indexed MCAP file's window read gives them
(`logscan.readers.mcap.window`): every sample from ``margin_s`` before the window to ``margin_s``
after it, and before that each channel's samples from its last finite one (a hold into the window
starts there, however stale its limit lets it be); the log's span and each channel's times across
the whole log (`WholeTimes`, sorted and unique, one per time array: alignment finds the grid's
span and phase from them once) come from the whole read. The held read's samples are views, not
copies: the window costs what the block's analysis holds, not a second log. What differs from the
analysis of the whole log at once is block mode's (docs/algorithms.md section 8.1b).
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace

import numpy as np

from logscan.log import Channel, Log, WholeTimes
from logscan.readers.common import ReadWindow, file_stat

_NS = 1_000_000_000
_BATCH = 1 << 20  # times per batch of `WholeTimes.batches`
_LOOK_BACK = 1024  # samples looked at per step back to a channel's last finite sample


@dataclass
class HeldLog:
    """A log read whole, held for the windows of it: the file's stat when read (a changed file is
    read again), the topics it was read for, and its channels' times across it."""

    log: Log
    stat: tuple
    topics: frozenset[str]
    times: dict[str, WholeTimes] = field(default_factory=dict)
    in_order: dict[int, bool] = field(default_factory=dict)  # id of a time array -> whether sorted


def held_window(path: str, window: ReadWindow, topics: frozenset[str], read: Callable[[], Log]) -> Log:
    """The ``window`` of the log at ``path`` read whole for ``topics``: the one ``window.plans``
    holds, else ``read()``'s, held there for the next window."""
    plans = window.plans if window.plans is not None else {}
    held = plans.get(path)
    stat = file_stat(path)
    if not isinstance(held, HeldLog) or held.stat != stat or held.topics != topics:
        log = read()
        held = plans[path] = HeldLog(log, stat, topics, whole_times(log))
    return window_of(held, window)


def whole_times(log: Log) -> dict[str, WholeTimes]:
    """Each channel's times across ``log`` as `WholeTimes` (channels sharing a time array share one)."""
    shared: dict[int, WholeTimes] = {}
    times: dict[str, WholeTimes] = {}
    for name, channel in log.channels.items():
        if len(channel):
            found = shared.get(id(channel.t))
            if found is None:
                found = shared[id(channel.t)] = _times_of(channel.t)
            times[name] = found
    return times


def _times_of(t: np.ndarray) -> WholeTimes:
    """``t`` sorted, a time logged twice once (as alignment cleans them), as `WholeTimes`."""
    steps = np.diff(t)
    unique = t if bool((steps > 0).all()) else np.unique(t)

    def batches() -> Iterator[np.ndarray]:
        for lo in range(0, unique.size, _BATCH):
            yield unique[lo : lo + _BATCH]

    def fetch(lo_ns: int, hi_ns: int) -> np.ndarray:
        return unique[np.searchsorted(unique, lo_ns, "left") : np.searchsorted(unique, hi_ns, "right")]

    return WholeTimes(int(unique.size), int(unique[0]), int(unique[-1]), batches, fetch)


def window_of(held: HeldLog, window: ReadWindow) -> Log:
    """The window of ``held``'s log (module docstring): a new `Log` of views of its samples, with
    its own copy of the source facts (an analysis adds warnings to them)."""
    whole = held.log
    origin = whole.origin_ns
    margin = round(window.margin_s * _NS)
    lo = None if window.start_s is None or origin is None else origin + round(window.start_s * _NS) - margin
    hi = None if window.end_s is None or origin is None else origin + round(window.end_s * _NS) + margin
    bounds: dict[int, tuple[int, int] | None] = {}  # per time array: the window's indices, None: all
    channels = {}
    for name, channel in whole.channels.items():
        key = id(channel.t)
        if key not in bounds:
            bounds[key] = _bounds(held, channel.t, lo, hi)
        channels[name] = _cut(channel, bounds[key])
    source = replace(
        whole.source,
        topics=dict(whole.source.topics),
        skipped=copy.deepcopy(whole.source.skipped),
        warnings=list(whole.source.warnings),
        unread=list(whole.source.unread),
    )
    log = Log(channels=channels, source=source, truth=whole.truth, profile_text=whole.profile_text)
    start, end = whole.start_ns, whole.end_ns
    if start is not None and end is not None:
        log.read_as_window((start, end), held.times)
    return log


def _bounds(held: HeldLog, t: np.ndarray, lo: int | None, hi: int | None) -> tuple[int, int] | None:
    """The indices of ``t`` from ``lo`` to ``hi`` ns (either None: that end); None for every
    sample: neither given, or times out of order (`HeldLog.in_order`, found once per array)."""
    if lo is None and hi is None or t.size < 2:
        return None
    in_order = held.in_order.get(id(t))
    if in_order is None:
        in_order = held.in_order[id(t)] = bool((t[1:] >= t[:-1]).all())
    if not in_order:
        return None
    first = 0 if lo is None else int(np.searchsorted(t, lo, "left"))
    return first, t.size if hi is None else int(np.searchsorted(t, hi, "right"))


def _cut(channel: Channel, bounds: tuple[int, int] | None) -> Channel:
    """``channel``'s samples within ``bounds`` and, before them, from its last finite sample (every
    sample at that time): views of its arrays."""
    if bounds is None:
        return channel
    first, last = _hold_start(channel.t, channel.values, bounds[0]), bounds[1]
    if first == 0 and last == channel.t.size:
        return channel
    cut = object.__new__(Channel)  # views of arrays already checked (`Channel.sharing_time`)
    cut.name, cut.unit = channel.name, channel.unit
    cut.t, cut.values = channel.t[first:last], channel.values[first:last]
    return cut


def _hold_start(t: np.ndarray, values: np.ndarray, at: int) -> int:
    """The first index of the samples at the time of the last finite sample before index ``at``
    (``at``: none)."""
    end = at
    while end > 0:
        begin = max(end - _LOOK_BACK, 0)
        finite = np.flatnonzero(np.isfinite(values[begin:end]))
        if finite.size:
            return int(np.searchsorted(t[:at], t[begin + finite[-1]], "left"))
        end = begin
    return at
