"""What a window read of an indexed MCAP file learns that does not depend on the window
(`FilePlan`): the top-level records, the wanted channels' Message Index records (each one's first
and last time and where its times lie, `window.ChannelIndex`) and each wanted topic's times across
the file (`Log.WholeTimes`: read again from the index when asked; alignment keeps what it finds in
them there). Found by the first window read of the file and kept in the window's ``plans``
(`ReadWindow.plans`), so that block mode reads them once for all its blocks, each block then
reading only its own chunks (issue 29, item 2).

A topic's times are read from the index a batch of records at a time: their records sorted by
first time and cut where no record before reaches past the next one's first time (records
overlapping in time are sorted together), so each batch, sorted and made unique, follows the one
before. Memory: a batch, not the file's times; the file's pages read are given back every few
MiB (`GIVE_BACK_RECORDS`).
"""

from __future__ import annotations

import mmap
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from logscan.log import WholeTimes
from logscan.memory import drop_mapped_pages
from logscan.readers.common import file_stat
from logscan.readers.mcap.records import Records
from logscan.readers.mcap.window import ChannelIndex, channel_index, record_times

BATCH_TIMES = 1 << 20  # index times read at a time for a pass over a topic's (8 MiB)
GIVE_BACK_RECORDS = 16  # index records read before the file's pages read are given back (a few MiB of file)


@dataclass
class FilePlan:
    """One file's plan for the channels ``wanted``: its size and modification time when planned
    (a file changed since is planned again), its top-level records, its channels' index (None: no
    window of it can be read, it is read whole), each wanted topic's times."""

    stat: tuple[int, int]
    top: Records
    wanted: frozenset[int]
    index: dict[int, ChannelIndex] | None
    times: dict[str, WholeTimes]


def known_top(plans: dict | None, path: str) -> Records | None:
    """The top-level records of ``path`` a window read before found, if the file is unchanged."""
    plan = plans.get(path) if plans is not None else None
    return plan.top if plan is not None and plan.stat == file_stat(path) else None


def file_plan(
    path: str,
    plans: dict | None,
    u8: np.ndarray,
    top: Records,
    wanted: set[int],
    topics: dict[int, str],
    give_back: Callable[[int], None],
) -> FilePlan:
    """The plan of ``path`` (mapped as ``u8``, walked into ``top``) for the channels ``wanted``:
    the one in ``plans`` when it is of the same file and channels, else found and kept there.
    ``topics``: channel id -> topic of every channel the summary defines."""
    stat = file_stat(path)
    plan = plans.get(path) if plans is not None else None
    if plan is not None and plan.stat == stat and plan.wanted == frozenset(wanted):
        return plan
    index = channel_index(u8, top, wanted, set(topics), give_back)
    times: dict[str, WholeTimes] = {}
    if index is not None:
        by_topic: dict[str, list[ChannelIndex]] = {}
        for cid, entry in index.items():
            if entry.at is not None:
                by_topic.setdefault(topics[cid], []).append(entry)
        times = {topic: _whole_times(path, entries) for topic, entries in by_topic.items()}
    plan = FilePlan(stat, top, frozenset(wanted), index, times)
    if plans is not None:
        plans[path] = plan
    return plan


def _whole_times(path: str, entries: list[ChannelIndex]) -> WholeTimes:
    """The times of one topic's channels ``entries`` across the file ``path`` (sorted, a time
    logged twice once: as alignment cleans them), read from its index when asked."""
    at = np.concatenate([e.at for e in entries if e.at is not None])
    counts = np.concatenate([e.counts for e in entries if e.counts is not None])
    firsts = np.concatenate([e.firsts for e in entries if e.firsts is not None])
    lasts = np.concatenate([e.lasts for e in entries if e.lasts is not None])
    order = np.argsort(firsts, kind="stable")
    at, counts, firsts, lasts = at[order], counts[order], firsts[order], lasts[order]
    bounds = _batch_bounds(firsts, lasts, counts)

    def batches() -> Iterator[np.ndarray]:
        with _Mapped(path) as mapped:
            for lo, hi in zip(bounds[:-1], bounds[1:]):
                yield _sorted_unique(mapped.times(at[lo:hi], counts[lo:hi]))

    def fetch(lo_ns: int, hi_ns: int) -> np.ndarray:
        near = (lasts >= lo_ns) & (firsts <= hi_ns)
        with _Mapped(path) as mapped:
            t = _sorted_unique(mapped.times(at[near], counts[near]))
        return t[(t >= lo_ns) & (t <= hi_ns)]

    return WholeTimes(int(counts.sum()), int(firsts.min()), int(lasts.max()), batches, fetch)


class _Mapped:
    """The file mapped read-only as ``u8`` while in a ``with``, its index times read with the pages
    given back as they go (`times`)."""

    def __init__(self, path: str):
        self.path = path

    def __enter__(self) -> _Mapped:
        self._fh = open(self.path, "rb")  # noqa: SIM115 - closed in __exit__
        self._map = mmap.mmap(self._fh.fileno(), 0, access=mmap.ACCESS_READ)
        self.u8 = np.frombuffer(self._map, dtype=np.uint8)
        return self

    def times(self, at: np.ndarray, counts: np.ndarray) -> np.ndarray:
        """`record_times` of the records at ``at``, `GIVE_BACK_RECORDS` at a time, the pages before
        the last one read given back after each: reading a record maps the whole folio around it
        (up to megabytes), and a topic's records lie one after each chunk, all over the file."""
        times = np.empty(int(counts.sum()), dtype=np.int64)
        into = 0
        for lo in range(0, at.size, GIVE_BACK_RECORDS):
            part = record_times(self.u8, at[lo : lo + GIVE_BACK_RECORDS], counts[lo : lo + GIVE_BACK_RECORDS])
            times[into : into + part.size] = part
            into += part.size
            drop_mapped_pages(self._map, int(at[lo : lo + GIVE_BACK_RECORDS].max()))
        return times

    def __exit__(self, *exc) -> None:
        del self.u8
        self._map.close()
        self._fh.close()


def _batch_bounds(firsts: np.ndarray, lasts: np.ndarray, counts: np.ndarray) -> list[int]:
    """Where the batches of the records (sorted by first time) start and end: about `BATCH_TIMES`
    times each, cut only where no record before reaches the next one's first time."""
    if not firsts.size:
        return [0]
    reach = np.maximum.accumulate(lasts)
    starts = np.flatnonzero(np.concatenate(([True], firsts[1:] > reach[:-1])))  # records nothing overlaps
    before = (np.cumsum(counts) - counts)[starts]  # the times of the records before each
    bounds = [0]
    while bounds[-1] < firsts.size:
        j = int(np.searchsorted(before, before[np.searchsorted(starts, bounds[-1])] + BATCH_TIMES))
        bounds.append(int(starts[j]) if j < starts.size else int(firsts.size))
    return bounds


def _sorted_unique(t: np.ndarray) -> np.ndarray:
    if t.size > 1 and np.any(t[1:] < t[:-1]):
        t.sort(kind="stable")
    if t.size > 1:
        repeated = t[1:] == t[:-1]
        if repeated.any():
            t = t[np.concatenate(([True], ~repeated))]
    return t
