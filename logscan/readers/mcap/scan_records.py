"""What a scan of an MCAP file hands on: its Schema and Channel records, raw messages and batches of
them, and the helpers that walk and map the file (bounds of a record, the mapped file, damage)."""

from __future__ import annotations

import mmap
import os
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from logscan.readers.flatten import MessageBytes
from logscan.readers.mcap.records import (
    Records,
)


class _Corrupt(Exception):
    """Internal: the record at ``offset`` is broken; ``reason`` says how.

    ``fatal``: nothing read can be trusted (a data-section CRC mismatch over records that have no
    CRC of their own), so no partial result may be returned.
    """

    def __init__(self, reason: str, offset: int, fatal: bool = False):
        super().__init__(reason)
        self.reason = reason
        self.offset = offset
        self.fatal = fatal


@dataclass
class SchemaRec:
    """A Schema record: id, name, encoding and definition bytes."""

    id: int
    name: str
    encoding: str
    data: bytes


@dataclass
class ChannelRec:
    """A Channel record: id, schema id, topic, message encoding and metadata."""

    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: dict[str, str]


class RawMessage(NamedTuple):
    """One message as stored: topic, channel id, sequence, log and publish time (ns), data bytes."""

    topic: str
    channel_id: int
    sequence: int
    log_time: int
    publish_time: int
    data: bytes


@dataclass
class _Batch:
    """Messages of one channel, per container: log times (int64) and (buffer, starts, ends) segments.

    No Python object per message: the segments point into the decompressed chunk (or the file) and
    ``messages()`` packs them into one ``MessageBytes`` for decoding.
    """

    times: list[np.ndarray] = field(default_factory=list)
    segments: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=list)

    def count(self) -> int:
        return sum(int(seg[1].size) for seg in self.segments)

    def messages(self) -> MessageBytes:
        return MessageBytes(self.segments)


def _claimed_end(u8: np.ndarray, pos: int, stop: int) -> int:
    """Where the record at ``pos`` ends by its header's length; ``stop`` when that cannot be read."""
    if pos + 9 > stop:
        return stop
    length = int.from_bytes(u8[pos + 1 : pos + 9].tobytes(), "little")
    return min(stop, pos + 9 + length)


def _map_file(fh) -> mmap.mmap | bytes:
    """The open file mapped read-only (b"" when empty: an empty file cannot be mapped)."""
    if os.fstat(fh.fileno()).st_size == 0:
        return b""
    return mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)


def raise_corrupt(reason: str, offset: int) -> None:
    raise _Corrupt(reason, offset)


def _private_records(top: Records) -> list[str]:
    """Where the first top-level record with a private-use opcode (0x80-0xff) lies, once damage is
    found: the likely skipped chunk."""
    private = np.flatnonzero(top.ops >= 0x80)
    if not private.size:
        return []
    first = int(private[0])
    more = f" ({private.size - 1} more such records)" if private.size > 1 else ""
    return [
        f"the record at byte {int(top.offsets[first]) - 9} has the private-use opcode 0x{int(top.ops[first]):02x}"
        f"{more}: a chunk whose opcode byte is damaged looks like that"
    ]
