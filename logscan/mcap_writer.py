"""MCAP writer for numeric topics (JSON or ROS 2 CDR): deterministic bytes, written atomically.

``write_mcap(path, {"/imu": TopicData("sensor_msgs/msg/Imu", t_ns, {"linear_acceleration.x": x,
...})})`` writes one message per timestamp per topic. Dotted field names become nested JSON
objects, or nested ROS 2 message types (sub-definitions ``MSG: <pkg>/<Type><Field>`` after a
``====`` separator line), so ``logscan.readers.mcap_reader`` reads both back as channels
``/imu/linear_acceleration.x``. All fields are float64 (ROS 2 ``float64``).

Messages go out in global log_time order (stable: ties keep topic order), in lz4 chunks (none when
lz4 is missing) with CRCs, message and chunk indexes, statistics and a data-section CRC. The header
says library ``logscan`` and nothing depends on the clock, so equal inputs give equal bytes.
Metadata records (``{name: {key: value}}``, e.g. ``logscan.truth`` / ``logscan.profile``, see the
reader) are written before the messages, in the order given.
"""

from __future__ import annotations

import io
import json
import math
import os
import re
from dataclasses import dataclass

import numpy as np

from logscan.artifacts import write_atomic
from logscan.errors import UsageError

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
                raise UsageError(
                    f"topic {topic!r}: field {name!r} has shape {np.shape(values)}, t_ns has {t.shape}"
                )


def mcap_bytes(
    topics: dict[str, TopicData],
    *,
    encoding: str = "json",
    metadata: dict[str, dict[str, str]] | None = None,
    chunk_size: int = 1024 * 1024,
) -> bytes:
    """The MCAP file ``write_mcap`` writes, as bytes (``chunk_size``: uncompressed bytes per chunk)."""
    from mcap.writer import CompressionType, Writer

    _check(topics, encoding)
    try:
        import lz4.frame  # noqa: F401 - only checks availability

        compression = CompressionType.LZ4
    except ImportError:
        compression = CompressionType.NONE
    buffer = io.BytesIO()
    writer = Writer(buffer, chunk_size=chunk_size, compression=compression, enable_data_crcs=True)
    writer.start(profile="ros2" if encoding == "ros2" else "", library=LIBRARY)
    for name, record in (metadata or {}).items():
        writer.add_metadata(name, {str(k): str(v) for k, v in record.items()})

    channel_ids: list[int] = []
    payloads: list[list[bytes]] = []
    times: list[np.ndarray] = []
    for topic, data in topics.items():
        tree = _field_tree(list(data.fields), topic)
        if encoding == "ros2":
            text = _ros2_msgdef(data.schema_name, tree, topic)
            schema_id = writer.register_schema(data.schema_name, "ros2msg", text.encode())
            channel_id = writer.register_channel(topic, "cdr", schema_id)
        else:
            schema = json.dumps(_json_schema(tree, data.schema_name), separators=(",", ":"))
            schema_id = writer.register_schema(data.schema_name, "jsonschema", schema.encode())
            channel_id = writer.register_channel(topic, "json", schema_id)
        channel_ids.append(channel_id)
        payloads.append(_payloads(data, topic, encoding, tree))
        times.append(np.asarray(data.t_ns, dtype=np.int64))

    if times:
        all_t = np.concatenate(times)
        which = np.concatenate([np.full(t.size, k, dtype=np.int64) for k, t in enumerate(times)])
        row = np.concatenate([np.arange(t.size, dtype=np.int64) for t in times])
        order = np.argsort(all_t, kind="stable")
        add = writer.add_message
        sequence = [0] * len(times)
        for log_time, k, r in zip(all_t[order].tolist(), which[order].tolist(), row[order].tolist()):
            add(channel_ids[k], log_time, payloads[k][r], log_time, sequence[k])
            sequence[k] += 1
    writer.finish()
    return buffer.getvalue()


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
