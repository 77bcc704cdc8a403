"""ROS 2 CDR without per-message Python: a layout program built from the definition, run by a numba kernel.

Definitions made of primitives, strings and fixed-size arrays become a program of (kind, size,
type code, column) steps; ``cdr_fast`` runs it over every message of a channel in place and gives
the same columns as the ``mcap_ros2`` decoder (tests check they match exactly). A definition
without strings puts every value at the same offset in every message: its columns are read at
those offsets (`fixed_offsets`), a message only checked to be long enough, without stepping
through the program (2.5 times faster on 12-float messages in cache). Anything else
(variable-length arrays, unknown nested types) has no layout and goes through the decoder, and so
does a definition whose fixed-size arrays unroll to more than ``MAX_LAYOUT_STEPS`` steps (a schema
is data from the file: ``float64[100000000]`` must not allocate a column name per element).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from logscan.numba_cache import follow_dependencies
from logscan.readers.bits import float_of_bits, load_u64
from logscan.readers.flatten import FlatColumns, MessageBytes
from logscan.readers.mcap.scan_records import SchemaRec


class _Unsupported(Exception):
    """The ROS 2 definition has something the fast CDR path does not handle (it falls back)."""


# primitive -> (size in bytes, type code for the kernel); uint8/byte arrays decode as bytes
_CDR_PRIMITIVES = {
    "bool": (1, 1),
    "byte": (1, 1),
    "uint8": (1, 1),
    "char": (1, 2),
    "int8": (1, 2),
    "uint16": (2, 3),
    "int16": (2, 4),
    "uint32": (4, 5),
    "int32": (4, 6),
    "uint64": (8, 7),
    "int64": (8, 8),
    "float32": (4, 9),
    "float64": (8, 10),
}
_OP_VALUE, _OP_STRING, _OP_SKIP = 0, 1, 2
MAX_LAYOUT_STEPS = 65_536  # steps (columns, strings, skips) of one message's program


class CdrLayout(NamedTuple):
    """The program, one row per step (kind, size, type code, output column), and the column names."""

    kinds: np.ndarray
    sizes: np.ndarray
    codes: np.ndarray
    columns: np.ndarray
    paths: list[str]
    skipped: list[str]
    # no strings: each column's value offset after the 4-byte CDR header, and the bytes a message
    # needs there (`fixed_offsets`); None and -1 otherwise (the program is stepped through)
    offsets: np.ndarray | None = None
    need: int = -1


def cdr_layout(schema: SchemaRec) -> CdrLayout | None:
    """Program for messages whose fields are primitives, strings and fixed-size arrays, else None."""
    msgdefs = _message_definitions(schema)
    root = None if msgdefs is None else msgdefs.get(schema.name)
    if msgdefs is None or root is None:
        return None
    program = _Program(msgdefs)
    try:
        program.add(root, "", 0)
    except _Unsupported:
        return None
    table = np.array(program.steps, dtype=np.int64).reshape(-1, 4)
    kinds, sizes, codes, columns = (table[:, i].copy() for i in range(4))
    offsets, need = fixed_offsets(kinds.tolist(), sizes.tolist(), columns.tolist())
    return CdrLayout(kinds, sizes, codes, columns, program.paths, program.skipped, offsets, need)


def fixed_offsets(kinds: list[int], sizes: list[int], columns: list[int]) -> tuple[np.ndarray | None, int]:
    """Where `_cdr_run` finds each column's value (bytes after the 4-byte header) and the bytes a
    message needs after the header for the program to fit, when it has no string step (no offset
    then depends on the message); (None, -1) when it has one."""
    if _OP_STRING in kinds:
        return None, -1
    offsets = np.empty(sum(column >= 0 for column in columns), dtype=np.int64)
    pos = 0
    for kind, size, column in zip(kinds, sizes, columns):
        if kind == _OP_VALUE and size > 1 and pos % size:  # aligned to the value's own size
            pos += size - pos % size
        if column >= 0:
            offsets[column] = pos
        pos += size
    return offsets, pos


def _message_definitions(schema: SchemaRec) -> dict[str, Any] | None:
    """The schema's message definitions by full and short name (builtin Time and Duration
    included), else None (the schema does not parse, or mcap_ros2's private helpers moved)."""
    try:
        from mcap_ros2._dynamic import TimeDefinition, _for_each_msgdef
    except ImportError:  # the private helpers moved: the decoder path still works
        return None
    msgdefs: dict[str, Any] = {"builtin_interfaces/Time": TimeDefinition, "builtin_interfaces/Duration": TimeDefinition}

    def keep(full_name: str, short_name: str, msgdef: Any) -> None:
        msgdefs[full_name] = msgdef
        msgdefs[short_name] = msgdef

    try:
        _for_each_msgdef(schema.name, schema.data.decode("utf-8"), keep)
    except Exception:  # noqa: BLE001 - an unparsable schema is reported by the decoder path
        return None
    return msgdefs


class _Program:
    """A layout's steps (op, size, code, path index), built field by field; `_Unsupported` for a
    message the layout cannot describe."""

    def __init__(self, msgdefs: dict[str, Any]):
        self.msgdefs = msgdefs
        self.steps: list[tuple[int, int, int, int]] = []
        self.paths: list[str] = []
        self.skipped: list[str] = []

    def add(self, msgdef: Any, prefix: str, depth: int) -> None:
        """The steps of a message's fields, nested messages unrolled (names under ``prefix``)."""
        if depth > 32:
            raise _Unsupported("nesting too deep")
        if not msgdef.fields:
            self.steps.append((_OP_VALUE, 1, 1, -1))  # the placeholder uint8 of an empty message
        for fld in msgdef.fields:
            self.add_field(fld, prefix + fld.name, depth)

    def add_field(self, fld: Any, name: str, depth: int) -> None:
        """The steps of one field: fixed-size arrays unrolled, a byte array one skip step."""
        ftype = fld.type
        if ftype.is_array and not ftype.is_fixed_size_array():
            raise _Unsupported("variable-length array")
        count = ftype.array_size if ftype.is_array else None
        if ftype.type in ("uint8", "byte") and count is not None:
            self.steps.append((_OP_SKIP, count, 0, -1))  # one step, whatever the count
            self.skipped.append(name)
            return
        if len(self.steps) + (count or 1) > MAX_LAYOUT_STEPS:
            raise _Unsupported("fixed-size arrays unroll to too many steps")
        names = [name] if count is None else [f"{name}[{i}]" for i in range(count)]
        if not ftype.is_primitive_type():
            sub = self.msgdefs.get(f"{ftype.pkg_name}/{ftype.type}")
            if sub is None:
                raise _Unsupported("unknown nested type")
            for item in names:
                self.add(sub, item + ".", depth + 1)
        elif ftype.type == "string":
            for item in names:
                self.steps.append((_OP_STRING, 4, 0, -1))
                self.skipped.append(item)
        elif ftype.type in _CDR_PRIMITIVES:
            size, code = _CDR_PRIMITIVES[ftype.type]
            for item in names:
                self.steps.append((_OP_VALUE, size, code, len(self.paths)))
                self.paths.append(item)
        else:
            raise _Unsupported(f"type {ftype.type}")


@njit(cache=True, inline="always")
def le_value(buf, pos, size, code):  # pragma: no cover - compiled
    """The little-endian value of ``size`` bytes at ``buf[pos]`` as float64, by its type ``code``
    (`_CDR_PRIMITIVES`): float64 (10) and float32 (9) by their bits, unsigned (1, 3, 5, 7), int64
    (8), other signed sizes by two's complement. (The bits went through views of work arrays once:
    numba's array creation and view made `_cdr_fixed` take 0.95 s to compile cold, now 0.3 s.)"""
    raw = np.uint64(0)
    for i in range(size):
        raw |= np.uint64(buf[pos + i]) << np.uint64(8 * i)
    if code == 10:
        return float_of_bits(raw)
    if code == 9:
        return np.float64(float_of_bits(np.uint32(raw)))
    if code == 1 or code == 3 or code == 5 or code == 7:
        return np.float64(raw)
    if code == 8:
        return np.float64(np.int64(raw))
    bits = 8 * size  # signed 1, 2 or 4 bytes: two's complement
    signed = np.int64(raw)
    if signed >= (np.int64(1) << (bits - 1)):
        signed -= np.int64(1) << bits
    return np.float64(signed)


@njit(cache=True)
def _cdr_run(buf, starts, ends, kinds, sizes, codes, columns, out, row):  # pragma: no cover - compiled
    """Run the layout program over each message, its columns into ``out[:, row:]`` (one row per
    column); False when a message does not fit it."""
    for m in range(starts.size):
        start = starts[m]
        end = ends[m]
        if end - start < 4 or buf[start] != 0 or buf[start + 1] != 1:  # CDR little endian only
            return False
        base = start + 4
        pos = base
        for k in range(kinds.size):
            kind = kinds[k]
            size = sizes[k]
            if kind == 0:
                if size > 1 and (pos - base) % size != 0:  # align to the value's own size
                    pos += size - (pos - base) % size
                if pos + size > end:
                    return False
                value = le_value(buf, pos, size, codes[k])
                if columns[k] >= 0:
                    out[columns[k], row + m] = value
                pos += size
            elif kind == 1:
                if (pos - base) % 4 != 0:
                    pos += 4 - (pos - base) % 4
                if pos + 4 > end:
                    return False
                length = (
                    np.int64(buf[pos])
                    | (np.int64(buf[pos + 1]) << 8)
                    | (np.int64(buf[pos + 2]) << 16)
                    | (np.int64(buf[pos + 3]) << 24)
                )
                pos += 4 + length
                if pos > end:
                    return False
            else:
                pos += size
                if pos > end:
                    return False
    return True


@njit(cache=True)
def _cdr_fixed(buf, starts, ends, need, offsets, sizes, codes, out, row):  # pragma: no cover - compiled
    """`_cdr_run` for a program without strings (`fixed_offsets`): the same columns and the same
    verdict, each value read at its offset (``sizes``/``codes`` per column, not per step)."""
    for m in range(starts.size):
        start = starts[m]
        if ends[m] - start < 4 + need or buf[start] != 0 or buf[start + 1] != 1:  # short, or not CDR LE
            return False
        base = start + 4
        for c in range(offsets.size):
            pos = base + offsets[c]
            if codes[c] == 10:  # float64, the common case: one unaligned 8-byte load
                out[c, row + m] = float_of_bits(load_u64(buf, pos))
            else:
                out[c, row + m] = le_value(buf, pos, sizes[c], codes[c])
    return True


def cdr_fast(layout: CdrLayout, datas: MessageBytes | Sequence[bytes]) -> FlatColumns | None:
    """Columns of CDR messages decoded by the layout program, or None if one does not fit."""
    packed = datas if isinstance(datas, MessageBytes) else MessageBytes.from_list(datas)
    n = len(packed)
    out = np.empty((len(layout.paths), n), dtype=np.float64)  # one row per column: contiguous, no copy
    fixed = layout.offsets
    per_column = layout.columns >= 0
    sizes, codes = layout.sizes[per_column], layout.codes[per_column]  # step order is column order
    for (buf, starts, ends), row in zip(packed.parts, packed.first.tolist()):
        if fixed is not None:
            fits = _cdr_fixed(buf, starts, ends, layout.need, fixed, sizes, codes, out, row)
        else:
            fits = _cdr_run(buf, starts, ends, layout.kinds, layout.sizes, layout.codes, layout.columns, out, row)
        if not fits:
            return None
    flat = FlatColumns()
    every = np.arange(n, dtype=np.int64)
    for column, path in enumerate(layout.paths):
        flat.columns[path] = (every, out[column])
        flat.fields.append(path)
    for path in layout.skipped:
        flat.skipped[(path, "non-numeric")] = n
    return flat


follow_dependencies(__name__)  # the cached kernels are stamped with the intrinsics of `bits` too
