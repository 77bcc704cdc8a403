"""Numeric flattening of decoded messages (JSON, ROS 1, ROS 2, protobuf) into named columns.

A decoded message is walked depth first. Numbers (and bools, as 0/1) become leaves named by their
dotted path: ``linear_acceleration.x``, ``position[2]``, ``poses[1].position.z``. Strings, bytes
(this includes ROS ``uint8[]`` fields, which the decoders return as ``bytes``) and other non-numeric
values are not channels; they are reported as skipped with a reason. A JSON ``null`` is skipped
the same way ("null value"), never turned into 0. An integer beyond float range (JSON numbers
have no size limit) is a non-number: NaN in its column, counted as skipped, as in the CSV reader.

Messages of one topic are grouped by their leaf layout, so a topic whose variable-length arrays
change length yields, for each index seen, a column with only the messages that had that index.
Each column comes back with the message indices it was present in, so the reader can attach
per-column timestamps.

``MessageBytes`` is the undecoded side of the same hand-over: a topic's message bytes as one uint8
buffer plus start/end offsets, which the bulk paths (ROS 2 CDR layout kernel, JSON template
match) read without a Python object per message; ``to_list`` makes per-message ``bytes`` only for
the generic decoders.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

_NON_NUMERIC = "non-numeric"
_NULL = "null value"
_UNSUPPORTED = "unsupported value type"
_HUGE_INTEGER = "integer beyond float range (read as NaN)"

_slots_by_type: dict[type, tuple[str, ...]] = {}


def _slots_of(kind: type) -> tuple[str, ...]:
    """All ``__slots__`` names of ``kind`` and its bases, in definition order (cached per type)."""
    slots = _slots_by_type.get(kind)
    if slots is None:
        names: list[str] = []
        for klass in reversed(kind.__mro__):
            declared = klass.__dict__.get("__slots__", ())
            if isinstance(declared, str):
                declared = (declared,)
            names.extend(name for name in declared if name not in names and not name.startswith("__"))
        slots = tuple(names)
        _slots_by_type[kind] = slots
    return slots


def _walk(value: Any, path: str, keys: list, values: list, skipped: list) -> None:
    """Append the numeric leaves under ``value`` (named ``path...``) to ``keys``/``values``."""
    kind = type(value)
    if kind is float or kind is int:
        keys.append(path)
        values.append(value)
    elif kind is dict:
        prefix = path + "." if path else ""
        for name, item in value.items():
            item_kind = type(item)
            if item_kind is float or item_kind is int:
                keys.append(prefix + name)
                values.append(item)
            else:
                _walk(item, prefix + name, keys, values, skipped)
    elif kind is list or kind is tuple:
        for index, item in enumerate(value):
            item_kind = type(item)
            if item_kind is float or item_kind is int:
                keys.append(f"{path}[{index}]")
                values.append(item)
            else:
                _walk(item, f"{path}[{index}]", keys, values, skipped)
    elif kind is bool:
        keys.append(path)
        values.append(1.0 if value else 0.0)
    elif kind is str or kind is bytes or kind is bytearray or kind is memoryview:
        skipped.append((path, _NON_NUMERIC))
    elif value is None:
        skipped.append((path, _NULL))
    elif isinstance(value, (bool, np.bool_)):
        keys.append(path)
        values.append(1.0 if value else 0.0)
    elif isinstance(value, (int, float, np.integer, np.floating)):
        keys.append(path)
        values.append(float(value))
    elif isinstance(value, np.ndarray):
        _walk(value.tolist(), path, keys, values, skipped)
    elif hasattr(value, "DESCRIPTOR") and hasattr(value, "ListFields"):
        _walk_protobuf(value, path, keys, values, skipped)
    elif _slots_of(kind):
        prefix = path + "." if path else ""
        for name in _slots_of(kind):
            item = getattr(value, name, None)
            item_kind = type(item)
            if item_kind is float or item_kind is int:
                keys.append(prefix + name)
                values.append(item)
            else:
                _walk(item, prefix + name, keys, values, skipped)
    elif isinstance(value, Sequence) or (hasattr(value, "__len__") and hasattr(value, "__getitem__")):
        # protobuf repeated containers and other sequence types
        _walk(list(value), path, keys, values, skipped)
    else:
        skipped.append((path, _UNSUPPORTED))


def _walk_protobuf(message: Any, path: str, keys: list, values: list, skipped: list) -> None:
    """Protobuf message: every declared field; unset singular sub-messages are absent, not zeros."""
    prefix = path + "." if path else ""
    for field in message.DESCRIPTOR.fields:
        name = prefix + field.name
        is_repeated = getattr(field, "is_repeated", None)
        if is_repeated is None:  # older protobuf
            is_repeated = field.label == field.LABEL_REPEATED
        if field.message_type is not None and not is_repeated:
            if not message.HasField(field.name):
                continue
        if field.message_type is not None and field.message_type.GetOptions().map_entry:
            skipped.append((name, "map field"))
            continue
        _walk(getattr(message, field.name), name, keys, values, skipped)


class FlatColumns:
    """Columns flattened from the messages of one topic.

    ``columns[path] = (message_index int64 array, values float64 array)``; ``skipped[(path, why)]``
    counts the messages in which ``path`` was not numeric; ``fields`` lists paths in first-seen order.
    """

    def __init__(self) -> None:
        self.columns: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.skipped: dict[tuple[str, str], int] = {}
        self.fields: list[str] = []


class MessageBytes:
    """Undecoded messages of one topic, in order, as (buffer, starts, ends) parts, never copied.

    Part ``p`` holds messages ``first[p] .. first[p + 1] - 1``: its message ``j`` is
    ``buf[starts[j]:ends[j]]`` (uint8 buffer, int64 offsets anywhere in it: a decompressed chunk,
    the whole file). Bulk kernels run once per part; ``to_list`` makes per-message ``bytes`` only
    for the decoders that need them.
    """

    __slots__ = ("parts", "first")

    def __init__(self, parts: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]]):
        merged: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        for buf, starts, ends in parts:
            if not starts.size:
                continue
            if merged and merged[-1][0] is buf:  # consecutive runs in one buffer: one part
                last = merged[-1]
                merged[-1] = (buf, np.concatenate([last[1], starts]), np.concatenate([last[2], ends]))
            else:
                merged.append((buf, np.asarray(starts, dtype=np.int64), np.asarray(ends, dtype=np.int64)))
        self.parts = merged
        self.first = np.concatenate([[0], np.cumsum([p[1].size for p in merged])]).astype(np.int64)

    def __len__(self) -> int:
        return int(self.first[-1])

    @classmethod
    def from_list(cls, datas: Sequence[bytes]) -> MessageBytes:
        """Pack a list of per-message bytes (one join)."""
        lengths = np.fromiter((len(d) for d in datas), dtype=np.int64, count=len(datas))
        ends = np.cumsum(lengths)
        return cls([(np.frombuffer(b"".join(datas), dtype=np.uint8), ends - lengths, ends)])

    def message(self, index: int) -> bytes:
        part = int(np.searchsorted(self.first, index, side="right")) - 1
        buf, starts, ends = self.parts[part]
        local = index - int(self.first[part])
        return buf[int(starts[local]) : int(ends[local])].tobytes()

    def total_bytes(self) -> int:
        return sum(int((ends - starts).sum()) for _buf, starts, ends in self.parts)

    def to_list(self, indices: Sequence[int] | np.ndarray | None = None) -> list[bytes]:
        """Per-message ``bytes`` (of ``indices``, default all, in that order)."""
        wanted = np.arange(len(self), dtype=np.int64) if indices is None else np.asarray(indices, dtype=np.int64)
        out: list[bytes] = [b""] * wanted.size
        part_of = np.searchsorted(self.first, wanted, side="right") - 1
        for part, (buf, starts, ends) in enumerate(self.parts):
            positions = np.flatnonzero(part_of == part)
            if not positions.size:
                continue
            local = wanted[positions] - self.first[part]
            view = memoryview(buf)  # no copy of the whole buffer (it may be the whole file)
            for position, s, e in zip(positions.tolist(), starts[local].tolist(), ends[local].tolist()):
                out[position] = view[s:e].tobytes()
        return out


class _Shape:
    """Code generation state for ``_compile_extractor``."""

    def __init__(self) -> None:
        self.checks: list[str] = []
        self.leaves: list[str] = []
        self.names: dict[str, Any] = {}

    def constant(self, value: Any) -> str:
        name = f"_c{len(self.names)}"
        self.names[name] = value
        return name


def _describe(value: Any, expr: str, shape: _Shape) -> bool:
    """Add the checks and leaf expressions that pin ``value``'s layout; False when unsupported."""
    kind = type(value)
    if kind is float or kind is int or kind is bool:
        shape.leaves.append(expr)
        return True
    if kind is str or kind is bytes or value is None:
        shape.checks.append(f"type({expr}) is {shape.constant(kind)}")
        return True
    if kind is dict or kind is list or kind is tuple:
        shape.checks.append(f"type({expr}) is {shape.constant(kind)} and len({expr}) == {len(value)}")
        items = value.items() if kind is dict else enumerate(value)
        for key, item in items:
            if kind is dict and type(key) is not str:
                return False
            if not _describe(item, f"{expr}[{key!r}]", shape):
                return False
        return True
    slots = _slots_of(kind) if not hasattr(value, "DESCRIPTOR") else ()
    if slots and all(name.isidentifier() for name in slots):
        shape.checks.append(f"type({expr}) is {shape.constant(kind)}")
        for name in slots:
            if not _describe(getattr(value, name, None), f"{expr}.{name}", shape):
                return False
        return True
    return False


def _compile_extractor(example: Any):
    """A function returning the numeric leaves of a message laid out exactly like ``example``
    (same keys, array lengths, types of non-numeric leaves), or None for any other message.

    Generated once per topic; turns the per-message walk into one expression.
    """
    shape = _Shape()
    if not _describe(example, "m", shape):
        return None
    condition = " and ".join(shape.checks) or "True"
    source = (
        "def extract(m):\n"
        "    try:\n"
        f"        if {condition}:\n"
        f"            return [{', '.join(shape.leaves)}]\n"
        "    except (KeyError, IndexError, TypeError, AttributeError):\n"
        "        pass\n"
        "    return None\n"
    )
    namespace = dict(shape.names)
    try:
        exec(compile(source, "<logscan flatten>", "exec"), namespace)  # noqa: S102 - generated code
    except (SyntaxError, RecursionError, MemoryError):
        return None
    return namespace["extract"]


def flatten_messages(messages: Sequence[Any]) -> FlatColumns:
    """Flatten decoded ``messages`` of one topic into per-path columns (see ``FlatColumns``).

    Fast path: messages laid out like the first one go through a generated extractor and one
    numpy conversion. The rest (and everything when the fast path does not apply) are walked one
    by one and grouped by their leaf layout, each group becoming one (n, k) float64 array.
    """
    groups: dict[tuple, tuple[list[int], list[list[Any]]]] = {}
    remaining: Sequence[int] | range = range(len(messages))
    entries = []
    if len(messages) > 1:
        fast = _fast_group(messages)
        if fast is not None:
            signature, indices, rows, remaining = fast
            entries.append((signature, indices, rows))
    add_to_groups(groups, [messages[index] for index in remaining], list(remaining))
    entries.extend((signature, indices, rows) for signature, (indices, rows) in groups.items())
    return columns_from_groups(entries)


def add_to_groups(groups: dict, messages: Sequence[Any], indices: Sequence[int]) -> None:
    """Walk ``messages`` (whose message numbers are ``indices``) into ``groups`` by leaf layout.

    ``groups[(keys, skipped)] = (message numbers, rows of leaf values)``.
    """
    for index, message in zip(indices, messages):
        keys: list[str] = []
        values: list[Any] = []
        skipped: list[tuple[str, str]] = []
        _walk(message, "", keys, values, skipped)
        signature = (tuple(keys), tuple(skipped))
        group = groups.get(signature)
        if group is None:
            group = groups[signature] = ([], [])
        group[0].append(index)
        group[1].append(values)


def layout_of(message: Any) -> tuple[tuple, list]:
    """(signature, leaf values) of one decoded message; the signature is its group key."""
    keys: list[str] = []
    values: list[Any] = []
    skipped: list[tuple[str, str]] = []
    _walk(message, "", keys, values, skipped)
    return (tuple(keys), tuple(skipped)), values


def _fast_group(messages: Sequence[Any]):
    """(signature, indices, value matrix, indices left for the slow path) or None."""
    keys: list[str] = []
    values: list[Any] = []
    skipped: list[tuple[str, str]] = []
    _walk(messages[0], "", keys, values, skipped)
    extract = _compile_extractor(messages[0])
    if extract is None or not keys:
        return None
    rows = [extract(m) for m in messages]
    misfits = [k for k, row in enumerate(rows) if row is None]
    if misfits:
        misfit_set = set(misfits)
        indices = [k for k in range(len(messages)) if k not in misfit_set]
        rows = [row for row in rows if row is not None]
    else:
        indices = list(range(len(messages)))
    if not rows:
        return None
    matrix = np.array(rows)  # dtype inferred: anything non-numeric (str, None, huge int) shows
    if matrix.dtype.kind not in "biuf" or matrix.shape != (len(rows), len(keys)):
        return None
    return (tuple(keys), tuple(skipped)), indices, matrix.astype(np.float64, copy=False), misfits


def _floats_of_huge(rows: Sequence[Sequence[Any]], keys: tuple[str, ...], skipped: dict) -> np.ndarray:
    """float64 values of ``rows`` where integers beyond float range are NaN and counted in ``skipped``
    under (path, _HUGE_INTEGER): a non-number, as the CSV reader reads such a cell. Only called
    when the one-step conversion overflowed, so the common path pays nothing."""
    out = np.empty((len(rows), len(keys)), dtype=np.float64)
    for r, row in enumerate(rows):
        for c, value in enumerate(row):
            try:
                out[r, c] = value
            except OverflowError:
                out[r, c] = np.nan
                item = (keys[c], _HUGE_INTEGER)
                skipped[item] = skipped.get(item, 0) + 1
    return out


def columns_from_groups(entries: Sequence[tuple[tuple, Any, Any]]) -> FlatColumns:
    """FlatColumns from (signature, message numbers, (n, k) values) entries; a signature may repeat."""
    out = FlatColumns()
    pieces: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    seen: set[str] = set()
    for (keys, skipped), indices, rows in entries:
        index_array = np.asarray(indices, dtype=np.int64)
        for item in skipped:
            out.skipped[item] = out.skipped.get(item, 0) + len(indices)
        if not keys:
            continue
        try:
            matrix = np.asarray(rows, dtype=np.float64).reshape(len(indices), len(keys))
        except OverflowError:  # a Python int beyond float range (JSON numbers have no size limit)
            matrix = _floats_of_huge(rows, keys, out.skipped).reshape(len(indices), len(keys))
        for column, key in enumerate(keys):
            if key not in seen:
                seen.add(key)
                out.fields.append(key)
            pieces.setdefault(key, []).append((index_array, matrix[:, column]))
    for key in out.fields:
        parts = pieces[key]
        if len(parts) == 1:
            out.columns[key] = (parts[0][0], np.ascontiguousarray(parts[0][1]))
            continue
        index_array = np.concatenate([p[0] for p in parts])
        value_array = np.concatenate([p[1] for p in parts])
        order = np.argsort(index_array, kind="stable")
        out.columns[key] = (index_array[order], value_array[order])
    return out
