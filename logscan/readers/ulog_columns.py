"""A ULog topic's numeric fields as float64 rows, in one kernel call per topic.

A clean read (`ulog_framed`) has each subscription's records in one buffer of packed records of
``width`` bytes. Casting each field's strided column with ``astype`` costs about a microsecond per
field, most of a short log's channel building (2,000-2,500 fields over 100 topics); one kernel
call per topic writes every field read into a row of one (fields, samples) float64 array instead.
The casts are numpy's: each value read at its type and converted to float64 (float32 exactly, a
signalling NaN made quiet as numpy's cast makes it; 64-bit integers rounded to nearest).
"""

from __future__ import annotations

from itertools import accumulate

import numpy as np
from numba import njit

from logscan.numba_cache import follow_dependencies
from logscan.readers import spill

# pyulog's primitive types -> the kernel's type codes (bool and char are int8 in pyulog's dtype)
TYPE_CODES = {
    "int8_t": 0,
    "bool": 0,
    "char": 0,
    "uint8_t": 1,
    "int16_t": 2,
    "uint16_t": 3,
    "int32_t": 4,
    "uint32_t": 5,
    "int64_t": 6,
    "uint64_t": 7,
    "float": 8,
    "double": 9,
}
# each type code's numpy type (its size: the kernel's bytes per field)
_TYPES = (np.int8, np.uint8, np.int16, np.uint16, np.int32, np.uint32, np.int64, np.uint64, np.float32, np.float64)
_SIZES = np.array([np.dtype(kind).itemsize for kind in _TYPES], np.int64)


def exact_in_float32(dtype) -> bool:
    """Whether float32 holds every value of ``dtype`` exactly (8 and 16-bit integers, bool, float):
    a log held for block mode's windows keeps such fields as float32 (`ColumnLayout.held_rows`)."""
    return bool(np.can_cast(dtype, np.float32, "safe"))


EXACT_IN_FLOAT32 = frozenset(code for code, kind in enumerate(_TYPES) if exact_in_float32(kind))  # type codes
# Records converted at a time by `held_rows`: a long topic is never float64 whole (16 MiB of a
# 32-field topic's float64 at a time)
HELD_CHUNK = 1 << 16


class ColumnLayout:
    """A message format's flattened fields (names, pyulog's types, sizes) and where each lies in
    its packed record. What the reader asks of it is worked out on the first request."""

    __slots__ = ("names", "kinds", "sizes", "width", "_lists", "_columns", "_last")

    def __init__(self, names: list[str], kinds: list[str], sizes: list[int]) -> None:
        self.names, self.kinds, self.sizes = names, kinds, sizes
        self.width = sum(sizes)
        self._lists: tuple[list[str], list[str]] | None = None
        self._columns: tuple[dict[str, int], list[int], list[int]] | None = None  # index, offsets, codes
        self._last: tuple[list[str], np.ndarray, np.ndarray] | None = None  # the last field list asked for

    def lists(self) -> tuple[list[str], list[str]]:
        """(numeric field names, text fields): `field_lists`."""
        if self._lists is None:
            self._lists = field_lists(self.names, self.kinds)
        return self._lists

    def _places(self, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """(byte offsets in the record, type codes) of the fields ``names``, picked from lists of
        every field's made once per format."""
        if self._columns is None:  # lists, not arrays: a format has tens of fields, a read a hundred formats
            every = list(accumulate(self.sizes, initial=0))
            types = list(map(TYPE_CODES.__getitem__, self.kinds))
            self._columns = (dict(zip(self.names, range(len(self.names)))), every, types)
        index, every, types = self._columns
        picked = list(map(index.__getitem__, names))
        return np.array([every[i] for i in picked], np.int64), np.array([types[i] for i in picked], np.int64)

    def rows(self, records: np.ndarray, names: list[str]) -> np.ndarray:
        """(len(names), samples) float64: the fields ``names`` of the packed ``records`` (uint8)."""
        known = self._last
        if known is not None and known[0] == names:  # the instances of a topic read the same fields
            offsets, codes = known[1], known[2]
        else:
            offsets, codes = self._places(names)
            self._last = (names, offsets, codes)
        return _float_rows(records, records.size // self.width, self.width, offsets, codes)

    def held_rows(self, records: np.ndarray, names: list[str]) -> list[np.ndarray]:
        """The fields ``names`` of the packed ``records`` as rows, in order: float32 (rows of one
        array) where the field's type is one float32 holds exactly (`EXACT_IN_FLOAT32`), float64
        (rows of another) for the others; converted `HELD_CHUNK` records at a time into arrays of
        `logscan.readers.spill.empty` (on disk within `spill.spilling`), so a long topic is never held
        whole as float64 (a log held for block mode's windows)."""
        exact = [code in EXACT_IN_FLOAT32 for code in self._places(names)[1].tolist()]
        count = records.size // self.width
        rows: dict[str, np.ndarray] = {}
        for kind, chosen in (
            (np.float32, [n for n, e in zip(names, exact, strict=True) if e]),
            (np.float64, [n for n, e in zip(names, exact, strict=True) if not e]),
        ):
            if not chosen:
                continue
            out = spill.empty((len(chosen), count), kind)
            for lo in range(0, count, HELD_CHUNK):
                hi = min(lo + HELD_CHUNK, count)
                out[:, lo:hi] = self.rows(records[lo * self.width : hi * self.width], chosen)
                spill.passed((hi - lo) * (self.width + out.itemsize * len(chosen)))
            rows.update(zip(chosen, out, strict=True))
        return [rows[name] for name in names]


class Records:
    """A topic's data messages as packed records (uint8, ``layout.width`` bytes each)."""

    __slots__ = ("layout", "buffer", "count")

    def __init__(self, layout: ColumnLayout, buffer: np.ndarray) -> None:
        self.layout, self.buffer = layout, buffer
        self.count = buffer.size // layout.width

    def stamps(self) -> np.ndarray | None:
        """The ``timestamp`` column (a strided view), None unless the format has one of uint64."""
        layout = self.layout
        if "timestamp" not in layout.names or layout.kinds[at := layout.names.index("timestamp")] != "uint64_t":
            return None
        offset = sum(layout.sizes[:at])
        return np.ndarray((self.count,), dtype="<u8", buffer=self.buffer, offset=offset, strides=(layout.width,))

    def rows(self, names: list[str]) -> np.ndarray:
        return self.layout.rows(self.buffer, names)

    def bytes_in_file(self, header_bytes: int) -> int:
        """The bytes of the data messages in the file (``header_bytes`` before each payload)."""
        return self.count * (header_bytes + self.layout.width)


def field_lists(names: list[str], kinds: list[str]) -> tuple[list[str], list[str]]:
    """(numeric field names, text fields) of a format's flattened fields (names and pyulog's types),
    in order: the timestamp and padding are neither; a text (char) field is named once, without its
    index."""
    # the usual format: no text, no padding (one search of the names joined, not a test per name)
    if "char" not in kinds and "\n_padding" not in "\n" + "\n".join(names):
        return [name for name in names if name != "timestamp"], []
    fields = zip(names, kinds)
    named = [(name, kind) for name, kind in fields if name != "timestamp" and not name.startswith("_padding")]
    numeric = [name for name, kind in named if kind != "char"]
    text = [
        name.split("[", 1)[0]
        for name, kind in named
        if kind == "char" and ("[" not in name or name.endswith("[0]"))  # one per string field
    ]
    return numeric, text


@njit(cache=True)
def stamp_facts(stamps, beyond_us):  # pragma: no cover - numba kernel
    """(zero timestamps, timestamps over ``beyond_us``, strictly increasing?) of uint64 ``stamps``."""
    zeros = 0
    beyond = 0
    increasing = True
    for i in range(stamps.size):
        value = stamps[i]
        if value == 0:
            zeros += 1
        elif value > beyond_us:
            beyond += 1
        if i and value <= stamps[i - 1]:
            increasing = False
    return zeros, beyond, increasing


@njit(cache=True)
def _float_rows(records, n, width, offsets, codes):  # pragma: no cover - numba kernel
    """Row j: field j (at ``offsets[j]``, of type ``codes[j]``) of each of the ``n`` records."""
    out = np.empty((offsets.size, n), np.float64)
    packed = np.empty(n * 8, np.uint8)  # one field's bytes, record after record
    for j in range(offsets.size):
        code = codes[j]
        size = _SIZES[code]
        at = offsets[j]
        for i in range(n):
            start = i * width + at
            for b in range(size):
                packed[i * size + b] = records[start + b]
        row = out[j]
        if code == 0:
            _widen(packed.view(np.int8), row)
        elif code == 1:
            _widen(packed, row)
        elif code == 2:
            _widen(packed.view(np.int16), row)
        elif code == 3:
            _widen(packed.view(np.uint16), row)
        elif code == 4:
            _widen(packed.view(np.int32), row)
        elif code == 5:
            _widen(packed.view(np.uint32), row)
        elif code == 6:
            _widen(packed.view(np.int64), row)
        elif code == 7:
            _widen(packed.view(np.uint64), row)
        elif code == 8:
            _widen(packed.view(np.float32), row)
        else:
            _widen(packed.view(np.float64), row)
    return out


@njit(inline="always")
def _widen(values, row):  # pragma: no cover - numba kernel
    """The first ``row.size`` of ``values``, each converted to float64, into ``row``."""
    for i in range(row.size):
        row[i] = values[i]


follow_dependencies(__name__)
