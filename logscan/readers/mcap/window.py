"""A window of an indexed MCAP file (`read_mcap`'s ``window``): which chunks to decode, planned
from the Message Index records alone, so a window of a long log is not read whole.

Each chunk of an indexed file is followed by one Message Index record per channel it holds (the
MCAP specification), listing every message's log time: what the whole read would have given the
window comes from them without decompressing a chunk, and what does not depend on the window is
found once per file (`logscan.readers.mcap.file_plan`: block mode reads it once for every block):
 - time zero, the first message of the wanted channels (`Log.start_ns` of the whole read);
 - the grid's span and phase: each wanted topic's times as the runs `time_sanity.outlying_runs`
   splits them into (`logscan.timebase.time_runs`), not the times themselves;
 - the chunks to decode: those holding a message of a wanted channel from ``margin_s`` before the
   window to ``margin_s`` after it, and the one holding each channel's last message before that
   (a hold reaches back as far as a channel's staleness allows, without limit for some): from
   each record's first and last time, reading the times of the records that straddle the window.
A file without a Message Index after every chunk, or with messages outside chunks, has no plan:
it is read whole. What the window read does not see is in docs/algorithms.md section 8.1.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numba import njit

from logscan.numba_cache import follow_dependencies
from logscan.readers.bits import load_u64
from logscan.readers.common import ReadWindow
from logscan.readers.mcap.records import OP_CHUNK, OP_MESSAGE, OP_MESSAGE_INDEX, Records, gather_u32

_NS = 1_000_000_000
_INT64_MAX = 2**63 - 1
# Message Index records per slice read before the file's pages read are given back: one record per
# chunk and channel, ~50 KiB of file apart in a 100 Hz quadcopter log, so a few MiB of file (a
# slice of 4096 records held ~180 MiB of a 24-hour file's pages)
_HEADS_SLICE = 128
_INDEX_HEAD = 6  # channel_id u16, then the byte length u32 of its (log_time u64, offset u64) pairs


@dataclass
class WindowPlan:
    """The chunks to decode (their records' body offsets), the log's time zero and last time, and
    what the chunks read must show for a hold into the window to be the whole read's (`before`)."""

    chunks: set[int]
    origin_ns: int
    end_ns: int
    lo_ns: int | None  # where the chunks read start to hold every message (the window less its margin)
    before: dict[int, int]  # channel id -> its last log time before lo_ns, the sample a hold starts from


def channel_index(
    u8: np.ndarray, top: Records, ids: set[int], known: set[int], give_back: Callable[[int], None]
) -> dict[int, ChannelIndex] | None:
    """The Message Index records of the channels ``ids`` (channel id -> `ChannelIndex`); None when
    the file is not indexed throughout, or indexes a channel not in ``known`` (the summary's: one
    defined only inside a chunk could be wanted). ``give_back(offset)`` hears the file offset read
    to, every few MiB: the pages before it may go (`Scan.give_back`)."""
    ops = top.ops
    if np.any(ops == OP_MESSAGE):  # messages outside chunks have no index
        return None
    chunk_at = np.flatnonzero(ops == OP_CHUNK)
    index_at = np.flatnonzero(ops == OP_MESSAGE_INDEX)
    if not chunk_at.size:
        return None
    owner = np.searchsorted(chunk_at, index_at) - 1  # an index record follows the chunk it indexes
    if np.any(owner < 0) or np.unique(owner).size != chunk_at.size:  # a chunk without an index
        return None
    body = top.offsets[index_at]
    cids, sizes = _index_heads(u8, body, give_back)
    if np.any(sizes % 16) or np.any(sizes + _INDEX_HEAD > top.lengths[index_at]):
        return None  # a damaged index: the whole read finds what is wrong
    if not set(np.unique(cids).tolist()) <= known:
        return None
    counts = sizes // 16
    firsts, lasts = _index_bounds(u8, body + _INDEX_HEAD, counts, give_back)
    if np.any(lasts > _INT64_MAX):  # a log time int64 ns cannot hold: the whole read drops and counts it
        # (a record listing no message reads 0 here)
        return None
    found: dict[int, ChannelIndex] = {}
    wanted = set(ids)
    for cid in np.unique(cids[counts > 0]).tolist():
        mine = np.flatnonzero((cids == cid) & (counts > 0))  # its records, in file order
        entry = found[cid] = ChannelIndex(int(counts[mine].sum()), int(firsts[mine].min()), int(lasts[mine].max()))
        if cid in wanted:
            entry.at, entry.counts = body[mine] + _INDEX_HEAD, counts[mine]
            entry.chunks = top.offsets[chunk_at[owner[mine]]]
            entry.firsts, entry.lasts = firsts[mine].astype(np.int64), lasts[mine].astype(np.int64)
    return found


def _index_bounds(
    u8: np.ndarray, at: np.ndarray, counts: np.ndarray, give_back: Callable[[int], None]
) -> tuple[np.ndarray, np.ndarray]:
    """The first and last log time (uint64) of each Message Index record whose pairs start at
    ``at``, a slice of records at a time, the pages read given back."""
    firsts, lasts = np.empty(at.size, dtype=np.uint64), np.empty(at.size, dtype=np.uint64)
    none, nowhere = np.empty(0, dtype=np.int64), np.full(at.size, -1, dtype=np.int64)
    for lo in range(0, at.size, _HEADS_SLICE):
        hi = min(lo + _HEADS_SLICE, at.size)
        _record_times(u8, at[lo:hi], counts[lo:hi], nowhere[lo:hi], none, firsts[lo:hi], lasts[lo:hi])
        give_back(int(at[hi - 1]))
    return firsts, lasts


def record_times(u8: np.ndarray, at: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """The log times the Message Index records whose pairs start at ``at`` list, one record after
    the other (int64: the plan checked that they fit)."""
    into = np.cumsum(counts) - counts
    times = np.empty(int(counts.sum()), dtype=np.int64)
    scratch = np.empty(at.size, dtype=np.uint64)
    _record_times(u8, at, counts, into, times, scratch, scratch.copy())
    return times


@njit(cache=True, nogil=True)
def _record_times(u8, at, counts, into, times, firsts, lasts):  # pragma: no cover - compiled
    """Record k lists counts[k] (log_time u64, offset u64) pairs from u8[at[k]]: the least and the
    greatest log time into firsts[k] and lasts[k], and the times into times[into[k]:] when into[k] >= 0."""
    for k in range(at.size):
        if counts[k] == 0:  # nothing to read: its end may be the file's (a truncated file)
            firsts[k], lasts[k] = np.uint64(0), np.uint64(0)
            continue
        first = last = load_u64(u8, at[k])
        for j in range(counts[k]):
            t = load_u64(u8, at[k] + 16 * j)
            first = min(first, t)
            last = max(last, t)
            if into[k] >= 0:
                times[into[k] + j] = np.int64(t)
        firsts[k] = first
        lasts[k] = last


def _index_heads(u8: np.ndarray, body: np.ndarray, give_back: Callable[[int], None]) -> tuple[np.ndarray, np.ndarray]:
    """(channel id, byte length of the pairs) of each Message Index record at ``body``, read a
    slice at a time with the pages given back: the records' heads lie on most of the index's pages."""
    cids, sizes = np.empty(body.size, dtype=np.int64), np.empty(body.size, dtype=np.int64)
    for lo in range(0, body.size, _HEADS_SLICE):
        at = body[lo : lo + _HEADS_SLICE]
        cids[lo : lo + at.size] = u8[at].astype(np.int64) | (u8[at + 1].astype(np.int64) << 8)
        sizes[lo : lo + at.size] = gather_u32(u8, at + 2)
        give_back(int(at[-1]))
    return cids, sizes


@dataclass
class ChannelIndex:
    """One channel's Message Index records: its message count and first and last log times, and of
    a wanted channel, per record: where its pairs start, how many it lists, the body offset of the
    chunk it indexes and its first and last log time."""

    count: int
    first: int
    last: int
    at: np.ndarray | None = None  # a wanted channel's, its records in file order
    counts: np.ndarray | None = None
    chunks: np.ndarray | None = None
    firsts: np.ndarray | None = None
    lasts: np.ndarray | None = None


def plan_window(index: dict[int, ChannelIndex], window: ReadWindow, u8: np.ndarray) -> WindowPlan | None:
    """The chunks the window needs (module docstring) of the file ``u8``; None when no wanted
    channel has a message. A chunk whose messages straddle the window is decoded even when none
    falls inside: a few samples more than needed change no hold."""
    index = {cid: entry for cid, entry in index.items() if entry.at is not None}
    if not index:
        return None
    origin = min(entry.first for entry in index.values())
    end = max(entry.last for entry in index.values())
    margin = round(window.margin_s * _NS)
    # Python ints: exact at epoch magnitudes; then within int64, to compare with the times
    lo = origin + round(window.start_s * _NS) - margin if window.start_s is not None else None
    hi = origin + round(window.end_s * _NS) + margin if window.end_s is not None else None
    lo = None if lo is None else min(max(lo, -_INT64_MAX), _INT64_MAX)
    hi = None if hi is None else min(max(hi, -_INT64_MAX), _INT64_MAX)
    chunks: set[int] = set()
    before: dict[int, int] = {}
    for cid, entry in index.items():
        mine, last_before = _chunks_of(entry, lo, hi, u8)
        chunks |= mine
        if last_before is not None:
            before[cid] = last_before
    return WindowPlan(chunks, origin, end, lo, before)


def _chunks_of(entry: ChannelIndex, lo: int | None, hi: int | None, u8: np.ndarray) -> tuple[set[int], int | None]:
    """The chunks of one channel the window from ``lo`` to ``hi`` ns (margins in) needs, and the
    time of its last message before ``lo`` (None: none). With the window's: the chunk of its first
    message (time zero is checked against it) and every chunk holding its last message before
    ``lo`` (a time logged twice: the whole read keeps the later sample)."""
    assert entry.at is not None and entry.counts is not None and entry.chunks is not None
    assert entry.firsts is not None and entry.lasts is not None
    owners, firsts, lasts = entry.chunks, entry.firsts, entry.lasts
    overlaps = np.ones(owners.size, dtype=bool)
    if lo is not None:
        overlaps &= lasts >= lo
    if hi is not None:
        overlaps &= firsts <= hi
    chunks = set(owners[overlaps].tolist()) | {int(owners[np.argmin(firsts)])}
    if lo is None or firsts.min() >= lo:
        return chunks, None
    latest = np.where(lasts < lo, lasts, np.iinfo(np.int64).min)
    for k in np.flatnonzero((firsts < lo) & (lasts >= lo)).tolist():  # records straddling lo
        t = record_times(u8, entry.at[k : k + 1], entry.counts[k : k + 1])
        latest[k] = t[t < lo].max()
    before = int(latest.max())
    return chunks | set(owners[latest == before].tolist()), before


follow_dependencies(__name__)  # the cached kernel is stamped with the intrinsics of `bits` too
