"""PX4 ULog input through pyulog: topics ``<name>_<multi_id>``, channels ``/<name>_<multi_id>/<field>``.

Array fields keep pyulog's names (``xyz[0]``). Messages with timestamp 0 (PX4's "never set")
are dropped and counted. ``char`` fields (strings) and ``_padding`` fields
are skipped and counted. Timestamps are microseconds in the file and int64 nanoseconds here.
``source.metadata`` holds ``ulog.info`` (``sys_name``, ``ver_hw``, ...), ``ulog.parameters``
(initial values), ``ulog.parameters_changed``, ``ulog.log`` (counts of dropouts, logged messages,
changed parameters, corruption flags) and ``ulog.messages`` (the logged text messages).
"""

from __future__ import annotations

import os
import re
import struct

import numpy as np

from logscan.errors import CorruptLogError, InputError
from logscan.log import Channel, Log, SourceInfo, TopicInfo
from logscan.readers.csv_reader import ZERO_TIMESTAMP_WHY, report_time_order

_INSTANCE_RE = re.compile(r"^(?P<name>.+)_(?P<instance>\d+)$")
_MAX_TEXT_MESSAGES = 500  # logged text messages kept in metadata (the count is always exact)


def message_filter(wanted: set[str] | None) -> list[str] | None:
    """ULog message names to decode for ``wanted`` topics/channels (None: all).

    ``vehicle_imu_0`` and ``/vehicle_imu_0/accel[0]`` both ask for message ``vehicle_imu``.
    """
    if wanted is None:
        return None
    names = set()
    for item in wanted:
        topic = item.lstrip("/").split("/", 1)[0]
        match = _INSTANCE_RE.match(topic)
        names.add(match.group("name") if match else topic)
    return sorted(names)


def read_ulog(path: str | os.PathLike, wanted: set[str] | None) -> Log:
    """Read a ULog file into a Log, decoding only the messages ``wanted`` asks for."""
    from pyulog import ULog
    from pyulog.exceptions import ULogException

    from logscan.readers import topic_wanted

    source = SourceInfo(path=str(path), format="ulog", time_unit="us", time_source="ulog timestamp")
    try:
        ulog = ULog(str(path), message_filter(wanted), True)
    except FileNotFoundError:
        raise InputError("no such file", path=str(path)) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=str(path)) from None
    except (ULogException, struct.error, ValueError, IndexError, KeyError, OverflowError,
            UnicodeDecodeError, TypeError, MemoryError) as exc:
        raise CorruptLogError(
            f"ULog cannot be parsed ({type(exc).__name__}: {exc})".rstrip(": )") + ")",
            path=str(path),
            hint="the file header or definitions section is damaged",
        ) from None

    channels: dict[str, Channel] = {}
    for data in ulog.data_list:
        topic = f"{data.name}_{data.multi_id}"
        if not (topic_wanted(topic, wanted) or topic_wanted("/" + topic, wanted)):
            continue
        if topic in source.topics:  # same message and instance subscribed twice: keep the first
            source.skip(f"topic {topic}", "subscribed twice in the file; second copy ignored")
            continue
        t_us = np.asarray(data.data["timestamp"], dtype=np.int64)
        keep = t_us != 0  # PX4 publishes timestamp 0 for a message never really set
        if not keep.all():
            source.skip(f"messages of {topic}", ZERO_TIMESTAMP_WHY, int((~keep).sum()))
        t_ns = t_us[keep] * 1000
        fields = []
        for field in data.field_data:
            name = field.field_name
            if name == "timestamp":
                continue
            if name.startswith("_padding"):
                continue
            if field.type_str == "char":
                if "[" in name and not name.endswith("[0]"):
                    continue  # one skip per string field, not per character
                source.skip(f"text field {data.name}.{_array_base(name)}", "char (string) field")
                continue
            fields.append(name)
            channel = f"/{topic}/{name}"
            if topic_wanted(channel, wanted) or topic_wanted(topic, wanted) or topic_wanted(
                "/" + topic, wanted
            ):
                channels[channel] = Channel(channel, t_ns, data.data[name][keep])
        source.topics[topic] = TopicInfo(
            name=topic,
            message_count=int(t_ns.size),
            encoding="ulog",
            schema=data.name,
            first_ns=int(t_ns.min()) if t_ns.size else None,
            last_ns=int(t_ns.max()) if t_ns.size else None,
            fields=fields,
        )
        report_time_order(t_ns, topic, source)
    _fill_metadata(ulog, source)
    if ulog.file_corruption:
        source.partial = True
        source.partial_reason = (
            "pyulog found corrupt data and skipped it; the topics hold the messages around it"
        )
    if wanted is not None and not source.topics:
        source.warnings.append(f"none of the requested topics is in the log: {sorted(wanted)}")
    return Log(channels=channels, source=source)


def _array_base(name: str) -> str:
    return name.split("[", 1)[0]


def _fill_metadata(ulog, source: SourceInfo) -> None:
    """Info, parameters, dropouts and logged messages of the file into ``source.metadata``."""
    source.metadata["ulog.info"] = {str(k): _text(v) for k, v in ulog.msg_info_dict.items()}
    source.metadata["ulog.parameters"] = {
        str(k): _text(v) for k, v in ulog.initial_parameters.items()
    }
    changed = ulog.changed_parameters
    if changed:
        source.metadata["ulog.parameters_changed"] = {
            f"{i:05d}": f"{t / 1e6:.6f} s {name} = {_text(value)}"
            for i, (t, name, value) in enumerate(changed)
        }
    dropouts = ulog.dropouts
    dropout_ms = sum(int(d.duration) for d in dropouts)
    messages = list(ulog.logged_messages)
    for tagged in ulog.logged_messages_tagged.values():
        messages.extend(tagged)
    messages.sort(key=lambda m: m.timestamp)
    source.metadata["ulog.log"] = {
        "start_timestamp_us": str(ulog.start_timestamp),
        "last_timestamp_us": str(ulog.last_timestamp),
        "dropouts": str(len(dropouts)),
        "dropout_total_ms": str(dropout_ms),
        "logged_messages": str(len(messages)),
        "changed_parameters": str(len(changed)),
        "file_corruption": str(bool(ulog.file_corruption)).lower(),
        "data_appended": str(bool(ulog.has_data_appended)).lower(),
        "info_multiple_keys": ", ".join(sorted(ulog.msg_info_multiple_dict)),
    }
    source.metadata["ulog.messages"] = {
        f"{i:05d}": f"{m.timestamp / 1e6:.6f} s [{m.log_level_str()}] "
        f"{m.message}"
        for i, m in enumerate(messages[:_MAX_TEXT_MESSAGES])
    }
    if dropouts:
        source.warnings.append(
            f"{len(dropouts)} logging dropout(s), {dropout_ms} ms of data lost in total"
        )


def _text(value) -> str:
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, float):
        return repr(value)
    return str(value)
