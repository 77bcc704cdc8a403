"""The message types of a ROS bag as ROS 2 types: one rosbags typestore, CDR bytes, flat columns.

Types come from the definitions the bag carries (ROS 1 connection headers, rosbag2 message
definitions), else from rosbags' built-in ROS 2 store (a rosbag2 without definitions). ROS 1
messages become ROS 2 CDR by byte conversion (``Typestore.ros1_to_cdr``, as ``rosbags convert``
does): ``std_msgs/Header`` is the ROS 2 one, so its ``seq`` is dropped, and ROS 1 ``time`` /
``duration`` are ``builtin_interfaces`` ``sec``/``nanosec`` already. The CDR then takes the MCAP
reader's path: the layout kernel (``logscan.readers.mcap.cdr``) from the ROS 2 ``.msg`` text the
typestore generates, else rosbags' deserializer and ``flatten_messages``. The same messages so give
the same columns as in a ROS 2 MCAP.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from logscan.log import SourceInfo
from logscan.readers.common import UNDECODED_WHY
from logscan.readers.flatten import FlatColumns, MessageBytes, flatten_messages
from logscan.readers.mcap.cdr import CdrLayout, cdr_fast, cdr_layout
from logscan.readers.mcap.scan_records import SchemaRec


def ros2_type_name(msgtype: str) -> str:
    """``pkg/msg/Type`` of a type name (rosbags names ROS 1 types that way already)."""
    parts = msgtype.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else msgtype


def bag_typestore(connections: list, ros1: bool) -> tuple[Any, dict[str, str], Any]:
    """(typestore of every type the bag's connections use, as ROS 2 types; msgtype -> why it cannot
    be decoded; for a ROS 1 bag, the store of its types as written (the ROS 1 Header), else None).

    A definition that does not parse, or a rosbag2 type without a definition that the built-in
    ROS 2 store does not know, makes that type undecodable (its topics are skipped), not the bag.
    """
    from rosbags.interfaces import MessageDefinitionFormat
    from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

    typs: dict = {}
    bad: dict[str, str] = {}
    missing: set[str] = set()
    for connection in connections:
        msgdef = connection.msgdef
        try:
            if msgdef.format == MessageDefinitionFormat.MSG:
                typs.update(get_types_from_msg(msgdef.data, connection.msgtype))
            elif msgdef.format == MessageDefinitionFormat.IDL:
                typs.update(_types_from_idl(msgdef.data, get_types_from_idl))
            else:
                missing.add(connection.msgtype)
        except Exception as exc:  # noqa: BLE001 - a definition from the file that does not parse
            bad[connection.msgtype] = f"message definition does not parse ({_one_line(exc)})"
    ros2 = get_typestore(getattr(Stores, "LATEST", Stores.ROS2_HUMBLE))
    wire = None
    if ros1:
        wire = get_typestore(Stores.EMPTY)
        try:
            wire.register(dict(typs))
        except Exception:  # noqa: BLE001 - disagreeing definitions: reported for the ROS 2 store below
            wire = None
        # the ROS 2 Header: ros1_to_cdr drops the ROS 1 seq
        typs["std_msgs/msg/Header"] = ros2.fielddefs["std_msgs/msg/Header"]
    for msgtype in missing - set(typs):
        if msgtype not in ros2.fielddefs:
            bad[msgtype] = "no message definition in the bag, and not a standard ROS 2 type"
    store = get_typestore(Stores.EMPTY)
    if missing:
        store.register({k: v for k, v in ros2.fielddefs.items() if k not in typs})
    try:
        store.register(typs)
    except Exception as exc:  # noqa: BLE001 - definitions of one type that disagree
        for msgtype in {c.msgtype for c in connections}:
            bad.setdefault(msgtype, f"message definitions do not agree ({_one_line(exc)})")
    return store, bad, wire


def _one_line(exc: Exception, limit: int = 160) -> str:
    """An exception as one short line (rosbags' parse errors quote the definition over lines)."""
    text = " ".join(f"{type(exc).__name__}: {exc}".split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _types_from_idl(text: str, get_types_from_idl) -> dict:
    sep = "=" * 80 + "\n"
    if not text.startswith(f"{sep}IDL: "):
        return get_types_from_idl(text)
    typs: dict = {}
    for block in text.split(sep)[1:]:
        typs.update(get_types_from_idl(block.split("\n", 1)[1]))
    return typs


def ros1_to_cdr(store: Any, msgtype: str, datas: list[bytes]) -> tuple[MessageBytes, list[int]]:
    """CDR of ROS 1 messages, by byte conversion (no deserialization) into one buffer, each
    message after its 4-byte CDR header; and the indices of the messages that do not fit the
    definition (left out). What ``Typestore.ros1_to_cdr`` does per message, without a buffer each."""
    msgdef = store.get_msgdef(msgtype)
    getsize, convert = msgdef.getsize_ros1_to_cdr, msgdef.ros1_to_cdr
    sizes: list[int] = []
    kept: list[bytes] = []
    failed: list[int] = []
    for index, data in enumerate(datas):
        try:
            used, size = getsize(data, 0, None, 0, store)
        except Exception:  # noqa: BLE001 - message bytes that do not fit the definition
            used, size = -1, 0
        if used != len(data):
            failed.append(index)
            continue
        sizes.append(size + 4)
        kept.append(data)
    ends = np.cumsum(np.asarray(sizes, dtype=np.int64))
    starts = ends - np.asarray(sizes, dtype=np.int64)
    buf = bytearray(int(ends[-1]) if ends.size else 0)
    view = memoryview(buf)
    for data, start, end in zip(kept, starts.tolist(), ends.tolist()):
        buf[start + 1] = 1  # CDR little endian: 00 01 00 00
        convert(data, 0, view[start + 4 : end], 0, store)
    return MessageBytes([(np.frombuffer(buf, dtype=np.uint8), starts, ends)]), failed


class TopicColumns:
    """Columns of CDR messages per type: the layout kernel when the type has a layout, else
    rosbags' deserializer and ``flatten_messages``; the layout of a type is made once."""

    def __init__(self, store: Any):
        self.store = store
        self.layouts: dict[str, CdrLayout | None] = {}
        self.names: dict[type, tuple[str, ...]] = {}  # field names per rosbags message class

    def layout(self, msgtype: str) -> CdrLayout | None:
        if msgtype not in self.layouts:
            try:
                text = self.store.generate_msgdef(msgtype, ros_version=2)[0]
            except Exception:  # noqa: BLE001 - a type rosbags cannot write out: the deserializer path
                self.layouts[msgtype] = None
            else:
                schema = SchemaRec(id=0, name=ros2_type_name(msgtype), encoding="ros2msg", data=text.encode())
                self.layouts[msgtype] = cdr_layout(schema)
        return self.layouts[msgtype]

    def columns(
        self, topic: str, msgtype: str, cdrs: MessageBytes, times: np.ndarray, skips: SourceInfo
    ) -> tuple[FlatColumns, np.ndarray]:
        """Flat columns of one topic's CDR messages and the times of the messages they index."""
        layout = self.layout(msgtype)
        flat = cdr_fast(layout, cdrs) if layout is not None else None
        if flat is not None:
            return flat, times
        messages, failed = [], []
        for index, data in enumerate(cdrs.to_list()):
            try:
                messages.append(_plain(self.store.deserialize_cdr(data, msgtype), self.store, self.names))
            except Exception:  # noqa: BLE001 - message bytes that do not fit the definition
                failed.append(index)
        if failed:
            skips.skip(topic, UNDECODED_WHY, len(failed))
            keep = np.ones(len(cdrs), dtype=bool)
            keep[failed] = False
            times = times[keep]
        return flatten_messages(messages), times


def _plain(value: Any, store: Any, names: dict[type, tuple[str, ...]]) -> Any:
    """A rosbags message as the MCAP decoders give it: its fields (not its constants) by name,
    ``uint8[]`` as bytes. ``names`` caches the field names per message class."""
    kind = type(value)
    if dataclasses.is_dataclass(kind):
        fields = names.get(kind)
        if fields is None:
            fields = names[kind] = tuple(name for name, _ in store.fielddefs[value.__msgtype__][1])
        return {name: _plain(getattr(value, name), store, names) for name in fields}
    if isinstance(value, np.ndarray):
        return value.tobytes() if value.dtype == np.uint8 else value
    if isinstance(value, list):
        return [_plain(item, store, names) for item in value]
    return value
