"""MCAP writer for numeric topics (JSON or ROS 2 CDR): deterministic bytes, written atomically.

``write_mcap(path, {"/imu": TopicData("sensor_msgs/msg/Imu", t_ns, {"linear_acceleration.x": x,
...})})`` writes one message per timestamp per topic. Dotted field names become nested JSON
objects, or nested ROS 2 message types (sub-definitions ``MSG: <pkg>/<Type><Field>`` after a
``====`` separator line), so ``logscan.readers.mcap.reader`` reads both back as channels
``/imu/linear_acceleration.x``. All fields are float64 (ROS 2 ``float64``).

Messages go out in global log_time order (stable: ties keep topic order), in lz4 chunks (none when
lz4 is missing) with CRCs, message and chunk indexes, statistics and a data-section CRC. The header
says library ``logscan`` and nothing depends on the clock, so equal inputs give equal bytes.
Metadata records (``{name: {key: value}}``, e.g. ``logscan.truth`` / ``logscan.profile``, see the
reader) are written before the messages, in the order given.
"""

from __future__ import annotations

import json
import math
import os
import re
import struct
import zlib
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from logscan.artifacts import write_atomic
from logscan.errors import UsageError
from logscan.readers.common import MCAP_MAGIC

LIBRARY = "logscan"
_ROS2_FIELD = re.compile(r"^[a-z][a-z0-9_]*$")
_CDR_HEADER = b"\x00\x01\x00\x00"  # CDR, little endian, no options


@dataclass
class TopicData:
    """One topic to write: its schema name, int64 ns log times and float64 fields by dotted name."""

    schema_name: str
    t_ns: np.ndarray
    fields: dict[str, np.ndarray]


def _field_tree(names: list[str], topic: str) -> dict:
    """Nested dict of the dotted ``names`` (leaves are None), in first-seen order."""
    tree: dict = {}
    for name in names:
        parts = name.split(".")
        if not name or any(not part for part in parts):
            raise UsageError(f"topic {topic!r}: empty part in field name {name!r}")
        node = tree
        for part in parts[:-1]:
            child = node.setdefault(part, {})
            if child is None:
                raise UsageError(f"topic {topic!r}: field {part!r} is both a value and a message in {name!r}")
            node = child
        if parts[-1] in node:
            raise UsageError(f"topic {topic!r}: field {name!r} given twice or also used as a message")
        node[parts[-1]] = None
    return tree


def _leaf_order(tree: dict, prefix: str = "") -> list[str]:
    """Dotted leaf names in depth-first order: the order of the values in the message."""
    out: list[str] = []
    for key, child in tree.items():
        name = prefix + key
        out.extend([name] if child is None else _leaf_order(child, name + "."))
    return out


def _json_template(tree: dict) -> str:
    """``{"a":{"x":%s,...},...}`` with one %s per leaf, in depth-first order."""
    parts = []
    for key, child in tree.items():
        value = "%s" if child is None else _json_template(child)
        parts.append(json.dumps(key) + ":" + value)
    return "{" + ",".join(parts) + "}"


def _json_schema(tree: dict, title: str | None = None) -> dict:
    schema: dict = {"type": "object", "properties": {}}
    if title:
        schema["title"] = title
    for key, child in tree.items():
        schema["properties"][key] = {"type": "number"} if child is None else _json_schema(child)
    return schema


def _camel(word: str) -> str:
    return "".join(piece[:1].upper() + piece[1:] for piece in word.split("_"))


def _ros2_msgdef(schema_name: str, tree: dict, topic: str) -> str:
    """ROS 2 concatenated message definition: the root type, then one ``MSG:`` block per sub-type."""
    package = schema_name.split("/")[0]
    root = schema_name.split("/")[-1]
    blocks: list[str] = []

    def define(node: dict, type_name: str) -> str:
        lines = []
        for key, child in node.items():
            if not _ROS2_FIELD.match(key) or "__" in key or key.endswith("_"):
                raise UsageError(
                    f"topic {topic!r}: {key!r} is not a valid ROS 2 field name",
                    hint="use lower_case names, or write with encoding='json'",
                )
            if child is None:
                lines.append(f"float64 {key}")
            else:
                sub_type = type_name + _camel(key)
                blocks.append("=" * 80 + f"\nMSG: {package}/{sub_type}\n" + define(child, sub_type))
                lines.append(f"{package}/{sub_type} {key}")
        return "\n".join(lines) + "\n"

    head = define(tree, root)
    return head + "".join(blocks)


def _payloads(data: TopicData, topic: str, encoding: str, tree: dict) -> list[bytes]:
    order = _leaf_order(tree)
    n = data.t_ns.shape[0]
    matrix = np.empty((n, len(order)), dtype=np.float64)
    for column, name in enumerate(order):
        matrix[:, column] = data.fields[name]
    if encoding == "ros2":
        # CDR: 4-byte encapsulation header, then the float64 values (8-aligned, no padding).
        body = matrix.astype("<f8").tobytes()
        width = 8 * len(order)
        return [_CDR_HEADER + body[k * width : (k + 1) * width] for k in range(n)]
    template = _json_template(tree)
    rows = matrix.tolist()
    finite = np.isfinite(matrix).all(axis=1).tolist()
    out = []
    for row, ok in zip(rows, finite):
        values = tuple(map(repr, row)) if ok else tuple(_json_number(v) for v in row)
        out.append((template % values).encode())
    return out


def _json_number(value: float) -> str:
    if math.isnan(value):
        return "NaN"
    if math.isinf(value):
        return "Infinity" if value > 0 else "-Infinity"
    return repr(value)


def _check(topics: dict[str, TopicData], encoding: str) -> None:
    if encoding not in ("json", "ros2"):
        raise UsageError(f"unknown MCAP message encoding {encoding!r}", hint="use 'json' or 'ros2'")
    for topic, data in topics.items():
        t = np.asarray(data.t_ns)
        if t.ndim != 1:
            raise UsageError(f"topic {topic!r}: t_ns must be one-dimensional")
        if not data.fields:
            raise UsageError(f"topic {topic!r}: no fields to write")
        for name, values in data.fields.items():
            if np.shape(values) != t.shape:
                raise UsageError(f"topic {topic!r}: field {name!r} has shape {np.shape(values)}, t_ns has {t.shape}")


class _Out:
    """Byte sink that tracks offsets and builds MCAP records (opcode, u64 length, body)."""

    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.size = 0

    def add(self, data: bytes) -> int:
        offset = self.size
        self.parts.append(data)
        self.size += len(data)
        return offset

    def record(self, opcode: int, body: bytes) -> int:
        return self.add(struct.pack("<BQ", opcode, len(body)) + body)

    def crc(self, start: int = 0) -> int:
        crc, offset = 0, 0
        for part in self.parts:
            if offset + len(part) > start:
                crc = zlib.crc32(part[max(0, start - offset) :], crc)
            offset += len(part)
        return crc


def _string(text: str) -> bytes:
    data = text.encode("utf-8")
    return struct.pack("<I", len(data)) + data


def _string_map(items: dict[str, str]) -> bytes:
    body = b"".join(_string(k) + _string(v) for k, v in items.items())
    return struct.pack("<I", len(body)) + body


_MESSAGE_HEADER = np.dtype(
    [
        ("opcode", "u1"),
        ("length", "<u8"),
        ("channel", "<u2"),
        ("sequence", "<u4"),
        ("log_time", "<u8"),
        ("publish_time", "<u8"),
    ]
)


def _message_records(
    channel: np.ndarray, sequence: np.ndarray, log_time: np.ndarray, datas: list[bytes]
) -> tuple[bytes, np.ndarray]:
    """Message records back to back, and the offset of each within the returned bytes."""
    sizes = np.fromiter((len(d) for d in datas), dtype=np.int64, count=len(datas))
    headers = np.zeros(len(datas), dtype=_MESSAGE_HEADER)
    headers["opcode"] = 0x05
    headers["length"] = sizes + (_MESSAGE_HEADER.itemsize - 9)
    headers["channel"] = channel
    headers["sequence"] = sequence
    headers["log_time"] = log_time
    headers["publish_time"] = log_time
    raw = headers.tobytes()
    width = _MESSAGE_HEADER.itemsize
    pieces = [raw[k * width : (k + 1) * width] for k in range(len(datas))]
    body = b"".join([piece for pair in zip(pieces, datas) for piece in pair])
    offsets = np.concatenate([[0], np.cumsum(sizes + width)[:-1]]).astype(np.int64)
    return body, offsets


def mcap_bytes(
    topics: dict[str, TopicData],
    *,
    encoding: str = "json",
    metadata: dict[str, dict[str, str]] | None = None,
    chunk_size: int = 1024 * 1024,
) -> bytes:
    """The MCAP file ``write_mcap`` writes, as bytes (``chunk_size``: uncompressed bytes per chunk).

    Layout: magic, Header, Metadata records, Chunks (the first one also holds the Schema and
    Channel records) each followed by its MessageIndex records, DataEnd with the data-section
    CRC; summary: Schemas, Channels, Statistics, ChunkIndexes, MetadataIndexes, SummaryOffsets;
    Footer with the summary CRC; magic.
    """
    _check(topics, encoding)
    try:
        import lz4.frame

        compress, compression = lz4.frame.compress, "lz4"
    except ImportError:
        compress, compression = None, ""

    schema_records, channel_records, payloads, times = _topic_records(topics, encoding)
    out = _Out()
    out.add(MCAP_MAGIC)
    out.record(0x01, _string("ros2" if encoding == "ros2" else "") + _string(LIBRARY))
    metadata_indexes = []
    for name, items in (metadata or {}).items():
        body = _string(name) + _string_map({str(k): str(v) for k, v in items.items()})
        offset = out.record(0x0C, body)
        metadata_indexes.append(_record(0x0D, struct.pack("<QQ", offset, 9 + len(body)) + _string(name)))

    messages = _in_time_order(times, payloads)
    chunk_indexes: list[bytes] = []
    for chunk_number, (lo, hi) in enumerate(_chunk_bounds(messages.datas, chunk_size)):
        prefix = b"".join(schema_records + channel_records) if chunk_number == 0 else b""
        chunk_indexes.append(_write_chunk(out, prefix, messages, lo, hi, compress, compression))
    out.record(0x0F, struct.pack("<I", out.crc()))
    _write_summary(out, schema_records, channel_records, messages, len(times), metadata_indexes, chunk_indexes)
    out.add(MCAP_MAGIC)
    return b"".join(out.parts)


def _topic_records(
    topics: dict[str, TopicData], encoding: str
) -> tuple[list[bytes], list[bytes], list[list[bytes]], list[np.ndarray]]:
    """Schema and Channel records (channel and schema ids 1, 2, ... in topic order), and each
    topic's message payloads and int64 log times."""
    schema_records: list[bytes] = []
    channel_records: list[bytes] = []
    payloads: list[list[bytes]] = []
    times: list[np.ndarray] = []
    for number, (topic, data) in enumerate(topics.items(), start=1):
        tree = _field_tree(list(data.fields), topic)
        if encoding == "ros2":
            schema_encoding, message_encoding = "ros2msg", "cdr"
            schema_data = _ros2_msgdef(data.schema_name, tree, topic).encode()
        else:
            schema_encoding, message_encoding = "jsonschema", "json"
            schema_data = json.dumps(_json_schema(tree, data.schema_name), separators=(",", ":")).encode()
        schema_records.append(
            _record(
                0x03,
                struct.pack("<H", number)
                + _string(data.schema_name)
                + _string(schema_encoding)
                + struct.pack("<I", len(schema_data))
                + schema_data,
            )
        )
        channel_records.append(
            _record(
                0x04, struct.pack("<HH", number, number) + _string(topic) + _string(message_encoding) + _string_map({})
            )
        )
        payloads.append(_payloads(data, topic, encoding, tree))
        times.append(np.asarray(data.t_ns, dtype=np.int64))
    return schema_records, channel_records, payloads, times


class _Messages(NamedTuple):
    """Every message in global log_time order: log time, channel id, sequence, payload."""

    t: np.ndarray  # int64 ns
    channel: np.ndarray  # int64, 1-based topic number
    sequence: np.ndarray  # int64
    datas: list[bytes]


def _in_time_order(times: list[np.ndarray], payloads: list[list[bytes]]) -> _Messages:
    """Every message in global log_time order (stable: ties keep topic order)."""
    all_t = np.concatenate(times) if times else np.empty(0, dtype=np.int64)
    which = np.concatenate([np.full(t.size, k + 1, dtype=np.int64) for k, t in enumerate(times)]) if times else all_t
    row = np.concatenate([np.arange(t.size, dtype=np.int64) for t in times]) if times else all_t
    order = np.argsort(all_t, kind="stable")
    all_t, which, row = all_t[order], which[order], row[order]
    datas = [payloads[k - 1][r] for k, r in zip(which.tolist(), row.tolist())]
    # sequence: the message's number within its channel (= its row, as rows are in time order)
    return _Messages(all_t, which, row, datas)


def _chunk_bounds(datas: list[bytes], chunk_size: int) -> list[tuple[int, int]]:
    """(first, stop) message numbers of each chunk; one empty chunk when there are no messages."""
    sizes = np.fromiter((len(d) for d in datas), dtype=np.int64, count=len(datas)) + _MESSAGE_HEADER.itemsize
    # chunk boundaries: start a new chunk when the running size passes a multiple of chunk_size
    chunk_of = np.cumsum(sizes) // max(1, chunk_size) if len(datas) else np.empty(0, dtype=np.int64)
    starts = np.flatnonzero(np.r_[True, np.diff(chunk_of) != 0]) if len(datas) else np.empty(0, dtype=np.int64)
    bounds = list(zip(starts.tolist(), starts[1:].tolist() + [len(datas)]))
    if not bounds:
        bounds = [(0, 0)]
    return bounds


def _write_chunk(out: _Out, prefix: bytes, messages: _Messages, lo: int, hi: int, compress, compression: str) -> bytes:
    """Write messages ``lo:hi`` (after ``prefix`` records) as a Chunk and its MessageIndexes; its ChunkIndex."""
    channel = messages.channel[lo:hi]
    t = messages.t[lo:hi]
    body, offsets = _message_records(channel, messages.sequence[lo:hi], t, messages.datas[lo:hi])
    records = prefix + body
    offsets = offsets + len(prefix)
    payload = compress(records) if compress is not None else records
    t_start = int(t.min()) if t.size else 0
    t_end = int(t.max()) if t.size else 0
    chunk_body = (
        struct.pack("<QQQI", t_start, t_end, len(records), zlib.crc32(records))
        + _string(compression)
        + struct.pack("<Q", len(payload))
        + payload
    )
    chunk_offset = out.record(0x06, chunk_body)
    chunk_length = 9 + len(chunk_body)
    index_offsets: dict[int, int] = {}
    index_start = out.size
    for k in np.unique(channel).tolist():
        select = channel == k
        pairs = np.empty((int(np.count_nonzero(select)), 2), dtype="<u8")
        pairs[:, 0] = t[select]
        pairs[:, 1] = offsets[select]
        index_offsets[k] = out.record(0x07, struct.pack("<HI", k, pairs.nbytes) + pairs.tobytes())
    offsets_map = b"".join(struct.pack("<HQ", k, v) for k, v in index_offsets.items())
    return _record(
        0x08,
        struct.pack("<QQQQ", t_start, t_end, chunk_offset, chunk_length)
        + struct.pack("<I", len(offsets_map))
        + offsets_map
        + struct.pack("<Q", out.size - index_start)
        + _string(compression)
        + struct.pack("<QQ", len(payload), len(records)),
    )


def _write_summary(
    out: _Out,
    schema_records: list[bytes],
    channel_records: list[bytes],
    messages: _Messages,
    n_topics: int,
    metadata_indexes: list[bytes],
    chunk_indexes: list[bytes],
) -> None:
    """Write the summary (schemas, channels, statistics, chunk and metadata indexes, their offsets) and the footer."""
    summary_start = out.size
    all_t = messages.t
    counts = np.bincount(messages.channel, minlength=n_topics + 1)[1:] if n_topics else []
    counts_map = b"".join(struct.pack("<HQ", k + 1, int(c)) for k, c in enumerate(counts))
    statistics = _record(
        0x0B,
        struct.pack(
            "<QHIIIIQQ",
            len(messages.datas),
            n_topics,
            n_topics,
            0,
            len(metadata_indexes),
            len(chunk_indexes),
            int(all_t.min()) if all_t.size else 0,
            int(all_t.max()) if all_t.size else 0,
        )
        + struct.pack("<I", len(counts_map))
        + counts_map,
    )
    offsets_records = []
    for opcode, group in (
        (0x03, schema_records),
        (0x04, channel_records),
        (0x0B, [statistics]),
        (0x08, chunk_indexes),
        (0x0D, metadata_indexes),
    ):
        if not group:
            continue
        group_start = out.size
        for record in group:
            out.add(record)
        offsets_records.append(_record(0x0E, struct.pack("<BQQ", opcode, group_start, out.size - group_start)))
    summary_offset_start = out.size
    for record in offsets_records:
        out.add(record)
    footer_head = struct.pack("<BQQQ", 0x02, 20, summary_start, summary_offset_start)
    out.add(footer_head)
    out.add(struct.pack("<I", out.crc(summary_start)))


def _record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


def write_mcap(
    path: str | os.PathLike,
    topics: dict[str, TopicData],
    *,
    encoding: str = "json",
    metadata: dict[str, dict[str, str]] | None = None,
    chunk_size: int = 1024 * 1024,
) -> None:
    """Write ``topics`` to the MCAP file ``path`` atomically (see the module docstring)."""
    write_atomic(path, mcap_bytes(topics, encoding=encoding, metadata=metadata, chunk_size=chunk_size))
