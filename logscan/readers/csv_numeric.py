"""The fast path of the CSV reader: a file of plain numbers parsed from its bytes by one numba kernel.

Most wide CSV logs are a header and rows of numbers. For them pandas' tokenizer (every field held as
text, then converted) is most of the read; here one kernel walks the mapped file once and writes
each cell straight into its column (`numeric_columns`), with pandas' results:

 - a column whose every cell is an integer (``-?[0-9]+`` within int64) is int64, as pandas
   infers it; any other number makes the column float64, and an empty cell (also one of spaces:
   ``skipinitialspace``) makes it float64 with NaN there. Integers already read are then
   converted in place: float(int) and the decimal text parsed as a float are both correctly rounded,
   so they are the same double;
 - decimals are read by `decimal_float` (correctly rounded; pandas 3's parser is fast_float,
   also correctly rounded);
 - spaces after a delimiter and after a number are skipped; rows end with ``\\n`` or ``\\r\\n``;
   the last row may lack its line break.

Anything else (quotes anywhere, a header pandas would rename: empty or repeated names, a word or
NaN spelling in a cell, a blank line, a row with more or fewer fields, an integer beyond int64 or
``-0``, a number the kernel declines, bytes that are not ASCII) returns None and the file is read
by pandas (`csv_blocks.load_columns`), which judges it as before: the fast path gives the same
columns or none.
"""

from __future__ import annotations

import mmap
import os
from pathlib import Path

import numpy as np
from numba import njit

from logscan.numba_cache import follow_dependencies
from logscan.readers.bits import load_u64, set_bits
from logscan.readers.decimal_float import number_value, scan_number

INT, FLOAT = 0, 1  # column kinds
OK, NOT_PLAIN, NO_ROOM = 0, 1, 2  # how the kernel stopped
_ROOM = 1.25  # rows allocated: this times the file's bytes over the mean row length of its first 64 KiB
_MAX_INT_DIGITS = 19  # and at most 2**63 - 1: an int64 (epoch nanoseconds have 19 digits)
_INT64_MAX = np.uint64(2**63 - 1)
_SPACE, _NL, _CR = 32, 10, 13


_LOW7 = np.uint64(0x7F7F7F7F7F7F7F7F)
_NEWLINES = np.uint64(0x0A0A0A0A0A0A0A0A)


@njit(cache=True)
def _count_lines(buf, start):  # pragma: no cover - numba kernel
    """Line breaks in buf[start:], eight bytes at a time (a byte is a line break when it XORs to 0:
    the top bit of ~((t & 0x7f) + 0x7f | t | 0x7f) is set exactly for the zero bytes of t)."""
    count = 0
    i = start
    while i + 8 <= buf.size:
        t = load_u64(buf, i) ^ _NEWLINES
        count += set_bits(~(((t & _LOW7) + _LOW7) | t | _LOW7))
        i += 8
    for j in range(i, buf.size):
        count += buf[j] == _NL
    return count


@njit(cache=True, inline="always")
def _to_float(cells, floats, c, rows):  # pragma: no cover - numba kernel
    """Column c's first ``rows`` integers turned into doubles, in place (same memory)."""
    for r in range(rows):
        floats[c, r] = np.float64(cells[c, r])


# Arguments: buf uint8 (the file), start: the first byte of the first data row, sep: the delimiter
# byte; cells int64 (k, rows) and floats float64 (k, rows): the same memory, out: column c's cells
# are cells[c] while kinds[c] == INT, floats[c] once FLOAT (NaN: empty); kinds int64 (k,) out.
@njit(cache=True)
def parse_numeric_rows(buf, start, sep, cells, floats, kinds):  # pragma: no cover - numba kernel
    """(rows parsed, OK), or (the row, NOT_PLAIN) where a cell or a row is not one the fast path
    takes, or (rows, NO_ROOM) when the file holds more rows than ``cells``."""
    k = kinds.size
    end = buf.size
    p = start
    row = 0
    while p < end:
        if row >= cells.shape[1]:
            return row, NO_ROOM
        if buf[p] == _NL or buf[p] == _CR:  # a blank line: pandas skips it
            return row, NOT_PLAIN
        for c in range(k):
            while p < end and buf[p] == _SPACE:
                p += 1
            if p >= end or buf[p] == sep or buf[p] == _NL or buf[p] == _CR:  # empty: no sample
                if kinds[c] == INT:
                    _to_float(cells, floats, c, row)
                    kinds[c] = FLOAT
                floats[c, row] = np.nan
            else:
                negative, w, e, digits, integer, q, fine = scan_number(buf, p, end)
                if not fine or (integer and (digits > _MAX_INT_DIGITS or w > _INT64_MAX or (negative and w == 0))):
                    return row, NOT_PLAIN  # not a number, a long integer or -0: pandas' reading
                if integer and kinds[c] == INT:
                    cells[c, row] = -np.int64(w) if negative else np.int64(w)
                else:
                    number, exact = number_value(negative, w, e, digits)
                    if not exact:
                        return row, NOT_PLAIN
                    if kinds[c] == INT:
                        _to_float(cells, floats, c, row)
                        kinds[c] = FLOAT
                    floats[c, row] = number
                p = q
                while p < end and buf[p] == _SPACE:
                    p += 1
            if c < k - 1:
                if p >= end or buf[p] != sep:
                    return row, NOT_PLAIN
                p += 1
            elif p < end:
                if buf[p] == _CR and p + 1 < end and buf[p + 1] == _NL:
                    p += 1
                if buf[p] != _NL:
                    return row, NOT_PLAIN
                p += 1
        row += 1
    return row, OK


def numeric_columns(path: Path, header: str, sep: str) -> dict[str, np.ndarray] | None:
    """Column name -> int64 or float64 values (NaN: an empty cell) when the file is a header and
    rows of plain numbers (see the module docstring), else None: pandas reads it."""
    names = [name.strip() for name in header.split(sep)]
    if '"' in header or "" in names or len(set(names)) != len(names) or not sep.isascii():
        return None
    try:
        with open(path, "rb") as fh:
            if os.fstat(fh.fileno()).st_size == 0:
                return None
            with _mapped(fh) as mapped:
                cells, kinds, rows = _parse(mapped, len(names), ord(sep))
    except (OSError, MemoryError):  # unreadable or too large to map: pandas says why
        return None
    if rows <= 0:
        return None  # not plain numbers (or no rows: pandas says so)
    floats = cells.view(np.float64)
    return {name: cells[c, :rows] if kinds[c] == INT else floats[c, :rows] for c, name in enumerate(names)}


def _mapped(fh) -> mmap.mmap:
    """The open file mapped read-only, its pages mapped in one call where the system can (Linux:
    a page fault per 4 KiB page costs more)."""
    populate = getattr(mmap, "MAP_POPULATE", 0)
    if populate:
        return mmap.mmap(fh.fileno(), 0, flags=mmap.MAP_SHARED | populate, prot=mmap.PROT_READ)
    return mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)


def _parse(mapped: mmap.mmap, columns: int, sep: int) -> tuple[np.ndarray, np.ndarray, int]:
    """(cells, kinds, rows) of `parse_numeric_rows` over the mapped file; no view of it is kept."""
    buf = np.frombuffer(mapped, dtype=np.uint8)
    try:
        line_end = np.flatnonzero(buf[: 1 << 20] == _NL)
        if not line_end.size:  # no data rows, or a header over 1 MiB: pandas says which
            return np.empty((columns, 0), dtype=np.int64), np.zeros(columns, dtype=np.int64), 0
        start = int(line_end[0]) + 1
        head_rows = int(np.count_nonzero(buf[start : start + (1 << 16)] == _NL))
        row_bytes = max(1.0, min(1 << 16, buf.size - start) / max(1, head_rows))
        rows = int(_ROOM * (buf.size - start) / row_bytes) + 16
        while True:  # rows counted exactly when the guess is short (a file of shorter rows later)
            try:
                cells = np.empty((columns, rows), dtype=np.int64)
            except MemoryError:  # the guess is over an address-space limit: count, else pandas
                exact = _count_lines(buf, start) + 1
                if exact >= rows:
                    raise
                rows = exact
                continue
            kinds = np.full(columns, INT, dtype=np.int64)
            rows, status = parse_numeric_rows(buf, start, sep, cells, cells.view(np.float64), kinds)
            if status != NO_ROOM:
                break
            rows = _count_lines(buf, start) + 1
        if status == NOT_PLAIN:
            rows = 0
    finally:
        del buf  # the mapping closes only with no array left on it
    return cells, kinds, rows


follow_dependencies(__name__)  # the cached kernel is stamped with decimal_float's parsing too
