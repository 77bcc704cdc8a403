"""pyulog's ULog object of a clean file, built without pyulog's message loop.

`ulog_framed` has already framed the file and kept every message but the data ('D') messages.
pyulog would read those kept messages one by one through its file object, parse every message
format field by field and flatten each subscribed format again for every instance. Here the kept
messages are walked from their known offsets: the formats ('F') are split with the same rules as
pyulog's ``MessageFormat`` and each format is flattened once per read (nested formats once each),
with pyulog's field names, timestamp position, sizes and numpy dtype. The rarer messages (info,
parameters, logged text, dropouts, flag bits) go through pyulog's own message classes, so their
values are pyulog's. The object is pyulog's (bounded) ULog class with the attributes its read sets.

Anything pyulog would print about or flag as corrupt (an unknown file version, a format that does
not parse, a message too short for its fields) returns None: the caller then reads the file the
careful way, which reports it.
"""

from __future__ import annotations

import functools
import re
import struct
import sys
from collections.abc import Callable

import numpy as np

from logscan.readers.ulog_columns import ColumnLayout, Records
from logscan.readers.ulog_damage import _MAX_FORMAT_NESTING, _MAX_MESSAGE_BYTES, _bounded_ulog_class

_HEADER_BYTES = 16
_LITTLE_ENDIAN = sys.byteorder == "little"  # the column kernel reads fields in native byte order
_FLAG_BITS_MAX = 8 + 8 + 3 * 8  # longer flag bits make pyulog print a warning
_CORRUPT = (IndexError, ValueError, KeyError, OverflowError, struct.error, TypeError, UnicodeDecodeError)


_FIELD = re.compile(r"(\w+)(?:\[(\d+)\])? (\w+);", re.ASCII)
_WELL_FORMED = re.compile(r"\w+:(?:\w+(?:\[\d+\])? \w+;)*", re.ASCII)


class _Format:
    """A message format as pyulog's ``MessageFormat`` holds it: a name and (type, array size, name)."""

    __slots__ = ("name", "fields")

    def __init__(self, name: str, fields: list[tuple[str, int, str]]) -> None:
        self.name = name
        self.fields = fields


def _parse_format(data: bytes) -> _Format:
    """pyulog's ``MessageFormat(data)``: the same splits, the same errors on a malformed field. A
    well-formed format (``name:type[n] field;...;`` of word characters) is split by one regular
    expression; any other goes through pyulog's steps."""
    text = str(data, "utf-8", "ignore")
    if _WELL_FORMED.fullmatch(text):
        name, _, body = text.partition(":")
        fields = [(kind, int(size) if size else 0, field) for kind, size, field in _FIELD.findall(body)]
        if all(size <= 0xFFFF for _, size, _ in fields):
            return _Format(name, fields)
    format_arr = text.split(":")
    fields = []
    for text in format_arr[1].split(";"):
        if not text:
            continue
        parts = text.split(" ")
        type_str, name = parts[0], parts[1]
        a_pos = type_str.find("[")
        if a_pos == -1:
            fields.append((type_str, 0, name))
            continue
        array_size = int(type_str[a_pos + 1 : type_str.find("]")])
        if array_size < 0 or array_size > 0xFFFF:
            raise ValueError(f"invalid array size: {array_size}")
        fields.append((type_str[:a_pos], array_size, name))
    return _Format(format_arr[0], fields)


class _Layouts:
    """Each subscribed format flattened once per read, as pyulog's ``_MessageAddLogged`` does it."""

    def __init__(self, formats: dict, unpack_types: dict, field_class: type) -> None:
        self.formats = formats
        self.unpack = unpack_types
        self.field_class = field_class  # pyulog's _FieldData
        self.little = {kind: np.dtype(spec[2]).newbyteorder("<") for kind, spec in unpack_types.items()}
        self.size = {kind: spec[1] for kind, spec in unpack_types.items()}
        self.nested: dict[str, tuple[list[str], list[str]]] = {}  # type name -> its flattened names, types
        self.measured: dict[str, tuple[int, int]] = {}  # type name -> (bytes, nesting height)
        self.of_name: dict[str, _Layout] = {}

    def _flat(self, type_name: str) -> tuple[list[str], list[str]]:
        """(field names, primitive types) of a format, arrays and nested formats unrolled."""
        flat = self.nested.get(type_name)
        if flat is not None:
            return flat
        names: list[str] = []
        kinds: list[str] = []
        for field_type, array_size, field_name in self.formats[type_name].fields:
            if field_type in self.unpack:
                if array_size > 0:
                    names.extend([f"{field_name}[{i}]" for i in range(array_size)])
                    kinds.extend([field_type] * array_size)
                else:
                    names.append(field_name)
                    kinds.append(field_type)
                continue
            inner_names, inner_kinds = self._flat(field_type)
            prefixes = [f"{field_name}[{i}]." for i in range(array_size)] if array_size > 0 else [field_name + "."]
            for prefix in prefixes:
                names.extend([prefix + name for name in inner_names])
                kinds.extend(inner_kinds)
        flat = self.nested[type_name] = (names, kinds)
        return flat

    def layout(self, name: str) -> _Layout:
        """What pyulog's ``_MessageAddLogged`` derives from message ``name``'s format."""
        known = self.of_name.get(name)
        if known is not None:
            return known
        self._measure(name, 0)  # refuses formats that contain themselves, nest too deep or are too large
        names, kinds = self._flat(name)
        end = len(names)
        while end and names[end - 1].startswith("_padding"):  # pyulog drops trailing padding
            end -= 1
        names, kinds = names[:end], kinds[:end]
        if "" in names or len(set(names)) != len(names):
            raise ValueError(f"format {name!r}: a field name empty or repeated")  # pyulog's dtype renames or fails
        sizes = list(map(self.size.__getitem__, kinds))
        # a field named just "timestamp" is a top-level one (nested and array names have a . or a [):
        # pyulog's index, unless a top-level array is called timestamp too (then the later one's)
        stamp = names.index("timestamp") if "timestamp" in names else -1
        timestamp_idx = stamp if stamp >= 0 and "timestamp[0]" not in names else self._timestamp_index(name)
        columns = ColumnLayout(names, kinds, sizes)
        known = _Layout(self, columns, timestamp_idx, sum(sizes[:stamp]) if stamp >= 0 else columns.width)
        self.of_name[name] = known
        return known

    def _measure(self, type_name: str, depth: int) -> tuple[int, int]:
        """(bytes, nesting height) of a format, each format measured once per read. Raises where
        `format_bytes` (the careful read's check) raises: a format that contains itself, an undefined
        type (KeyError), more than 64 KiB; and, a little more often than it, for nesting deeper than
        its limit on any path (it may pass a deep path through a format it measured on a shallow
        one): this read then returns None and the careful read decides."""
        known = self.measured.get(type_name)
        if known is not None:
            if known[0] < 0:
                raise ValueError(f"message format {type_name!r} contains itself")
            if depth + known[1] > _MAX_FORMAT_NESTING:
                raise ValueError(f"message formats nested more than {_MAX_FORMAT_NESTING} deep")
            return known
        if depth >= _MAX_FORMAT_NESTING:
            raise ValueError(f"message formats nested more than {_MAX_FORMAT_NESTING} deep")
        self.measured[type_name] = (-1, 0)  # being measured: met again below, it contains itself
        total, height = 0, 1
        for field_type, array_size, _ in self.formats[type_name].fields:
            size = self.size.get(field_type)
            if size is None:
                size, inner = self._measure(field_type, depth + 1)
                height = max(height, inner + 1)
            total += size * max(1, array_size)
            if total > _MAX_MESSAGE_BYTES:
                raise ValueError(f"message format {type_name!r} flattens to more than {_MAX_MESSAGE_BYTES} bytes")
        known = self.measured[type_name] = (total, height)
        return known

    def _timestamp_index(self, name: str) -> int:
        """pyulog's ``timestamp_idx``: the flattened index of the last element of a top-level
        primitive field called ``timestamp`` (-1 without one), padding included."""
        timestamp_idx = -1
        index = 0
        for field_type, array_size, field_name in self.formats[name].fields:
            if field_type in self.unpack:
                index += max(1, array_size)
                if field_name == "timestamp":
                    timestamp_idx = index - 1
            else:
                index += len(self._flat(field_type)[0]) * max(1, array_size)
        return timestamp_idx

    def dtype(self, columns: ColumnLayout) -> np.dtype:
        """pyulog's little-endian packed dtype of the fields (a names-and-formats dict builds it in
        a third of the time of pyulog's list of pairs; the names are neither empty nor repeated)."""
        return np.dtype({"names": columns.names, "formats": [self.little[kind] for kind in columns.kinds]})


class _Layout:
    """What pyulog's ``_MessageAddLogged`` derives from a format: the flattened fields, the
    timestamp's index and offset, the record size; its dtype and ``_FieldData`` list are made when
    first asked for (a clean read's reader asks for neither)."""

    def __init__(self, layouts: _Layouts, columns: ColumnLayout, timestamp_idx: int, timestamp_offset: int) -> None:
        self.layouts = layouts
        self.columns = columns
        self.timestamp_idx = timestamp_idx
        self.timestamp_offset = timestamp_offset
        self.max_data_size = columns.width

    @functools.cached_property
    def dtype(self) -> np.dtype:
        return self.layouts.dtype(self.columns)

    @functools.cached_property
    def field_data(self) -> list:
        return list(map(self.layouts.field_class, self.columns.names, self.columns.kinds))


class _InfoParser:
    """pyulog's ``_MessageInfo`` (info and parameter messages: a typed key and its value) as
    (type, key, value), without an object per message: a log holds a thousand parameters. Strings
    are decoded as pyulog's lenient parse does (UTF-8, undecodable bytes dropped)."""

    def __init__(self, unpack_types: dict) -> None:
        self.structs = {name: struct.Struct("<" + spec[0]) for name, spec in unpack_types.items()}

    def __call__(self, data: bytes) -> tuple:
        key_len = data[0]
        type_key = str(data[1 : 1 + key_len], "utf-8", "ignore").split(" ")
        kind, key = type_key[0], type_key[1]
        if kind.startswith("char["):
            return kind, key, str(data[1 + key_len :], "utf-8", "ignore")
        unpacker = self.structs.get(kind)
        if unpacker is None:  # an array or another type: pyulog keeps the bytes
            return kind, key, data[1 + key_len :]
        return kind, key, unpacker.unpack(data[1 + key_len :])[0]

    def multiple(self, ulog, data: bytes) -> None:
        """An info-multiple message into pyulog's ``_msg_info_multiple_dict``, as its
        ``_add_message_info_multiple`` puts it: a continued value extends the key's last list."""
        is_continued = data[0]
        kind, key, value = self(data[1:])
        lists = ulog._msg_info_multiple_dict.get(key)
        if lists is None:
            ulog._msg_info_multiple_dict[key] = [[value]]
            ulog._msg_info_multiple_dict_types[key] = kind
        elif is_continued:
            lists[-1].append(value)
        else:
            lists.append([value])


class _Subscription:
    """What pyulog's ``_MessageAddLogged`` holds of a subscription (its buffer filled by the caller)."""

    def __init__(self, data: bytes, name: str, layout: _Layout) -> None:
        self.layout = layout
        self.multi_id = data[0]
        self.msg_id = data[1] | (data[2] << 8)
        self.message_name = name
        self.timestamp_idx = layout.timestamp_idx
        self.timestamp_offset = layout.timestamp_offset
        self.max_data_size = layout.max_data_size
        self.buffer = bytearray()

    @property
    def dtype(self) -> np.dtype:
        return self.layout.dtype

    @property
    def field_data(self) -> list:
        return list(self.layout.field_data)


class _Topic:
    """pyulog's ``ULog.Data`` of a topic read: the same attributes; ``data`` (the dict of columns)
    and ``field_data`` are made when first read (`read_ulog` reads ``logscan_records`` instead)."""

    def __init__(self, subscription: _Subscription) -> None:
        self.multi_id = subscription.multi_id
        self.msg_id = subscription.msg_id
        self.name = subscription.message_name
        self.timestamp_idx = subscription.timestamp_idx
        self._subscription = subscription
        # the records and where each field lies (the column kernel reads native byte order)
        self.logscan_records = Records(subscription.layout.columns, subscription.buffer) if _LITTLE_ENDIAN else None

    def release(self) -> None:
        """Drop the records once the reader has its channels: a long log's topics are then not held
        twice, as records and as channels, while the next ones are converted."""
        self.logscan_records = None
        self._subscription.buffer = bytearray()
        self.__dict__.pop("data", None)  # pyulog's columns, when they were made: views of the records

    @functools.cached_property
    def field_data(self) -> list:
        return self._subscription.field_data

    @functools.cached_property
    def data(self) -> dict[str, np.ndarray]:
        records = np.frombuffer(self._subscription.buffer, dtype=self._subscription.dtype)
        return {name: records[name] for name in records.dtype.names}


def build_ulog(reduced: np.ndarray, sizes: np.ndarray, types: np.ndarray, names: set[str] | None, fill: Callable):
    """pyulog's ULog of ``reduced`` (the header and the kept messages of ``sizes`` and ``types``, in
    file order); ``fill(subscription)`` fills a read subscription's buffer. None when pyulog would
    print a warning or flag the file as corrupt."""
    ulog_class = _bounded_ulog_class()
    ulog = ulog_class(None, None, True)  # log_file None: pyulog's empty object, strings parsed leniently
    raw = reduced.tobytes()
    if raw[:7] != ulog_class.HEADER_BYTES or raw[7] > 1:
        return None
    ulog._file_version = raw[7]
    ulog._start_timestamp = ulog._last_timestamp = struct.unpack_from("<Q", raw, 8)[0]
    try:
        in_bulk = _initial_parameters(ulog, reduced, raw, sizes, types)
        subscriptions = _walk(ulog, raw, sizes.tolist(), types.tobytes(), names, in_bulk)
    except _CORRUPT:
        return None
    if subscriptions is None:
        return None
    for subscription in subscriptions:
        fill(subscription)
    # pyulog's order: it pops its subscriptions dict's items, then sorts them (a stable sort)
    data_list = [_Topic(subscription) for subscription in reversed(subscriptions) if len(subscription.buffer) > 0]
    data_list.sort(key=lambda ds: (ds.name, ds.multi_id))
    ulog._data_list = data_list
    return ulog


def _initial_parameters(ulog, reduced: np.ndarray, raw: bytes, sizes: np.ndarray, types: np.ndarray) -> bool:
    """The parameter ('P') messages of the definitions section (a thousand in a PX4 log) into
    ``ulog._initial_parameters`` at once (``raw``: ``reduced``'s bytes): their type-and-key strings
    decoded as one text, their values read as one array. False (nothing done: the walk reads them
    one by one) unless every key is plain ASCII text (pyulog decodes each string leniently) and
    every value an int32_t or a float. Raises struct.error where pyulog's read would: a value of the wrong size."""
    kinds_text = types.tobytes()
    split = min((at for at in map(kinds_text.find, (b"A", b"L", b"C")) if at >= 0), default=types.size)
    chosen = np.flatnonzero(types[:split] == ord("P"))
    if not chosen.size:
        return True
    payloads = _HEADER_BYTES + 3 + np.concatenate(([0], np.cumsum(sizes[: split - 1] + 3)))
    starts, sizes = payloads[chosen], sizes[chosen]
    key_lens = reduced[starts].astype(np.int64)
    text = b"\n".join([raw[s + 1 : s + 1 + k] for s, k in zip(starts.tolist(), key_lens.tolist())])
    if not text.isascii() or text.count(b"\n") != chosen.size - 1:
        return False
    typed = [item.split(" ") for item in text.decode("ascii").split("\n")]
    kinds, keys = [item[0] for item in typed], [item[1] for item in typed]  # IndexError as pyulog's
    if not set(kinds) <= {"int32_t", "float"}:
        return False
    if (sizes - 1 - key_lens != 4).any():
        raise struct.error("parameter value of the wrong size")
    words = reduced[(starts + 1 + key_lens)[:, None] + np.arange(4)]
    ints, floats = words.view("<i4")[:, 0].tolist(), words.view("<f4")[:, 0].tolist()
    values = [number if kind == "float" else integer for kind, integer, number in zip(kinds, ints, floats)]
    ulog._initial_parameters.update(zip(keys, values, strict=True))
    return True


def _walk(ulog, reduced: bytes, sizes: list[int], types: bytes, names: set[str] | None, in_bulk: bool) -> list | None:
    """The kept messages into ``ulog`` as pyulog's definitions and data loops would put them; the
    subscriptions of the topics read, in file order (None: something pyulog would print about).
    ``in_bulk``: the definitions' parameters are already read (`_initial_parameters`)."""
    info = _InfoParser(ulog._UNPACK_TYPES)
    layouts = _Layouts(ulog._message_formats, ulog._UNPACK_TYPES, ulog._FieldData)
    initial = ulog._initial_parameters
    subscriptions = []
    in_data = False
    end = _HEADER_BYTES
    for index, (size, kind) in enumerate(zip(sizes, types, strict=True)):
        start = end + 3
        end = start + size
        if kind == 80 and not in_data:  # P: most of the messages kept
            if not in_bulk:
                _, key, value = info(reduced[start:end])
                initial[key] = value
        elif kind == 77:  # M
            info.multiple(ulog, reduced[start:end])
        elif kind == 70:  # F
            message_format = _parse_format(reduced[start:end])
            ulog._message_formats[message_format.name] = message_format
        elif kind == 65:  # A: pyulog flattens every subscribed format, read or not
            in_data = True  # pyulog's definitions section ends at the first A, L or C
            data = reduced[start:end]
            name = str(data[3:], "utf-8", "ignore")
            subscription = _Subscription(data, name, layouts.layout(name))
            if names is None or name in names:
                subscriptions.append(subscription)
            else:
                ulog._filtered_message_ids.add(subscription.msg_id)
        elif kind == 66:  # B
            if index or size > _FLAG_BITS_MAX:
                return None
            _flag_bits(ulog, reduced[start:end], size)
        else:
            in_data = in_data or kind in b"LC"
            _other_message(ulog, kind, reduced[start:end], in_data, info)
    return subscriptions


def _flag_bits(ulog, data: bytes, size: int) -> None:
    header = ulog._MessageHeader()
    header.msg_size = size
    bits = ulog._MessageFlagBits(data, header)
    if bits.incompat_flags[0] & ~1 or any(bits.incompat_flags[1:]):
        raise ValueError("unknown incompatible flag")  # pyulog refuses the file: the careful read says so
    ulog._compat_flags, ulog._incompat_flags = bits.compat_flags, bits.incompat_flags
    ulog._appended_offsets = bits.appended_offsets


def _other_message(ulog, kind: int, data: bytes, in_data: bool, info: _InfoParser) -> None:
    """Info, parameter, default, logged text, dropout and sync messages, through pyulog's classes.
    A parameter change and a dropout get time 0 here: `ulog_framed` sets them from the data read."""
    if kind == 80:  # P
        _, key, value = info(data)
        if in_data:
            ulog._changed_parameters.append((0, key, value))
        else:
            ulog._initial_parameters[key] = value
    elif kind == 73:  # I
        value_type, key, value = info(data)
        ulog._msg_info_dict[key] = value
        ulog._msg_info_dict_types[key] = value_type
    elif kind == 81:  # Q: pyulog's _add_parameter_default: one dict per bit set, keyed (bit value - 1)
        default_types = data[0]
        _, key, value = info(data[1:])
        while default_types:
            bit = default_types & -default_types
            default_types ^= bit
            ulog._default_parameters.setdefault(bit - 1, {})[key] = value
    elif kind == 76:  # L
        ulog._logged_messages.append(ulog.MessageLogging(data, None))
    elif kind == 67:  # C
        tagged = ulog.MessageLoggingTagged(data, None)
        ulog._logged_messages_tagged.setdefault(tagged.tag, []).append(tagged)
    elif kind == 79:  # O
        ulog._dropouts.append(ulog.MessageDropout(data, None, 0))
    elif kind == 83:  # S
        ulog._sync_seq_cnt += 1
    else:
        raise ValueError(f"message type {kind} not expected in a clean file")
