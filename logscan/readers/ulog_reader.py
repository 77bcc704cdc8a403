"""PX4 ULog input through pyulog: topics ``<name>_<multi_id>``, channels ``/<name>_<multi_id>/<field>``.

Array fields keep pyulog's names (``xyz[0]``). Messages with timestamp 0 (PX4's "never set")
are dropped and counted. ``char`` fields (strings) and ``_padding`` fields
are skipped and counted. Timestamps are microseconds in the file and int64 nanoseconds here.
``source.metadata`` holds ``ulog.info`` (``sys_name``, ``ver_hw``, ...), ``ulog.parameters``
(initial values), ``ulog.parameters_default`` (PX4's system defaults of the parameters set away
from them, when the log has them), ``ulog.parameters_changed``, ``ulog.log`` (counts of dropouts,
logged messages, changed parameters, corruption flags) and ``ulog.messages`` (the logged text
messages).

Damage: pyulog stops without a word at a message it cannot frame (a data message of size 0 ends
its read loop: the rest of the file is dropped) and at a cut message. The reader watches every
byte range pyulog reads; a message cut by the end of the file, bytes never read (framing broken:
the reader stopped early or jumped), appended-data offsets past the end of the file, or pyulog's
corruption flag make the log partial, with ``partial_reason`` saying where and how much was
recovered. Messages pyulog drops without a word are damage too, counted in ``partial_reason``:
message types the format does not define (a damaged type byte), data messages with no
subscription for their msg_id or of a size their format does not fit (a lost or damaged 'A'
record), subscriptions an 'A' record reusing their msg_id replaces, a topic subscribed twice (the
second copy), and timestamps whose nanoseconds do not fit int64 (a header start timestamp like
that is not used as the log's time zero). A cut exactly between two messages leaves a valid,
shorter ULog (the format has no index or end marker): that cannot be told from a log that ended
there. A subscribed format without
a ``timestamp`` field (the spec requires one; a damaged definition renames it) has no times: its
topic is skipped with a warning naming it and the log is partial (a CorruptLogError when no other
topic is left); pyulog would stop reading the file at its first message, the reader reads on.

Sizes: every ULog message states its size in a uint16, so no read exceeds 64 KiB. Message
formats are data too: pyulog flattens a subscribed format into one field per array element,
recursively, so a format that contains itself, or nested arrays that multiply (``B[60000]`` of
``C[60000]`` of ``float[60000]``), would recurse or hang; a subscribed format whose flattened size
exceeds what a 64 KiB message can hold, or that nests deeper than ``_MAX_FORMAT_NESTING``, is
refused before pyulog flattens it: pyulog counts it as corrupt data and skips that subscription,
so the log is partial (other topics are still read).
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import struct
from collections.abc import Callable, Iterable, Iterator
from functools import partial

import numpy as np

from logscan.errors import CorruptLogError
from logscan.log import Channel, Log, SourceInfo, TopicInfo
from logscan.memory import collector_paused
from logscan.readers import spill
from logscan.readers.common import (
    ZERO_TIMESTAMP_WHY,
    StagedBytes,
    channel_wanted,
    input_error,
    report_time_order,
    stat_input,
    topic_wanted,
)
from logscan.readers.ulog_columns import exact_in_float32, field_lists, stamp_facts
from logscan.readers.ulog_damage import (
    _UNTIMED_WHY,
    MAX_TIMESTAMP_US,
    _bounded_ulog_class,
    _dropped_by_pyulog,
    _header_damage,
    _ReadWatch,
    _report_damage,
)
from logscan.readers.ulog_framed import parse_clean

_INSTANCE_RE = re.compile(r"^(?P<name>.+)_(?P<instance>\d+)$")
_MAX_TEXT_MESSAGES = 500  # logged text messages kept in metadata (the count is always exact)
_BEYOND_WHY = "timestamp beyond int64 nanoseconds (damaged)"
# Shares of a clean read's CPU time (the 6 ULogs of ../shared/testdata, 0.4 to 1.9 MB: about 7-15%,
# 30-40% and 45-60%): the numba framing pass, the parse of the definitions (with the subscriptions'
# buffers filled), the topics' columns converted. They weight the byte progress (`StagedBytes`) so
# that a bar advances about evenly in time.
_STAGE_SHARES = (0.15, 0.35, 0.50)
_FRAMED, _PARSED, _CONVERTED = range(3)
_DATA_HEADER_BYTES = 5  # a data message's size, type and msg_id before its payload
# A held read (block mode's, `read_ulog`'s ``held``) of a file from this size keeps its arrays on
# disk (`logscan.readers.spill`): about 20 minutes of a PX4 log at its default rates, where the held
# channels (two thirds of the file's bytes) start to weigh beside a block's analysis; below it the
# files and mappings are not worth their cost.
SPILL_FROM_BYTES = spill.HELD_FROM_BYTES


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


def read_ulog(
    path: str | os.PathLike,
    wanted: set[str] | None,
    *,
    progress: Callable[[int, int], None] | None = None,
    held: bool = False,
) -> Log:
    """Read a ULog file into a Log, decoding only the messages ``wanted`` asks for; ``held``: a
    log held for block mode's windows, its fields of a type float32 holds exactly (8 and 16-bit
    integers, bool, float) kept as float32 (`Channel.held`: most of a PX4 log, half the bytes).

    ``progress(done, file size)`` (`StagedBytes`): after the framing pass, after the parse of the definitions,
    after each topic converted (the bytes of the data messages converted so far), and at the end.
    A damaged file (read the careful way) is not framed: no call before pyulog's parse ends.
    A held read of a file of `SPILL_FROM_BYTES` or more keeps its records and channels on disk
    (`logscan.readers.spill`): a long log held whole holds in memory only what a step has in hand."""
    size = stat_input(path).st_size
    # its arrays take about its size on disk; the collector paused: a channel per field, made by
    # the thousand, was walked again by every collection they set off (what cyclic garbage the read
    # leaves, a few thousand objects of its format tables at any length, waits for it once)
    with spill.spilling(held and size >= SPILL_FROM_BYTES, needs=2 * size), collector_paused():
        return _read_ulog(path, wanted, progress, held, size)


def _read_ulog(path: str | os.PathLike, wanted: set[str] | None, progress, held: bool, size: int) -> Log:
    source = SourceInfo(path=str(path), format="ulog", time_unit="us", time_source="ulog timestamp")
    steps = None if progress is None else StagedBytes(progress, size, _STAGE_SHARES)
    ulog, watch, chatter = _parse(path, wanted, None if steps is None else partial(steps.at, _FRAMED, 1.0))
    if steps is not None:
        steps.at(_PARSED, 1.0)
    channels: dict[str, Channel] = {}
    untimed: list[str] = []  # topics whose format has no timestamp field: skipped, the log is partial
    lost: list[str] = []  # other messages dropped: each makes the log partial
    chosen = [data for data in ulog.data_list if _is_wanted(data, wanted)]
    with np.errstate(invalid="ignore"):  # entered once per read, not once per topic
        for data in chosen if steps is None else _converting(chosen, steps):
            topic = f"{data.name}_{data.multi_id}"
            if topic in source.topics:  # same message and instance subscribed twice: keep the first
                count = len(next(iter(data.data.values()), ()))
                source.skip(f"messages of {topic}", "subscribed twice in the file; second copy ignored", count)
                lost.append(f"{topic} subscribed twice: the {count} message(s) of the second subscription dropped")
            elif not _has_timestamp(data):  # the format breaks the spec: its definition is damaged
                count = len(next(iter(data.data.values()), ()))
                source.skip(f"topic {topic}", _UNTIMED_WHY, count)
                untimed.append(topic)
            else:
                lost.extend(_read_topic(data, topic, wanted, source, channels, held))
            if hasattr(data, "release"):  # a clean read's records (`ulog_definitions._Topic`)
                data.release()
    _fill_metadata(ulog, source)
    lost = _header_damage(ulog, source) + _dropped_by_pyulog(ulog) + lost
    _report_damage(path, ulog, source, chatter.getvalue(), watch, all_topics=wanted is None, untimed=untimed, lost=lost)
    if wanted is not None and not source.topics:
        source.warnings.append(f"none of the requested topics is in the log: {sorted(wanted)}")
    if steps is not None:
        steps.finish()
    return Log(channels=channels, source=source)


def _read_topic(
    data, topic: str, wanted: set[str] | None, source: SourceInfo, channels: dict, held: bool = False
) -> list[str]:
    """A timed topic's channels and `TopicInfo` (its samples with a usable timestamp, the others
    skipped and counted); returns the damage to report (timestamps beyond int64 nanoseconds). Called
    under ``np.errstate(invalid="ignore")``: a float32 signalling NaN (a flipped bit) cast to float64
    becomes a quiet NaN, as `Channel` would make it."""
    lost = []
    records = getattr(data, "logscan_records", None)  # a clean read's records: read without pyulog's dict
    t_raw = records.stamps() if records is not None else None
    if t_raw is None:
        t_raw = _timestamps_u64(np.asarray(data.data["timestamp"]))
    zeros, beyond, in_order = _stamp_facts(t_raw)
    keep = None
    if zeros:  # PX4 publishes timestamp 0 for a message never really set
        source.skip(f"messages of {topic}", ZERO_TIMESTAMP_WHY, zeros)
    if beyond:  # its nanoseconds do not fit int64: a damaged timestamp
        source.skip(f"messages of {topic}", _BEYOND_WHY, beyond)
        lost.append(f"{beyond} message(s) of {topic} dropped: {_BEYOND_WHY}")
    if zeros or beyond:
        keep = (t_raw != 0) & (t_raw <= MAX_TIMESTAMP_US)
    t_ns = _nanoseconds(t_raw if keep is None else t_raw[keep])
    fields = _topic_channels(data, topic, t_ns, keep, wanted, source, channels, held)
    if keep is not None:  # in order once the dropped samples are out?
        in_order = bool((np.diff(t_ns) > 0).all())
    first_ns = last_ns = None
    if t_ns.size:
        first_ns, last_ns = (int(t_ns[0]), int(t_ns[-1])) if in_order else (int(t_ns.min()), int(t_ns.max()))
    source.topics[topic] = TopicInfo(
        name=topic,
        message_count=int(t_ns.size),
        encoding="ulog",
        schema=data.name,
        first_ns=first_ns,
        last_ns=last_ns,
        fields=fields,
    )
    if not in_order:
        report_time_order(t_ns, topic, source, "ULog topics are written in time order: the file may be damaged")
    return lost


def _stamp_facts(t_raw: np.ndarray) -> tuple[int, int, bool]:
    """`stamp_facts` of the uint64 timestamps ``t_raw``, `spill.CHUNK` at a time: a long log's
    records are on disk (`logscan.readers.spill`), their pages given back as they are read."""
    zeros = beyond = 0
    in_order = True
    for lo in range(0, t_raw.size, spill.CHUNK):
        chunk = t_raw[lo : lo + spill.CHUNK]
        found = stamp_facts(chunk, np.uint64(MAX_TIMESTAMP_US))
        zeros, beyond = zeros + found[0], beyond + found[1]
        in_order = in_order and found[2] and (lo == 0 or bool(chunk[0] > t_raw[lo - 1]))
        spill.passed(chunk.size * t_raw.strides[0])  # the records it ran through
    return zeros, beyond, in_order


def _nanoseconds(t_us: np.ndarray) -> np.ndarray:
    """int64 nanoseconds of the uint64 microseconds ``t_us`` (all below `MAX_TIMESTAMP_US`), in a
    new array of `spill.empty` (on disk within `spill.spilling`), `spill.CHUNK` at a time."""
    t_ns = spill.empty(t_us.size, np.int64)
    for lo in range(0, t_us.size, spill.CHUNK):
        chunk = t_ns[lo : lo + spill.CHUNK]
        chunk[:] = t_us[lo : lo + spill.CHUNK]  # numpy's unsafe cast, as astype: exact below 2**63
        chunk *= 1000
        spill.passed(chunk.size * (chunk.itemsize + t_us.strides[0]))  # written, and the records read
    return t_ns


def _has_timestamp(data) -> bool:
    records = getattr(data, "logscan_records", None)
    return "timestamp" in (records.layout.names if records is not None else data.data)


def _is_wanted(data, wanted: set[str] | None) -> bool:
    topic = f"{data.name}_{data.multi_id}"
    return topic_wanted(topic, wanted)  # "/" or not: topic_wanted ignores it


def _converting(chosen: Iterable, steps: StagedBytes) -> Iterator:
    """The topics ``chosen``, one at a time; once the caller has converted one (asks for the next),
    the bytes of the data messages converted so far out of those of all ``chosen`` are reported: a
    topic's message count times its message size (payload and message header)."""
    sizes = [_data_bytes(data) for data in chosen]
    total = max(1, sum(sizes))
    done = 0
    for data, size in zip(chosen, sizes, strict=True):
        yield data
        done += size
        steps.at(_CONVERTED, done / total)


def _data_bytes(data) -> int:
    """The bytes in the file of a pyulog topic's data messages."""
    records = getattr(data, "logscan_records", None)
    if records is not None:
        return records.bytes_in_file(_DATA_HEADER_BYTES)
    columns = data.data.values()
    count = len(next(iter(columns), ()))
    return count * (_DATA_HEADER_BYTES + sum(column.dtype.itemsize for column in columns))


def _topic_channels(
    data,
    topic: str,
    t_ns: np.ndarray,
    keep: np.ndarray | None,
    wanted: set[str] | None,
    source: SourceInfo,
    channels: dict,
    held: bool = False,
) -> list[str]:
    """The topic's numeric fields (its samples ``keep``, all when None, at ``t_ns``) into
    ``channels`` where wanted; returns every numeric field's name. Text (char) fields are skipped,
    once each. Each column is cast to float64 in one step (``astype`` of pyulog's strided column,
    or of its kept samples); ``held``: to float32 where that holds its type exactly (`read_ulog`)."""
    records = getattr(data, "logscan_records", None)  # a clean read: its records and their layout
    if records is not None:
        numeric, text = records.layout.lists()
        fields = list(numeric)
    else:
        fields, text = field_lists(
            [field.field_name for field in data.field_data], [field.type_str for field in data.field_data]
        )
    for name in text:
        source.skip(f"text field {data.name}.{name}", "char (string) field")
    prefix = f"/{topic}/"
    if not (wanted is None or topic in wanted or "/" + topic in wanted):
        fields_read = [name for name in fields if channel_wanted(prefix + name, topic, wanted)]
        read = set(fields_read)
        source.unread.extend(prefix + name for name in fields if name not in read)
    else:
        fields_read = fields
    if records is not None and keep is None and fields_read:  # one kernel call for all fields
        names = [prefix + name for name in fields_read]
        if held:
            rows = records.layout.held_rows(records.buffer, fields_read)
            channels.update((name, Channel.held(name, t_ns, row)) for name, row in zip(names, rows, strict=True))
        else:
            channels.update(zip(names, Channel.sharing_time(names, t_ns, records.rows(fields_read)), strict=True))
        return fields
    columns = data.data
    for name in fields_read:
        channel = prefix + name
        column = columns[name] if keep is None else columns[name][keep]
        if held and exact_in_float32(column.dtype):
            channels[channel] = Channel.held(channel, t_ns, column.astype(np.float32))
        else:
            channels[channel] = Channel(channel, t_ns, column.astype(np.float64, copy=keep is None))
    return fields


def _parse(path: str | os.PathLike, wanted: set[str] | None, on_framed: Callable[[], None] | None = None) -> tuple:
    """(pyulog ULog of the ``wanted`` messages, the truncation watch, pyulog's printed chatter);
    InputError when the file cannot be read, CorruptLogError when its header or definitions break.
    ``on_framed()``: called when a clean file has been framed (`parse_clean`)."""
    from pyulog.exceptions import ULogException

    chatter = io.StringIO()
    stat_input(path)  # a FIFO or device is refused before it is opened
    # an undamaged file: pyulog skips the data loop
    clean = parse_clean(str(path), message_filter(wanted), on_framed)
    if clean is not None:
        return clean
    ULog = _bounded_ulog_class()
    try:
        watch = _ReadWatch(str(path))
    except OSError as exc:
        raise input_error(exc, path) from None
    try:
        with contextlib.redirect_stdout(chatter), contextlib.redirect_stderr(chatter), watch:
            ulog = ULog(watch, message_filter(wanted), True)
    except OSError as exc:
        raise input_error(exc, path) from None
    except (
        ULogException,
        struct.error,
        ValueError,
        IndexError,
        KeyError,
        OverflowError,
        UnicodeDecodeError,
        TypeError,
        MemoryError,
        RecursionError,
    ) as exc:
        raise CorruptLogError(
            f"ULog cannot be parsed ({type(exc).__name__}: {exc})".rstrip(": )") + ")",
            path=str(path),
            hint="the file header or definitions section is damaged",
        ) from None
    return ulog, watch, chatter


def _timestamps_u64(raw: np.ndarray) -> np.ndarray:
    """A timestamp column as uint64 microseconds: a damaged format may type it otherwise; negative,
    fractional-overflow or non-finite values become 2**64-1 (beyond range: dropped and counted)."""
    if raw.dtype == np.uint64:
        return raw
    bad = np.uint64(2**64 - 1)
    if raw.dtype.kind == "i":
        return np.where(raw < 0, bad, raw.astype(np.uint64))
    values = raw.astype(np.float64)
    fits = np.isfinite(values) & (values >= 0) & (values <= MAX_TIMESTAMP_US)
    return np.where(fits, np.where(fits, values, 0).astype(np.uint64), bad)


def _fill_metadata(ulog, source: SourceInfo) -> None:
    """Info, parameters, dropouts and logged messages of the file into ``source.metadata``."""
    source.metadata["ulog.info"] = {str(k): _text(v) for k, v in ulog.msg_info_dict.items()}
    source.metadata["ulog.parameters"] = _texts(ulog.initial_parameters)
    if ulog.has_default_parameters:  # newer PX4: the system default of each parameter set away from it
        source.metadata["ulog.parameters_default"] = {
            str(k): _text(v) for k, v in ulog.get_default_parameters(0).items()
        }
    changed = ulog.changed_parameters
    if changed:
        source.metadata["ulog.parameters_changed"] = {
            f"{i:05d}": f"{t / 1e6:.6f} s {name} = {_text(value)}" for i, (t, name, value) in enumerate(changed)
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
        f"{i:05d}": f"{m.timestamp / 1e6:.6f} s [{m.log_level_str()}] {m.message}"
        for i, m in enumerate(messages[:_MAX_TEXT_MESSAGES])
    }
    if dropouts:
        source.warnings.append(f"{len(dropouts)} logging dropout(s), {dropout_ms} ms of data lost in total")


def _texts(values: dict) -> dict[str, str]:
    """``{str(key): _text(value)}``, the plain ints and floats of a thousand parameters inline."""
    return {str(k): repr(v) if type(v) is float else str(v) if type(v) is int else _text(v) for k, v in values.items()}


def _text(value) -> str:
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, float):
        return repr(value)
    return str(value)
