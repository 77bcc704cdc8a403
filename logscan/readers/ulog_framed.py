"""The ULog read of an undamaged file without pyulog's per-message loop.

pyulog reads a ULog message by message in Python (two reads, a header and a payload, and a
buffer append per data message), also for the topics it then drops. Here a numba kernel frames
the whole file first (offset, size, type and a data message's id of every message), 16 MiB of it at
a time with the pages walked given back (as are those of each later gather and copy: the process
holds what it has read, not the mapped file); when the framing is clean, the
messages other than the data ('D') messages (header, definitions, subscriptions, parameters,
logged text: a few thousand small messages) are parsed into pyulog's ULog object by
`ulog_definitions` (pyulog's rules, without its loop), and each subscription read gets its
messages' payloads copied into its buffer by a second kernel, as pyulog would have appended them.
The values that depend on the data messages read so far (the time of each parameter change and
dropout: the latest data timestamp before it; the log's last timestamp) are set from the same
timestamps, vectorised.

Clean means: the messages tile the file exactly, every type byte is one the format defines, the
file has no appended data or only appended data that a read straight through gives as pyulog's
read section by section does (`_appended_data`), each message id is subscribed once and before its
first data message, every data message of a topic read fits its format and its format has a
uint64-sized timestamp field inside the stored bytes, and the definitions parse as pyulog parses
them without a warning or a corruption flag. Anything else returns None and the caller reads the
file the careful way (`logscan.readers.ulog_reader`, pyulog itself), which counts and reports the
damage: the result of both paths is the same for a clean file.
"""

from __future__ import annotations

import contextlib
import io
import mmap
from collections.abc import Callable, Iterator
from functools import partial

import numpy as np
from numba import njit

from logscan.memory import drop_mapped_pages
from logscan.numba_cache import follow_dependencies
from logscan.readers.ulog_definitions import _HEADER_BYTES, build_ulog

_DEFINITIONS = np.frombuffer(b"BFIMPQ", dtype=np.uint8)  # the types pyulog reads in the definitions
_SECTION_END = np.frombuffer(b"ALC", dtype=np.uint8)
_DATA_SECTION = np.frombuffer(b"AILCMPQODS", dtype=np.uint8)  # those it reads in the data section
_EMPTY = np.empty(0, np.uint8)
_FRAME_BYTES = 16 << 20  # file bytes framed before their pages are given back
_NO_MESSAGES = np.empty(0, np.int64)


@njit(cache=True)
def _frame(buf, start, stop):  # pragma: no cover - numba kernel
    """(offsets, payload sizes, types, message ids: a data message's, else 0) of the messages from
    ``start`` that start before ``stop``, and where the walk ended: at or past ``stop`` when there
    are more; ``len(buf)`` when the messages tile the rest of the file; short of both when the last
    is cut. Two passes, a count then the fill: arrays of the exact size, and a fill loop without a
    branch that grows them (with one, numba's loop ran about 15x slower)."""
    n = buf.size
    count = 0
    pos = start
    while pos + 3 <= n and pos < stop:
        size = np.int64(buf[pos]) | (np.int64(buf[pos + 1]) << 8)
        if pos + 3 + size > n:
            break
        count += 1
        pos += 3 + size
    offsets = np.empty(count, np.int64)
    sizes = np.empty(count, np.uint16)  # a message's size is a uint16
    types = np.empty(count, np.uint8)
    ids = np.zeros(count, np.uint16)
    pos = start
    for i in range(count):
        size = np.int64(buf[pos]) | (np.int64(buf[pos + 1]) << 8)
        offsets[i] = pos
        sizes[i] = size
        types[i] = buf[pos + 2]
        if buf[pos + 2] == 68 and size >= 2:  # 'D': its msg_id, read while the page is in hand
            ids[i] = np.uint16(buf[pos + 3]) | (np.uint16(buf[pos + 4]) << 8)
        pos += 3 + size
    return offsets, sizes, types, ids, pos


def _given_back(offsets: np.ndarray, buf: np.ndarray, give_back: Callable[[int], None]) -> Iterator[tuple[int, int]]:
    """`_file_slices` of ``offsets``, the pages before each slice's last offset given back once it
    is read (``give_back(offset)``), and all of ``buf``'s after the last."""
    for lo, hi in _file_slices(offsets):
        yield lo, hi
        give_back(int(offsets[hi - 1]))
    give_back(buf.size)


def _file_slices(offsets: np.ndarray, span: int | None = None) -> list[tuple[int, int]]:
    """(lo, hi) index slices of the increasing file ``offsets``, each within ``span`` bytes of the
    file (None: `_FRAME_BYTES`): read one after the other, the pages of each given back before the next."""
    if not offsets.size:
        return []
    span = _FRAME_BYTES if span is None else span
    marks = np.arange(int(offsets[0]) + span, int(offsets[-1]) + 1, span)
    bounds = np.unique(np.concatenate(([0], np.searchsorted(offsets, marks), [offsets.size])))
    return list(zip(bounds[:-1].tolist(), bounds[1:].tolist(), strict=True))


def _frame_file(buf: np.ndarray, start: int, give_back: Callable[[int], None]) -> tuple[np.ndarray, ...]:
    """`_frame` of the whole file from ``start``, `_FRAME_BYTES` at a time with the pages walked
    given back (``give_back(offset)``): one walk over the file would hold all of it."""
    parts = []
    pos = start
    while True:
        *framed, end = _frame(buf, pos, pos + _FRAME_BYTES)
        parts.append(framed)
        give_back(end)
        if end < pos + _FRAME_BYTES or end >= buf.size:  # the end of the file, or a cut message
            break
        pos = end
    return tuple(np.concatenate(column) for column in zip(*parts, strict=True))


@njit(cache=True)
def _gather(buf, starts, width, out):  # pragma: no cover - numba kernel
    """``width`` bytes from each of ``starts``, one after the other, into ``out``."""
    for i in range(starts.size):
        s = starts[i]
        out[i * width : (i + 1) * width] = buf[s : s + width]


@njit(cache=True)
def _copy_messages(buf, offsets, sizes, out, pos):  # pragma: no cover - numba kernel
    """The listed messages (3-byte header + payload) into ``out`` from ``pos``; returns where they end."""
    for i in range(offsets.size):
        width = 3 + sizes[i]
        out[pos : pos + width] = buf[offsets[i] : offsets[i] + width]
        pos += width
    return pos


def _compact(buf: np.ndarray, head: int, offsets: np.ndarray, sizes: np.ndarray, give_back) -> np.ndarray:
    """The first ``head`` bytes of ``buf`` followed by the listed messages, a slice of the file at a
    time with the pages read given back (``give_back(offset)``, `_file_slices`): the
    synchronisation and logged messages among them lie all over the file."""
    out = np.empty(head + 3 * sizes.size + int(sizes.sum(dtype=np.int64)), np.uint8)
    out[:head] = buf[:head]
    pos = head
    for lo, hi in _given_back(offsets, buf, give_back):
        pos = _copy_messages(buf, offsets[lo:hi], sizes[lo:hi], out, pos)
    return out


class _Plan:
    """The framing of a clean file: the data messages of each message id, and what the parse found."""

    def __init__(self, buf: np.ndarray, framed: tuple[np.ndarray, ...], give_back: Callable[[int], None]) -> None:
        offsets, sizes, types, ids = framed
        self.buf = buf
        self.give_back = give_back
        data = types == ord("D")
        self.data_offsets = offsets[data]
        self.data_sizes = sizes[data]
        ids = ids[data]
        order = np.argsort(ids, kind="stable")
        self.ids, first = np.unique(ids[order], return_index=True)
        self.groups = np.split(order, first[1:]) if order.size else []
        self.group_of = dict(zip(self.ids.tolist(), self.groups, strict=True))
        sizes_sorted = self.data_sizes[order]  # each id's smallest and largest data message
        self.size_range = dict(
            zip(
                self.ids.tolist(),
                zip(
                    np.minimum.reduceat(sizes_sorted, first).tolist() if order.size else [],
                    np.maximum.reduceat(sizes_sorted, first).tolist() if order.size else [],
                    strict=True,
                ),
                strict=True,
            )
        )
        self.kept = (offsets[~data], sizes[~data].astype(np.int64), types[~data])
        self.read: list[tuple[np.ndarray, np.ndarray]] = []  # (positions, timestamps) of the data read
        self.failed = False
        self.appended: _Appended | None = None  # the flag bits of a file with appended data

    def messages_of(self, msg_id: int) -> np.ndarray:
        """Indices (into the data messages) of ``msg_id``'s data messages, in file order."""
        return self.group_of.get(msg_id, _NO_MESSAGES)

    def fill(self, subscription) -> None:
        """The subscription's buffer, as pyulog would append it; ``failed`` when a message does not fit."""
        index = self.messages_of(subscription.msg_id)
        if not index.size:
            return
        width = subscription.max_data_size  # pyulog's dtype: packed, its itemsize is this
        smallest, largest = self.size_range[subscription.msg_id]
        t_off = subscription.timestamp_offset
        if (
            smallest - 2 < width
            or largest - 2 > subscription.max_data_size
            or subscription.timestamp_idx < 0
            or t_off + 8 > width
        ):
            self.failed = True
            return
        starts = self.data_offsets[index] + 5
        buffer = np.empty(starts.size * width, np.uint8)
        for lo, hi in _given_back(starts, self.buf, self.give_back):
            _gather(self.buf, starts[lo:hi], width, buffer[lo * width : hi * width])
        subscription.buffer = buffer  # np.frombuffer reads it as is
        # each message's timestamp where it stands in the buffer (a strided view, not a copy)
        stamps = np.ndarray((index.size,), dtype="<u8", buffer=buffer, offset=t_off, strides=(width,))
        self.read.append((self.data_offsets[index], stamps))


class _Appended:
    """The flag bits message of a file with appended data: where it is, and what pyulog reads from it."""

    def __init__(self, at: int, incompat: list[int], offsets: list[int]) -> None:
        self.at = at  # offset of the flag bits message
        self.incompat = incompat
        self.offsets = offsets  # pyulog's list: the trailing zeros dropped


def _appended_data(buf, offsets, sizes, types, split: int) -> _Appended | None | bool:
    """False for a file without flag bits or with none set; the flag bits of appended data that a read
    straight through gives the same as pyulog's read section by section (each offset a message start
    after the first of the data section, increasing, and no subscription or data message from the
    first offset on); None for anything else (unknown incompat flags, offsets elsewhere)."""
    flags = np.flatnonzero(types == ord("B"))
    if flags.size == 0:
        return False
    if flags.size != 1 or sizes[flags[0]] < 40:
        return None
    at = int(offsets[flags[0]])
    incompat = buf[at + 3 + 8 : at + 3 + 16]
    stated = buf[at + 3 + 16 : at + 3 + 40].copy().view("<u8")
    if not (incompat.any() or stated.any()):
        return False
    if incompat[0] != 1 or incompat[1:].any():
        return None  # no appended data but offsets, or flags pyulog refuses: the careful read
    listed = stated.tolist()
    while listed and listed[-1] == 0:
        listed.pop()
    if listed:
        where = np.searchsorted(offsets, stated[: len(listed)])
        if (
            0 in listed
            or np.any(np.diff(stated[: len(listed)].astype(np.int64)) <= 0)
            or np.any(where <= split)
            or np.any(where >= offsets.size)
            or np.any(offsets[np.minimum(where, offsets.size - 1)] != stated[: len(listed)])
            or np.isin(types[where[0] :], np.frombuffer(b"AD", dtype=np.uint8)).any()
        ):
            return None
    return _Appended(at, incompat.tolist(), [int(o) for o in listed])


def _clean_plan(buf: np.ndarray, give_back: Callable[[int], None]) -> _Plan | None:
    """The plan of a file whose messages tile it with known types, subscribed once before their
    data; ``give_back(offset)``: drop the file's pages before it from the process."""
    if buf.size < _HEADER_BYTES:
        return None
    framed = _frame_file(buf, _HEADER_BYTES, give_back)
    offsets, sizes, types = framed[:3]
    if offsets.size == 0 or offsets[-1] + 3 + sizes[-1] != buf.size:
        return None
    ends = np.flatnonzero(np.isin(types, _SECTION_END))  # the definitions section ends at the first of them
    split = int(ends[0]) if ends.size else types.size
    if not (np.isin(types[:split], _DEFINITIONS).all() and np.isin(types[split:], _DATA_SECTION).all()):
        return None  # types pyulog skips with a search for a sync sequence, or a damaged type byte
    appended = _appended_data(buf, offsets, sizes, types, split)
    if appended is None:
        return None
    subscribe = offsets[types == ord("A")]
    sub_ids = buf[subscribe + 4].astype(np.int64) | (buf[subscribe + 5].astype(np.int64) << 8)
    if np.unique(sub_ids).size != sub_ids.size or (sizes[types == ord("A")] < 3).any():
        return None
    plan = _Plan(buf, framed, give_back)
    plan.appended = appended or None
    if (plan.data_sizes < 2).any():
        return None
    first_data = np.array([plan.data_offsets[g[0]] for g in plan.groups], dtype=np.int64)
    where = np.searchsorted(np.sort(sub_ids), plan.ids)
    known = (where < sub_ids.size) & (np.sort(sub_ids)[np.minimum(where, sub_ids.size - 1)] == plan.ids)
    if not known.all():
        return None
    sub_at = dict(zip(sub_ids.tolist(), subscribe.tolist(), strict=True))
    if any(sub_at[i] > f for i, f in zip(plan.ids.tolist(), first_data.tolist(), strict=True)):
        return None
    return plan


def parse_clean(path: str, names: list[str] | None, on_framed: Callable[[], None] | None = None) -> tuple | None:
    """(pyulog ULog, clean read watch, chatter) of an undamaged file read without pyulog's data-message
    loop; None when the file is not clean or cannot be parsed (the caller then reads it the careful
    way, which says why). ``on_framed()`` is called once the whole file is framed and found clean."""
    try:
        with open(path, "rb") as fh:
            mapped = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    except (OSError, ValueError):  # unreadable or empty: the careful read says so
        return None
    try:
        return _parse_mapped(
            np.frombuffer(mapped, dtype=np.uint8), names, on_framed, partial(drop_mapped_pages, mapped)
        )
    finally:
        with contextlib.suppress(BufferError):  # an array still viewing it keeps the map alive
            mapped.close()


def _parse_mapped(
    buf: np.ndarray, names: list[str] | None, on_framed: Callable[[], None] | None, give_back: Callable[[int], None]
) -> tuple | None:
    plan = _clean_plan(buf, give_back)
    if plan is None:
        return None
    if on_framed is not None:
        on_framed()
    kept_offsets, kept_sizes, kept_types = plan.kept
    reduced_array = _compact(buf, _HEADER_BYTES, kept_offsets, kept_sizes, give_back)
    if plan.appended is not None:  # read straight through: the same messages in the same order
        reduced_array[plan.appended.at + 3 + 8 : plan.appended.at + 3 + 40] = 0
    wanted = None if names is None else set(names)
    try:
        ulog = build_ulog(reduced_array, kept_sizes, kept_types, wanted, plan.fill)
    finally:
        plan.buf = _EMPTY  # the map can be closed: the buffers are copies
    if ulog is None or plan.failed:
        return None
    _set_times(ulog, plan, kept_offsets, kept_types)
    if plan.appended is not None:  # the flag bits as pyulog read them from the file
        ulog._incompat_flags = plan.appended.incompat
        ulog._appended_offsets = plan.appended.offsets
    return ulog, _CleanRead(), io.StringIO()


def _set_times(ulog, plan: _Plan, offsets: np.ndarray, types: np.ndarray) -> None:
    """The times pyulog gives parameter changes and dropouts (the latest data timestamp read before
    each, from the header's start timestamp on) and the log's last timestamp."""
    start = int(ulog.start_timestamp)
    if plan.read:
        positions = np.concatenate([p for p, _ in plan.read])
        order = np.argsort(positions, kind="stable")
        positions = positions[order]
        stamps = np.concatenate([s for _, s in plan.read])[order]
        latest = np.maximum(np.maximum.accumulate(stamps), np.uint64(start))
    else:
        positions = np.empty(0, np.int64)
        latest = np.empty(0, np.uint64)

    def at(position: int) -> int:
        i = int(np.searchsorted(positions, position))
        return int(latest[i - 1]) if i else start

    section = np.flatnonzero(np.isin(types, _SECTION_END))
    first = int(offsets[section[0]]) if section.size else -1
    in_data = offsets >= first if first >= 0 else np.zeros(offsets.size, bool)
    changes = offsets[in_data & (types == ord("P"))]
    if len(changes) != len(ulog._changed_parameters):
        raise AssertionError("ULog framed read: parameter changes do not match")  # never: same messages
    ulog._changed_parameters = [
        (at(int(p)), key, value) for p, (_, key, value) in zip(changes, ulog._changed_parameters, strict=True)
    ]
    for p, dropout in zip(offsets[in_data & (types == ord("O"))], ulog._dropouts, strict=True):
        dropout.timestamp = at(int(p))
    ulog._last_timestamp = int(latest[-1]) if latest.size else start


class _CleanRead:
    """The read watch of a clean file: every byte read, nothing cut."""

    cut_at = None

    def unread(self, size: int) -> tuple[int, int]:
        return 0, -1


follow_dependencies(__name__)
