"""MCAP records: opcodes, the numba walk that finds record boundaries, the numba pass that groups a
container's messages by channel, vectorised field gathers, a field cursor."""

from __future__ import annotations

import struct
from typing import NamedTuple

import numpy as np
from numba import njit

from logscan.numba_cache import follow_dependencies
from logscan.readers.bits import load_u64

OP_FOOTER = 0x02
OP_SCHEMA = 0x03
OP_CHANNEL = 0x04
OP_MESSAGE = 0x05
OP_CHUNK = 0x06
OP_MESSAGE_INDEX = 0x07
OP_STATISTICS = 0x0B
OP_METADATA = 0x0C
OP_METADATA_INDEX = 0x0D
OP_DATA_END = 0x0F
MESSAGE_HEADER = 22  # channel_id u16, sequence u32, log_time u64, publish_time u64

# What a corrupt byte stream can make the parsing code raise; anything else is a bug and propagates.
PARSE_ERRORS = (struct.error, ValueError, UnicodeDecodeError, IndexError, OverflowError, MemoryError)


# how a record walk ended
WALK_END = 0  # reached the end of the buffer exactly
WALK_FOOTER = 1  # stopped after a Footer record
WALK_TRUNCATED = 2  # a record header or body runs past the end of the buffer
_LENGTH_LIMIT = np.uint64(1 << 48)
WALK_BAD_OPCODE = 3  # an opcode the MCAP specification reserves (0x00, 0x10-0x7f): misaligned or corrupt


@njit(cache=True)
def _walk_records(buf, start, stop, ops, offsets, lengths):  # pragma: no cover - compiled
    """Opcode, body offset and body length of each whole record in buf[start:stop] (the arrays
    hold one per 9 bytes, the most there can be); how many, the offset where the walk ended, and why."""
    n = 0
    pos = start
    while pos < stop:
        if pos + 9 > stop:
            return n, pos, WALK_TRUNCATED
        op = buf[pos]
        if op == 0 or (op >= 0x10 and op < 0x80):
            return n, pos, WALK_BAD_OPCODE
        word = load_u64(buf, pos + 1)  # the uint64 length (inside buf[start:stop], checked above)
        if word >= _LENGTH_LIMIT:  # length >= 2**48: no real record is that long
            return n, pos, WALK_TRUNCATED
        length = np.int64(word)
        if length > stop - pos - 9:
            return n, pos, WALK_TRUNCATED
        ops[n] = op
        offsets[n] = pos + 9
        lengths[n] = length
        n += 1
        pos += 9 + length
        if op == 2:
            return n, pos, WALK_FOOTER
    return n, pos, WALK_END


WALK_TEXT = {
    WALK_END: "file ends without a footer (truncated?)",
    WALK_TRUNCATED: "record runs past the end of the file (truncated, or a corrupt record length)",
    WALK_BAD_OPCODE: "invalid record opcode (corrupt bytes)",
}


class Records(NamedTuple):
    """Where the records of a buffer lie, one entry per whole record, and how the walk ended."""

    ops: np.ndarray  # uint8
    offsets: np.ndarray  # int64, offset of the record body
    lengths: np.ndarray  # int64, body length
    end: int  # where the walk stopped
    status: int  # WALK_* code


def walk_records(u8: np.ndarray, start: int, stop: int) -> Records:
    """The records of ``u8[start:stop]``, in one compiled pass (a pass to count them and one to fill
    their places took half as long again): the arrays are made for a record per 9 bytes and only
    their first entries are written, so only those pages are touched."""
    if u8.flags.writeable:  # a read-only view (as of a mapped file): the kernels compile for one type
        u8 = u8.view()
        u8.flags.writeable = False
    most = max(0, stop - start) // 9
    ops = np.empty(most, dtype=np.uint8)
    offsets = np.empty(most, dtype=np.int64)
    lengths = np.empty(most, dtype=np.int64)
    n, end, status = _walk_records(u8, start, stop, ops, offsets, lengths)
    return Records(ops[:n], offsets[:n], lengths[:n], int(end), int(status))


MAX_LOG_TIME_NS = 2**63 - 1  # log_time is a uint64 in the file, int64 ns here
CHANNEL_IDS = 1 << 16  # channel ids are uint16
_MAX_LOG_TIME = np.uint64(MAX_LOG_TIME_NS)


class ChannelGroups(NamedTuple):
    """A container's messages (`group_messages`): in its order, the ones whose log_time int64 ns
    hold; and the same grouped by channel id (ascending), each group in the container's order."""

    short_at: int  # body offset of the first message record shorter than its header, or -1 (nothing else set)
    messages: int  # message records, the dropped ones included
    channel_ids: np.ndarray  # int64, container order (log_time beyond int64 dropped)
    log_times: np.ndarray  # int64 ns, container order
    offsets: np.ndarray  # int64 record body offsets, container order
    lengths: np.ndarray  # int64 record body lengths, container order
    group_ids: np.ndarray  # int64 channel id of each group, ascending
    bounds: np.ndarray  # int64, group g is [bounds[g], bounds[g + 1]) of the grouped arrays
    low: np.ndarray  # int64 earliest log_time of each group
    high: np.ndarray  # int64 latest log_time of each group
    grouped_times: np.ndarray  # int64 ns
    grouped_starts: np.ndarray  # int64 offset of each message's data (after its header)
    grouped_ends: np.ndarray  # int64 end of each message's data


@njit(cache=True)
def _message_fields(buf, ops, offsets, lengths, channel_ids, log_times, m_off, m_len):  # pragma: no cover
    """Channel id, log time, offset and length of each message record whose log_time int64 ns
    hold, in order; how many; -1, or the body offset of the first message shorter than its header
    (then nothing is filled)."""
    for k in range(ops.size):
        if ops[k] == OP_MESSAGE and lengths[k] < MESSAGE_HEADER:
            return 0, offsets[k]
    kept = 0
    for k in range(ops.size):
        if ops[k] != OP_MESSAGE:
            continue
        pos = offsets[k]
        raw = load_u64(buf, pos + 6)
        if raw > _MAX_LOG_TIME:  # a damaged log_time: dropped (counted by the caller)
            continue
        channel_ids[kept] = np.int64(buf[pos]) | (np.int64(buf[pos + 1]) << 8)
        log_times[kept] = np.int64(raw)
        m_off[kept] = pos
        m_len[kept] = lengths[k]
        kept += 1
    return kept, -1


@njit(cache=True)
def _group_by_channel(channel_ids, log_times, m_off, m_len, slot, groups):  # pragma: no cover - compiled
    """A stable counting sort of the messages by channel id: fills the ``groups`` arrays (ids,
    bounds, low, high, times, starts, ends) and returns how many groups. ``slot`` (int64 per
    channel id) is -1 everywhere on entry and again on return. The ids met come in ascending order
    from a scan of ``slot`` between the least and the greatest (a few ids, mostly close together),
    and each group's low and high from a loop: with numba's generic sort and slice min / max the
    kernel took 1.7 s to compile on the first run, with these loops 0.25 s."""
    ids, bounds, low, high, times, starts, ends = groups
    least, greatest = CHANNEL_IDS, -1
    for i in range(channel_ids.size):  # messages per channel id, and the span of the ids met
        c = channel_ids[i]
        if slot[c] < 0:
            slot[c] = 0
            if c < least:
                least = c
            if c > greatest:
                greatest = c
        slot[c] += 1
    n_groups = 0
    position = 0
    for c in range(least, greatest + 1):  # each id's first place in the grouped arrays
        count = slot[c]
        if count < 0:
            continue
        ids[n_groups] = c
        bounds[n_groups] = position
        slot[c] = position
        position += count
        n_groups += 1
    bounds[n_groups] = position
    for i in range(channel_ids.size):
        j = slot[channel_ids[i]]
        slot[channel_ids[i]] = j + 1
        times[j] = log_times[i]
        starts[j] = m_off[i] + MESSAGE_HEADER
        ends[j] = m_off[i] + m_len[i]
    for g in range(n_groups):
        slot[ids[g]] = -1
        earliest = latest = times[bounds[g]]  # a group holds one message at least
        for j in range(bounds[g] + 1, bounds[g + 1]):
            if times[j] < earliest:
                earliest = times[j]
            if times[j] > latest:
                latest = times[j]
        low[g] = earliest
        high[g] = latest
    return n_groups


def group_messages(
    u8: np.ndarray, ops: np.ndarray, offsets: np.ndarray, lengths: np.ndarray, slot: np.ndarray
) -> ChannelGroups:
    """The message records among ``ops``/``offsets``/``lengths`` (a container's records in ``u8``),
    by channel (`ChannelGroups`): two compiled passes instead of a gather, a mask and a stable
    argsort per field. ``slot``: int64[CHANNEL_IDS], -1 everywhere (left so)."""
    if u8.flags.writeable:  # a read-only view (as of a mapped file): the kernels compile for one type
        u8 = u8.view()
        u8.flags.writeable = False
    count = int(np.count_nonzero(ops == OP_MESSAGE))
    fields = [np.empty(count, dtype=np.int64) for _ in range(4)]
    kept, short_at = _message_fields(u8, ops, offsets, lengths, *fields)
    channel_ids, log_times, m_off, m_len = (field[:kept] for field in fields)
    groups = tuple(np.empty(size, dtype=np.int64) for size in (kept, kept + 1, kept, kept, kept, kept, kept))
    n_groups = _group_by_channel(channel_ids, log_times, m_off, m_len, slot, groups) if short_at < 0 else 0
    ids, bounds, low, high, times, starts, ends = groups
    return ChannelGroups(
        int(short_at),
        count,
        channel_ids,
        log_times,
        m_off,
        m_len,
        ids[:n_groups],
        bounds[: n_groups + 1],
        low[:n_groups],
        high[:n_groups],
        times,
        starts,
        ends,
    )


def gather_u64(u8: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Little-endian uint64 at each of ``offsets`` in ``u8`` (vectorised)."""
    if offsets.size == 0:
        return np.empty(0, dtype=np.uint64)
    idx = offsets[:, None] + np.arange(8, dtype=np.int64)[None, :]
    return np.ascontiguousarray(u8[idx]).view("<u8").reshape(-1)


def gather_u32(u8: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    out = np.zeros(offsets.size, dtype=np.int64)
    for i in range(4):
        out |= u8[offsets + i].astype(np.int64) << (8 * i)
    return out


class Cursor:
    """Field reader over one record body (bounds-checked: a short body raises struct.error)."""

    def __init__(self, data: bytes | memoryview, pos: int, end: int):
        self.data = data
        self.pos = pos
        self.end = end

    def take(self, fmt: str) -> tuple:
        size = struct.calcsize(fmt)
        if self.pos + size > self.end:
            raise struct.error("record shorter than its fields")
        values = struct.unpack_from(fmt, self.data, self.pos)
        self.pos += size
        return values

    def raw(self, size: int) -> bytes:
        if size < 0 or self.pos + size > self.end:
            raise struct.error("record shorter than its fields")
        out = bytes(self.data[self.pos : self.pos + size])
        self.pos += size
        return out

    def string(self) -> str:
        (size,) = self.take("<I")
        return self.raw(size).decode("utf-8")

    def string_map(self) -> dict[str, str]:
        (size,) = self.take("<I")
        stop = self.pos + size
        if stop > self.end:
            raise struct.error("map longer than its record")
        out: dict[str, str] = {}
        while self.pos < stop:
            key = self.string()
            out[key] = self.string()
        if self.pos != stop:
            raise ValueError("map entries overrun the map length")
        return out


follow_dependencies(__name__)  # the cached kernels are stamped with the intrinsics of `bits` too
