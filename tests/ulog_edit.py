"""Edit topics of a real PX4 ULog in place of their bytes, everything else kept as logged.

    edit_ulog(src, dst, {"vehicle_gps_position": edit})   # edit(data): data["eph"][:] = ...

The ULog file is a 16-byte header and then messages (uint16 size, uint8 type, body). A
subscription 'A' (uint8 multi_id, uint16 msg_id, name) binds a msg_id to a topic; each data
message 'D' (uint16 msg_id, then the topic's packed struct) carries one sample. The struct's
layout is the topic's format as pyulog reads it (fields packed without alignment; the logger drops
the trailing padding), so the samples are decoded into a numpy structured array, ``edit`` changes
its fields in place (``data[name]``: one array per field as pyulog names it, ``"q[0]"`` for an
array's element, ``"timestamp"`` in microseconds), and the bytes are written back where they were:
sizes, order, every other topic and the definitions stay as logged.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np
from pyulog import ULog

_TYPES = {
    "int8_t": "i1",
    "uint8_t": "u1",
    "int16_t": "<i2",
    "uint16_t": "<u2",
    "int32_t": "<i4",
    "uint32_t": "<u4",
    "int64_t": "<i8",
    "uint64_t": "<u8",
    "float": "<f4",
    "double": "<f8",
    "bool": "u1",
    "char": "S1",
}
_ELEMENT = re.compile(r"^(?P<name>.+)\[(?P<index>\d+)\]$")


class Fields(Mapping):
    """The samples of one topic: ``data[field]`` is a writable view of one field's column."""

    def __init__(self, rows: np.ndarray):
        self.rows = rows

    def __getitem__(self, key: str) -> np.ndarray:
        match = _ELEMENT.match(key)
        if match and match.group("name") in self.rows.dtype.names:
            return self.rows[match.group("name")][:, int(match.group("index"))]
        return self.rows[key]

    def __iter__(self):
        return iter(self.rows.dtype.names)

    def __len__(self) -> int:
        return len(self.rows.dtype.names)


def _dtype(ulog: ULog, name: str) -> np.dtype:
    """The packed numpy dtype of topic ``name`` (no nested types: a GNSS or status topic)."""
    fields = []
    for type_name, size, field in ulog.message_formats[name].fields:
        base = _TYPES[type_name]  # KeyError: a nested type, which this editor does not unpack
        fields.append((field, base, (size,)) if size > 0 else (field, base))
    return np.dtype(fields)


def _messages(data: bytes):
    """(type, offset of the body, body size) of every message after the header."""
    offset = 16
    while offset + 3 <= len(data):
        size, kind = struct.unpack_from("<HB", data, offset)
        yield kind, offset + 3, size
        offset += 3 + size


def _subscriptions(data: bytes) -> dict[tuple[str, int], int]:
    """(topic, instance) -> msg_id of the log's subscriptions."""
    out = {}
    for kind, body, size in _messages(data):
        if kind == ord("A"):
            multi_id, msg_id = struct.unpack_from("<BH", data, body)
            out[(bytes(data[body + 3 : body + size]).decode(), multi_id)] = msg_id
    return out


def _edit(data: bytearray, dtype: np.dtype, msg_id: int, edit: Callable[[Fields], None]) -> None:
    where = []
    for kind, body, size in _messages(data):
        if kind == ord("D") and struct.unpack_from("<H", data, body)[0] == msg_id:
            where.append((body + 2, min(size - 2, dtype.itemsize)))
    buffer = np.zeros((len(where), dtype.itemsize), dtype=np.uint8)  # the dropped padding reads 0
    for row, (offset, size) in enumerate(where):
        buffer[row, :size] = np.frombuffer(data, dtype=np.uint8, count=size, offset=offset)
    rows = buffer.view(dtype).reshape(len(where))
    edit(Fields(rows))
    for row, (offset, size) in enumerate(where):
        data[offset : offset + size] = buffer[row, :size].tobytes()


def edit_ulog(
    src: str | Path,
    dst: str | Path,
    edits: Mapping[str, Callable[[Fields], None]],
    instance: int = 0,
) -> Path:
    """Copy ULog ``src`` to ``dst`` with each ``edits[topic](data)`` applied to that topic's
    samples (instance ``instance``), in place; a topic the log lacks raises KeyError."""
    data = bytearray(Path(src).read_bytes())
    ulog = ULog(str(src), list(edits))
    ids = _subscriptions(data)
    for topic, edit in edits.items():
        _edit(data, _dtype(ulog, topic), ids[(topic, instance)], edit)
    Path(dst).write_bytes(bytes(data))
    return Path(dst)


def cut_ulog(src: str | Path, dst: str | Path, after_s: float) -> Path:
    """Copy ULog ``src`` up to its first data message stamped more than ``after_s`` after the
    header's start time, that message and all after it left out: a log that ends there cleanly, at
    a message boundary (as if the logger had stopped)."""
    data = Path(src).read_bytes()
    start_us = struct.unpack_from("<Q", data, 8)[0]
    end = len(data)
    for kind, body, size in _messages(data):
        if kind == ord("D") and size >= 10 and struct.unpack_from("<Q", data, body + 2)[0] > start_us + after_s * 1e6:
            end = body - 3
            break
    Path(dst).write_bytes(data[:end])
    return Path(dst)
