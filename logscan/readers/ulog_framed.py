"""The ULog read of an undamaged file without pyulog's per-message loop.

pyulog reads a ULog message by message in Python (two reads, a header and a payload, and a
buffer append per data message), also for the topics it then drops. Here a numba kernel frames
the whole file first (offset, size, type and a data message's id of every message), 16 MiB of it at
a time with the pages walked given back (as are those of each later gather and copy: the process
holds what it has read, not the mapped file), each slice's data messages kept as 8 bytes each
(`_Part`: a 4-hour PX4 log has 14 million); when the framing is clean, the
messages other than the data ('D') messages (header, definitions, subscriptions, parameters,
logged text: a few thousand small messages) are parsed into pyulog's ULog object by
`ulog_definitions` (pyulog's rules, without its loop), and each subscription read gets its
messages' payloads copied into its buffer by a second kernel, as pyulog would have appended them.
The values that depend on the data messages read so far (the time of each parameter change and
dropout: the latest data timestamp before it; the log's last timestamp) are set from the same
timestamps, vectorised, a topic at a time.

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
from logscan.readers import spill
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


class _Part:
    """The data messages of one framed slice of the file (`_FRAME_BYTES`): where each starts, as an
    offset from ``base`` (uint32: a slice is 16 MiB), and its payload size, in file order; the
    message indices grouped by message id (``order``: each id's in file order, from ``starts``);
    and each id's count and first message in it. 10 bytes a message, where whole-file arrays with
    a sort order took 26."""

    __slots__ = ("base", "at", "sizes", "order", "starts", "counts", "first", "shortest")

    def __init__(self, offsets: np.ndarray, sizes: np.ndarray, ids: np.ndarray) -> None:
        self.base = int(offsets[0]) if offsets.size else 0
        self.shortest = int(sizes.min())  # found here: kept on disk, ``sizes`` is not read whole again
        self.at = spill.copied(offsets - self.base, np.uint32)  # on disk for a long log held whole
        self.sizes = spill.copied(sizes, np.uint16)
        # one stable sort (a radix sort of the uint16 ids) instead of a pass over every id per
        # topic read: a topic's messages are then one run of ``order``
        order = np.argsort(ids, kind="stable")
        grouped = ids[order]
        heads = np.flatnonzero(np.concatenate(([True], grouped[1:] != grouped[:-1])))
        known, counts = grouped[heads].tolist(), np.diff(np.append(heads, ids.size)).tolist()
        self.order = spill.copied(order, np.uint32)
        self.starts = dict(zip(known, heads.tolist(), strict=True))
        self.counts = dict(zip(known, counts, strict=True))
        self.first = dict(zip(known, offsets[order[heads]].tolist(), strict=True))  # each id's first message

    def offsets_of(self, msg_id: int) -> tuple[np.ndarray, np.ndarray]:
        """(file offsets, payload sizes) of ``msg_id``'s data messages in this slice, in file order."""
        count = self.counts.get(msg_id)
        if count is None:
            return _NO_MESSAGES, _NO_MESSAGES
        chosen = self.order[self.starts[msg_id] : self.starts[msg_id] + count]
        # the run of indices read, the offsets and sizes picked: each pick maps its page and the
        # kernel's fault-around (64 KiB), so a few picks a slice can map those arrays whole
        spill.passed(chosen.nbytes + self.at.nbytes + self.sizes.nbytes)
        return self.at[chosen].astype(np.int64) + self.base, self.sizes[chosen]


def _frame_file(buf: np.ndarray, start: int, give_back: Callable[[int], None]) -> tuple[list[_Part], tuple, int]:
    """`_frame` of the whole file from ``start``, `_FRAME_BYTES` at a time with the pages walked
    given back (``give_back(offset)``): one walk over the file would hold all of it. Returns the
    data messages a slice at a time (`_Part`), the other messages (offsets, sizes, types: a few
    thousand, whole-file arrays) and where the walk ended (the file's size when the messages tile it)."""
    parts, kept = [], []
    pos = start
    while True:
        offsets, sizes, types, ids, end = _frame(buf, pos, pos + _FRAME_BYTES)
        data = types == ord("D")
        if data.any():
            parts.append(_Part(offsets[data], sizes[data], ids[data]))
        kept.append((offsets[~data], sizes[~data], types[~data]))
        give_back(end)
        if end < pos + _FRAME_BYTES or end >= buf.size:  # the end of the file, or a cut message
            return parts, tuple(np.concatenate(column) for column in zip(*kept, strict=True)), end
        pos = end


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
    """The framing of a clean file: its data messages a slice at a time (`_Part`), the other
    messages, and what the subscriptions read found."""

    def __init__(self, buf: np.ndarray, parts: list[_Part], give_back: Callable[[int], None]) -> None:
        self.buf = buf
        self.give_back = give_back
        self.parts = parts
        self.kept: tuple[np.ndarray, np.ndarray, np.ndarray] = (_NO_MESSAGES, _NO_MESSAGES, _EMPTY)
        self.split = buf.size  # where the data section starts: its first 'A', 'L' or 'C' message
        self.queries = _NO_MESSAGES  # file offsets of the messages whose time is the data's so far (`_set_times`)
        # per topic read: its timestamps (a strided view of its buffer) and how many of them lie
        # before each of ``queries`` in the file
        self.read: list[tuple[np.ndarray, np.ndarray]] = []
        self.failed = False
        self.appended: _Appended | None = None  # the flag bits of a file with appended data

    def first_data(self) -> dict[int, int]:
        """Each message id's first data message's file offset."""
        first: dict[int, int] = {}
        for part in reversed(self.parts):  # the earliest part's last
            first.update(part.first)
        return first

    def fill(self, subscription) -> None:
        """The subscription's buffer, as pyulog would append it; ``failed`` when a message does not fit."""
        count = sum(part.counts.get(subscription.msg_id, 0) for part in self.parts)
        if not count:
            return
        width = subscription.max_data_size  # pyulog's dtype: packed, its itemsize is this
        t_off = subscription.timestamp_offset
        if subscription.timestamp_idx < 0 or t_off + 8 > width:
            self.failed = True
            return
        buffer = spill.empty(count * width, np.uint8)  # on disk for a long log held whole
        before = np.zeros(self.queries.size, np.int64)
        done = 0
        for part in self.parts:
            offsets, sizes = part.offsets_of(subscription.msg_id)
            if not offsets.size:
                continue
            if not (sizes == width + 2).all():  # payload: the msg_id's 2 bytes, then the record
                self.failed = True
                return
            _gather(self.buf, offsets + 5, width, buffer[done * width : (done + offsets.size) * width])
            if self.queries.size:
                before += np.searchsorted(offsets, self.queries)
            done += offsets.size
            self.give_back(int(offsets[-1]))
            spill.passed(offsets.size * width)
        self.give_back(self.buf.size)
        subscription.buffer = buffer  # np.frombuffer reads it as is
        # each message's timestamp where it stands in the buffer (a strided view, not a copy)
        stamps = np.ndarray((count,), dtype="<u8", buffer=buffer, offset=t_off, strides=(width,))
        self.read.append((stamps, before))


class _Appended:
    """The flag bits message of a file with appended data: where it is, and what pyulog reads from it."""

    def __init__(self, at: int, incompat: list[int], offsets: list[int]) -> None:
        self.at = at  # offset of the flag bits message
        self.incompat = incompat
        self.offsets = offsets  # pyulog's list: the trailing zeros dropped


def _appended_data(buf, kept: tuple, parts: list[_Part], split: int) -> _Appended | None | bool:
    """False for a file without flag bits or with none set; the flag bits of appended data that a read
    straight through gives the same as pyulog's read section by section (each offset a message start
    after the first of the data section (at file offset ``split``), increasing, and no subscription
    or data message from the first offset on); None for anything else (unknown incompat flags,
    offsets elsewhere). ``kept``: the messages other than data messages (offsets, sizes, types)."""
    offsets, sizes, types = kept
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
    listed = [int(o) for o in stated.tolist()]
    while listed and listed[-1] == 0:
        listed.pop()
    if listed:
        last_data = max((part.base + int(part.at[-1]) for part in parts), default=-1)
        subscribed = offsets[types == ord("A")]
        if (
            0 in listed
            or any(b <= a for a, b in zip(listed, listed[1:]))
            or listed[0] <= split
            or not all(_starts_a_message(o, offsets, parts) for o in listed)
            or last_data >= listed[0]
            or (subscribed.size and int(subscribed[-1]) >= listed[0])
        ):
            return None
    return _Appended(at, incompat.tolist(), listed)


def _starts_a_message(offset: int, kept_offsets: np.ndarray, parts: list[_Part]) -> bool:
    """Whether a message of the file starts at ``offset``."""
    where = int(np.searchsorted(kept_offsets, offset))
    if where < kept_offsets.size and int(kept_offsets[where]) == offset:
        return True
    for part in parts:
        relative = offset - part.base
        if 0 <= relative <= int(part.at[-1]):
            where = int(np.searchsorted(part.at, relative))
            return where < part.at.size and int(part.at[where]) == relative
    return False


def _clean_plan(buf: np.ndarray, give_back: Callable[[int], None]) -> _Plan | None:
    """The plan of a file whose messages tile it with known types, subscribed once before their
    data; ``give_back(offset)``: drop the file's pages before it from the process."""
    if buf.size < _HEADER_BYTES:
        return None
    parts, kept, end = _frame_file(buf, _HEADER_BYTES, give_back)
    offsets, sizes, types = kept
    if end != buf.size or (offsets.size == 0 and not parts):
        return None
    ends = np.flatnonzero(np.isin(types, _SECTION_END))  # the definitions section ends at the first of them
    split = int(offsets[ends[0]]) if ends.size else buf.size
    definitions = offsets < split
    first_data = min((part.base for part in parts), default=buf.size)
    if not (
        np.isin(types[definitions], _DEFINITIONS).all()
        and np.isin(types[~definitions], _DATA_SECTION).all()
        and (not parts or first_data > split)  # a data message is never among the definitions
    ):
        return None  # types pyulog skips with a search for a sync sequence, or a damaged type byte
    appended = _appended_data(buf, kept, parts, split)
    if appended is None:
        return None
    subscribe = offsets[types == ord("A")]
    sub_ids = buf[subscribe + 4].astype(np.int64) | (buf[subscribe + 5].astype(np.int64) << 8)
    if np.unique(sub_ids).size != sub_ids.size or (sizes[types == ord("A")] < 3).any():
        return None
    short = any(part.shortest < 2 for part in parts)
    spill.give_back()  # the framing of a long log held on disk: read again as each topic is gathered
    if short:
        return None
    plan = _Plan(buf, parts, give_back)
    plan.kept, plan.split = (offsets, sizes.astype(np.int64), types), split
    plan.appended = appended or None
    sub_at = dict(zip(sub_ids.tolist(), subscribe.tolist(), strict=True))
    if any(msg_id not in sub_at or sub_at[msg_id] > at for msg_id, at in plan.first_data().items()):
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
        return _parse_mapped(np.frombuffer(mapped, dtype=np.uint8), names, on_framed, _page_return(mapped))
    finally:
        with contextlib.suppress(BufferError):  # an array still viewing it keeps the map alive
            mapped.close()


def _page_return(mapped: mmap.mmap) -> Callable[[int], None]:
    """``give_back(offset)`` of the mapped file: its pages before the offset dropped from the
    process; nothing for a file within one framing slice (`_FRAME_BYTES`), held whole by the
    slice's walk anyway (two page drops per topic read are a tenth of a small log's read)."""
    if len(mapped) <= _FRAME_BYTES:
        return lambda offset: None
    return partial(drop_mapped_pages, mapped)


def _parse_mapped(
    buf: np.ndarray, names: list[str] | None, on_framed: Callable[[], None] | None, give_back: Callable[[int], None]
) -> tuple | None:
    plan = _clean_plan(buf, give_back)
    if plan is None:
        return None
    if on_framed is not None:
        on_framed()
    kept_offsets, kept_sizes, kept_types = plan.kept
    changes, dropouts = _timed_by_data(kept_offsets, kept_types, plan.split)
    plan.queries = np.concatenate((changes, dropouts))
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
    _set_times(ulog, plan, changes.size)
    if plan.appended is not None:  # the flag bits as pyulog read them from the file
        ulog._incompat_flags = plan.appended.incompat
        ulog._appended_offsets = plan.appended.offsets
    return ulog, _CleanRead(), io.StringIO()


def _timed_by_data(offsets: np.ndarray, types: np.ndarray, split: int) -> tuple[np.ndarray, np.ndarray]:
    """(file offsets of the parameter changes, of the dropouts) in the data section (from file
    offset ``split``): pyulog times each by the data read before it."""
    in_data = offsets >= split
    return offsets[in_data & (types == ord("P"))], offsets[in_data & (types == ord("O"))]


def _set_times(ulog, plan: _Plan, changes: int) -> None:
    """The times pyulog gives parameter changes and dropouts (the latest data timestamp read before
    each, from the header's start timestamp on: ``plan.queries``, the ``changes`` first) and the
    log's last timestamp; a topic's running maximum at a time, not the data read all at once."""
    start = np.uint64(ulog.start_timestamp)
    latest = np.full(plan.queries.size, start, np.uint64)
    last = start
    for stamps, before in plan.read:
        at, top = _running_max_at(stamps, before - 1)
        seen = before > 0
        latest[seen] = np.maximum(latest[seen], at[seen])
        last = max(last, top)
    if changes != len(ulog._changed_parameters):
        raise AssertionError("ULog framed read: parameter changes do not match")  # never: same messages
    ulog._changed_parameters = [
        (int(t), key, value) for t, (_, key, value) in zip(latest[:changes], ulog._changed_parameters, strict=True)
    ]
    for t, dropout in zip(latest[changes:], ulog._dropouts, strict=True):
        dropout.timestamp = int(t)
    ulog._last_timestamp = int(last)


def _running_max_at(stamps: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, np.uint64]:
    """(the running maximum of ``stamps`` at each index of ``at``, 0 where it is -1; their maximum),
    `spill.CHUNK` stamps at a time: a long log's records are on disk (`logscan.readers.spill`)."""
    found = np.zeros(at.size, np.uint64)
    carry = np.uint64(0)
    if not at.size:  # no parameter change or dropout to time (most files): the maximum alone
        for lo in range(0, stamps.size, spill.CHUNK):
            part = stamps[lo : lo + spill.CHUNK]
            carry = max(carry, np.maximum.reduce(part))
            spill.passed(part.size * stamps.strides[0])
        return found, carry
    for lo in range(0, stamps.size, spill.CHUNK):
        running = np.maximum.accumulate(stamps[lo : lo + spill.CHUNK])
        np.maximum(running, carry, out=running)
        inside = (at >= lo) & (at < lo + running.size)
        found[inside] = running[at[inside] - lo]
        carry = running[-1]
        spill.passed(running.size * stamps.strides[0])  # the records it ran through
    return found, carry


class _CleanRead:
    """The read watch of a clean file: every byte read, nothing cut."""

    cut_at = None

    def unread(self, size: int) -> tuple[int, int]:
        return 0, -1


follow_dependencies(__name__)
