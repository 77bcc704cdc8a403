"""What a damaged ULog loses, counted: pyulog hardened against damaged formats and sizes, lost or
duplicated subscriptions and unknown message types, and the read's damage report."""

from __future__ import annotations

import contextlib
import errno
import functools
import io
import mmap
import os
import struct

import numpy as np

from logscan.errors import CorruptLogError
from logscan.log import SourceInfo

_MAX_MESSAGE_BYTES = 0xFFFF  # a message's size field is a uint16
_MAX_FORMAT_NESTING = 64  # nested message formats (PX4 nests 2 or 3 deep)
_UNTIMED_WHY = "its message format has no timestamp field, which the ULog spec requires: the definition is damaged"
MAX_TIMESTAMP_US = (2**63 - 1) // 1000  # microseconds whose nanoseconds fit int64


def format_bytes(name: str, formats: dict) -> int:
    """Bytes one ``name`` message takes once flattened (pyulog's ``MessageFormat`` fields);
    ValueError when it contains itself, nests deeper than ``_MAX_FORMAT_NESTING`` or exceeds
    ``_MAX_MESSAGE_BYTES``. O(formats): each format's size is computed once."""
    from pyulog import ULog

    sizes: dict[str, int] = {}

    def size_of(type_name: str, chain: tuple[str, ...]) -> int:
        if type_name in sizes:
            return sizes[type_name]
        if type_name in chain:
            raise ValueError(f"message format {type_name!r} contains itself")
        if len(chain) >= _MAX_FORMAT_NESTING:
            raise ValueError(f"message formats nested more than {_MAX_FORMAT_NESTING} deep")
        total = 0
        for field_type, array_size, _ in formats[type_name].fields:  # KeyError: undefined type
            primitive = ULog._UNPACK_TYPES.get(field_type)
            one = primitive[1] if primitive else size_of(field_type, (*chain, type_name))
            total += one * max(1, array_size)
            if total > _MAX_MESSAGE_BYTES:
                raise ValueError(
                    f"message format {type_name!r} flattens to more than {_MAX_MESSAGE_BYTES} bytes, "
                    "more than a ULog message can hold"
                )
        sizes[type_name] = total
        return total

    return size_of(name, ())


@functools.cache
def _bounded_ulog_class():
    """pyulog's ULog whose subscriptions check their format (``format_bytes``) before flattening it,
    and which reads on past the data of a format without a uint64 ``timestamp`` field. Made once:
    the class holds no state of a read (a read's damage is kept on its ULog object)."""
    from pyulog import ULog

    class BoundedULog(ULog):
        class _MessageAddLogged(ULog._MessageAddLogged):
            def _parse_format(self, message_formats):
                format_bytes(self.message_name, message_formats)
                super()._parse_format(message_formats)

        class _MessageData(ULog._MessageData):
            def initialize(self, data, header, subscriptions, ulog_object) -> bool:
                try:
                    corrupt = super().initialize(data, header, subscriptions, ulog_object)
                except struct.error:
                    if len(data) < 2:  # too short to name its topic: pyulog stops there (framing broken)
                        raise
                    # The message is kept, but the 8 timestamp bytes pyulog reads lie past its end: its
                    # format has no uint64 `timestamp` field. pyulog would take this for the end of the
                    # file and drop the rest of it; read_ulog skips the topic and says why.
                    self.timestamp = 0
                    return False
                if corrupt:  # no subscription for its msg_id, or a size its format does not fit: dropped
                    _damage_of(ulog_object).dropped_data += 1
                return corrupt

        def _read_file_data(self, message_name_filter_list, read_until=None):
            damage = _damage_of(self)  # each section (appended data too) subscribes afresh
            self._subscriptions = _Subscriptions(self._subscriptions, self._filtered_message_ids, damage.replaced)
            self._filtered_message_ids = self._subscriptions.filtered
            return super()._read_file_data(message_name_filter_list, read_until)

        def _check_packet_corruption(self, header):
            # pyulog calls this for every message of a type it does not handle
            if header.msg_type not in _KNOWN_TYPES:
                types = _damage_of(self).unknown_types
                types[header.msg_type] = types.get(header.msg_type, 0) + 1
            return super()._check_packet_corruption(header)

    return BoundedULog


_KNOWN_TYPES = frozenset(b"BFIMPQARDLCSO")  # the message types of the ULog specification


class _Subscriptions(dict):
    """pyulog's msg_id -> subscription table, counting the 'A' records that reuse a msg_id already
    subscribed or filtered out (pyulog drops the messages buffered for a replaced subscription, and
    reads the later messages of that id by the wrong format): a duplicated or damaged msg_id."""

    def __init__(self, table: dict, filtered: set, replaced: list[tuple[str, int]]) -> None:
        super().__init__(table)
        self.filtered = _FilteredIds(filtered, self)
        self.replaced = replaced  # (topic, messages dropped) per reused msg_id

    def __setitem__(self, msg_id, subscription) -> None:
        old = self.get(msg_id)
        if old is not None:
            size = max(1, old.dtype.itemsize) if getattr(old, "dtype", None) is not None else 1
            self.replaced.append((f"{old.message_name}_{old.multi_id}", len(old.buffer) // size))
        elif msg_id in self.filtered.section:
            self.replaced.append(("(a topic not read)", 0))
        super().__setitem__(msg_id, subscription)


class _FilteredIds(set):
    """pyulog's set of the msg_ids of topics not read, counting the 'A' records that reuse an id."""

    def __init__(self, ids: set, subscriptions: _Subscriptions) -> None:
        super().__init__(ids)  # those of earlier sections: their data may follow in appended data
        self.subscriptions = subscriptions
        self.section: set = set()  # those this section's 'A' records filtered out

    def add(self, msg_id) -> None:
        old = self.subscriptions.get(msg_id)
        if old is not None:
            self.subscriptions.replaced.append((f"{old.message_name}_{old.multi_id}", 0))
        elif msg_id in self.section:
            self.subscriptions.replaced.append(("(a topic not read)", 0))
        self.section.add(msg_id)
        super().add(msg_id)


class _Damage:
    """What a read of pyulog's drops silently: unknown message types, data messages without a
    subscription or of a size their format does not fit, replaced subscriptions."""

    def __init__(self) -> None:
        self.unknown_types: dict[int, int] = {}  # message type byte -> count
        self.dropped_data = 0
        self.replaced: list[tuple[str, int]] = []  # 'A' records reusing a msg_id: (topic, messages dropped)


def _damage_of(ulog) -> _Damage:
    damage = getattr(ulog, "_logscan_damage", None)
    if damage is None:
        damage = ulog._logscan_damage = _Damage()
    return damage


class _ReadWatch(io.RawIOBase):
    """A read-only file that records the byte ranges read and where a read first came back short.

    pyulog stops silently at a cut message; a clean end of file is a 3-byte message-header read
    that returns nothing, anything shorter than asked for is truncation.

    pyulog reads message by message (two reads each), so ``read`` is the reader's hot path: the file
    is memory-mapped and sliced (no system call or ``tell`` per read), and consecutive reads extend
    one run of bytes read instead of adding an entry each (``unread`` sees the same union).
    """

    def __init__(self, path: str | None, data: bytes = b""):
        super().__init__()
        self._buf: mmap.mmap | bytes = data
        if path is not None:
            with open(path, "rb") as fh:
                with contextlib.suppress(ValueError):  # an empty file cannot be mapped
                    self._buf = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
        self._pos = 0
        self.cut_at: int | None = None
        self.starts: list[int] = []  # runs of consecutive reads: [starts[i], ends[i]) was read
        self.ends: list[int] = []
        self._run_start = self._run_end = -1

    @classmethod
    def over(cls, data: bytes) -> _ReadWatch:
        """The watch of reads of ``data`` (in memory)."""
        return cls(None, data)

    def read(self, size: int | None = -1) -> bytes:
        pos = self._pos
        data = self._buf[pos:] if size is None or size < 0 else self._buf[pos : pos + size]
        n = len(data)
        if size is not None and n < size and self.cut_at is None and not (size == 3 and not n):
            self.cut_at = pos
        if n:
            if pos != self._run_end:
                self._close_run()
                self._run_start = pos
            self._run_end = pos + n
            self._pos = pos + n
        return data

    def _close_run(self) -> None:
        if self._run_end > self._run_start:
            self.starts.append(self._run_start)
            self.ends.append(self._run_end)
        self._run_start = self._run_end = -1

    def unread(self, size: int) -> tuple[int, int]:
        """(bytes of the file never read, offset of the first of them; -1 when all were read)."""
        self._close_run()
        if not self.starts:
            return size, 0
        order = np.argsort(self.starts, kind="stable")
        starts = np.asarray(self.starts, dtype=np.int64)[order]
        # reach[i]: the furthest byte read by reads 0..i (sorted by start)
        reach = np.maximum.accumulate(np.asarray(self.ends, dtype=np.int64)[order])
        gaps = np.concatenate(([starts[0]], starts[1:] - reach[:-1], [size - reach[-1]]))
        where = np.concatenate(([0], reach))
        holes = gaps > 0
        return int(gaps[holes].sum()), int(where[holes][0]) if holes.any() else -1

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = 0) -> int:
        base = (0, self._pos, len(self._buf))[whence]
        if base + offset < 0:
            raise OSError(errno.EINVAL, os.strerror(errno.EINVAL))
        self._pos = base + offset
        return self._pos

    def tell(self) -> int:
        return self._pos

    def close(self) -> None:
        if isinstance(self._buf, mmap.mmap):
            self._buf.close()
        super().close()


def _header_damage(ulog, source: SourceInfo) -> list[str]:
    """A header start timestamp whose nanoseconds do not fit int64 is damage: it is not used as the
    log's time zero (``start_timestamp_us`` left out of the metadata)."""
    start = int(ulog.start_timestamp)
    if start <= MAX_TIMESTAMP_US:
        return []
    log_facts = source.metadata.get("ulog.log", {})
    log_facts.pop("start_timestamp_us", None)
    log_facts["start_timestamp_us_damaged"] = str(start)
    return [f"the header's start timestamp {start} us is beyond int64 nanoseconds (a damaged header): not used"]


def _dropped_by_pyulog(ulog) -> list[str]:
    """Messages pyulog drops without a word: unknown message types, data messages without a
    subscription or of a size their format does not fit, subscriptions an 'A' record replaced."""
    damage = _damage_of(ulog)
    out = []
    if damage.unknown_types:
        types = ", ".join(f"0x{t:02x} x{n}" for t, n in sorted(damage.unknown_types.items())[:5])
        out.append(
            f"{sum(damage.unknown_types.values())} message(s) of types the ULog format does not define skipped "
            f"({types}): damaged message type bytes"
        )
    if damage.dropped_data:
        out.append(
            f"{damage.dropped_data} data message(s) dropped as corrupt: no subscription ('A' record) for their "
            "message id, or a size their format does not fit (a lost or damaged subscription)"
        )
    if damage.replaced:
        topics = ", ".join(sorted({topic for topic, _ in damage.replaced})[:5])
        out.append(
            f"{len(damage.replaced)} subscription(s) replaced by an 'A' record reusing their message id ({topics}): "
            f"{sum(n for _, n in damage.replaced)} message(s) read before dropped, later ones read by the wrong format"
        )
    return out


def _report_damage(
    path,
    ulog,
    source: SourceInfo,
    chatter: str,
    watch: _ReadWatch,
    *,
    all_topics: bool,
    untimed: list[str],
    lost: list[str],
) -> None:
    """Mark the log partial when the file is truncated, its framing broken, pyulog skipped corrupt
    data or topics were skipped for lack of a timestamp field (``untimed``); the reason says where
    and how much was recovered. CorruptLogError when nothing at all could be read.

    ULog has no checksums: flipped bytes inside message payloads cannot be detected, only
    framing, truncation, pyulog's corruption flag and (as warnings) topic timestamps going backwards.
    """
    size = os.path.getsize(path)
    cut_at = watch.cut_at
    reasons = []
    if cut_at is not None:
        reasons.append(f"truncated: the message read at byte {cut_at} runs past the end of the file ({size} bytes)")
    unread, first_unread = watch.unread(size)
    if unread and cut_at is None:
        reasons.append(
            f"message framing broken: reading stopped at byte {first_unread} (a message pyulog could not frame, "
            "e.g. of size 0); "
            f"{unread} bytes ({100.0 * unread / size:.1f} % of the file) were never read"
        )
    beyond = [int(o) for o in getattr(ulog, "_appended_offsets", []) if int(o) > size]
    if beyond:
        reasons.append(f"truncated: data appended at byte {beyond[0]} lies past the end of the file ({size} bytes)")
    if ulog.file_corruption and not _damage_of(ulog).dropped_data:
        reasons.append("pyulog found corrupt data (broken framing or unknown message ids) and skipped it")
    reasons += lost
    skipped = f"topic{'s' if len(untimed) > 1 else ''} {', '.join(untimed)}"
    if untimed:
        source.warnings.append(f"{skipped} skipped: {_UNTIMED_WHY}")
        reasons.append(f"{skipped} not read: {_UNTIMED_WHY}")
    if reasons:
        source.partial = True
        source.partial_reason = "; ".join(reasons) + "; " + _recovered(source, ulog)
    lines = list(dict.fromkeys(line.strip() for line in chatter.splitlines() if line.strip()))
    for line in lines[:5]:
        source.warnings.append(f"pyulog: {line}")
    if len(lines) > 5:
        source.warnings.append(f"pyulog: ... {len(lines) - 5} more distinct message(s)")
    if cut_at is not None and all_topics and not ulog.data_list:
        raise CorruptLogError(
            f"ULog truncated at byte {cut_at} of {size} before any data message",
            path=str(path),
            hint="the file was cut during logging or copying; nothing to read",
        )
    if untimed and not source.topics:  # every topic read lacks its timestamp: no data at all
        raise CorruptLogError(
            f"no data to read: {skipped} skipped, {_UNTIMED_WHY}",
            path=str(path),
            hint="re-export or re-record the log",
        )


def _recovered(source: SourceInfo, ulog) -> str:
    """How much of the log a partial read recovered: data messages, and the time span of the busiest
    topic (single messages can carry any timestamp, so the span of all topics says little)."""
    count = sum(t.message_count for t in source.topics.values())
    timed = [t for t in source.topics.values() if t.first_ns is not None and t.last_ns is not None]
    if not timed:
        return "no data message was recovered"
    busiest = max(timed, key=lambda t: t.message_count)
    start = int(ulog.start_timestamp) * 1000 if int(ulog.start_timestamp) <= MAX_TIMESTAMP_US else 0
    return (
        f"recovered {count} data messages of the topics read; {busiest.name} (the busiest topic) covers "
        f"{(busiest.first_ns - start) / 1e9:.3f} .. {(busiest.last_ns - start) / 1e9:.3f} s after the log start"
    )
