"""The fast path of the CSV reader: a file of plain numbers parsed from its bytes by a numba kernel.

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
columns or none, so a bad row anywhere is pandas' one-line error with its line number.

A large file is parsed on every usable core (`row_blocks`, `THREAD_MIN_BYTES`): its rows are cut
after line breaks into one block per core, each parsed by the kernel (which runs without the GIL)
on a thread into its own rows of the columns, its own kinds; the blocks' rows are then moved
together and a column any block found a non-integer in becomes float64 (`_join_blocks`), the
columns of the single pass bit for bit. A block that is not plain numbers sends the whole file to
pandas, as the single pass does (a cut inside a quoted field is no matter: quotes are not plain).
"""

from __future__ import annotations

import mmap
import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numba import njit

from logscan.child_processes import usable_cores
from logscan.numba_cache import follow_dependencies
from logscan.readers.bits import byte_at, load_u64, set_bits, uncounted
from logscan.readers.decimal_float import number_value, scan_number

INT, FLOAT = 0, 1  # column kinds
OK, NOT_PLAIN, NO_ROOM = 0, 1, 2  # how the kernel stopped
_ROOM = 1.25  # rows allocated: this times the file's bytes over the mean row length of its first 64 KiB
_MAX_INT_DIGITS = 19  # and at most 2**63 - 1: an int64 (epoch nanoseconds have 19 digits)
_INT64_MAX = np.uint64(2**63 - 1)
_SPACE, _NL, _CR = 32, 10, 13
# The rows are cut into one block per usable core, but into blocks of at least this many bytes: a
# file of under twice this is parsed on this thread alone. Measured on this 2-core machine (the
# kernel parses about 2.7 ms per MB; numeric_columns of 1-127 MB files in 1 and 2 blocks, best and
# median of 60-100, at load 2-4: it was never idle): a thread's start and join cost about 80 us,
# the join of the blocks about 1 % of the parse, the kernels' CPU is the same in blocks; but the
# process took 5-9 % more CPU on 4-16 MB files in two blocks (the second thread waiting for a
# core, its pages) and 1-3 % at 127 MB. From 8 MiB (20 ms of parse) the second core's 10 ms are
# worth that.
THREAD_MIN_BYTES = 4 << 20
_MAX_MOVE_PIECES = 16  # blocks joined in at most this many copies per block (`_move_rows`)


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
def _to_float(cells, floats, c, first, row):  # pragma: no cover - numba kernel
    """Column c's integers of rows first..row-1 turned into doubles, in place (same memory)."""
    for r in range(first, row):
        floats[c, r] = np.float64(cells[c, r])


# Arguments: buf uint8 (the rows of one block: the file, or the part a thread parses), start: the
# first byte of its first data row, sep: the delimiter byte; cells int64 (k, n) and floats float64
# (k, n): the same memory, out: the block's rows go to cells[:, first:limit], column c's cells are
# cells[c] while kinds[c] == INT, floats[c] once FLOAT (NaN: empty); kinds int64 (k,) out, the
# block's own; empties int64 (k,) out, 1 where the block has an empty cell in column c. nogil: the
# blocks of one file are parsed on several threads (`_parse_blocks`).
@njit(cache=True, nogil=True)
def parse_numeric_rows(buf, start, sep, cells, floats, kinds, empties, first, limit):  # pragma: no cover - numba kernel
    """(rows parsed, OK), or (rows before the one, NOT_PLAIN) where a cell or a row is not one the
    fast path takes, or (rows, NO_ROOM) when the block holds more than ``limit - first`` rows."""
    buf = uncounted(buf)
    k = kinds.size
    # the row where each column turned FLOAT: its integers before are turned into doubles once the
    # block is parsed, not in the loop (where the conversion's setup cost every row 7 %)
    floated = np.full(k, first, dtype=np.int64)
    end = buf.size
    p = start
    row = first
    while p < end:
        if row >= limit:
            return row - first, NO_ROOM
        if byte_at(buf, p) == _NL or byte_at(buf, p) == _CR:  # a blank line: pandas skips it
            return row - first, NOT_PLAIN
        for c in range(k):
            while p < end and byte_at(buf, p) == _SPACE:
                p += 1
            # an empty cell: no sample
            if p >= end or byte_at(buf, p) == sep or byte_at(buf, p) == _NL or byte_at(buf, p) == _CR:
                if kinds[c] == INT:
                    floated[c] = row
                    kinds[c] = FLOAT
                floats[c, row] = np.nan
                empties[c] = 1
            else:
                negative, w, e, digits, integer, q, fine = scan_number(buf, p, end)
                if not fine or (integer and (digits > _MAX_INT_DIGITS or w > _INT64_MAX or (negative and w == 0))):
                    return row - first, NOT_PLAIN  # not a number, a long integer or -0: pandas' reading
                if integer and kinds[c] == INT:
                    cells[c, row] = -np.int64(w) if negative else np.int64(w)
                else:
                    number, exact = number_value(negative, w, e, digits)
                    if not exact:
                        return row - first, NOT_PLAIN
                    if kinds[c] == INT:
                        floated[c] = row
                        kinds[c] = FLOAT
                    floats[c, row] = number
                p = q
                while p < end and byte_at(buf, p) == _SPACE:
                    p += 1
            if c < k - 1:
                if p >= end or byte_at(buf, p) != sep:
                    return row - first, NOT_PLAIN
                p += 1
            elif p < end:
                if byte_at(buf, p) == _CR and p + 1 < end and byte_at(buf, p + 1) == _NL:
                    p += 1
                if byte_at(buf, p) != _NL:
                    return row - first, NOT_PLAIN
                p += 1
        row += 1
    for c in range(k):  # the integers before each column's first non-integer, as doubles
        _to_float(cells, floats, c, first, floated[c])
    return row - first, OK


class NumericColumns(NamedTuple):
    """The columns of a file of plain numbers."""

    values: dict[str, np.ndarray]  # column name -> int64 or float64 values (NaN: an empty cell)
    complete: frozenset[str]  # the columns with a number in every row: no empty cell, so no NaN


def numeric_columns(path: Path, header: str, sep: str) -> NumericColumns | None:
    """The file's columns when it is a header and rows of plain numbers (see the module docstring),
    else None: pandas reads it."""
    names = [name.strip() for name in header.split(sep)]
    if '"' in header or "" in names or len(set(names)) != len(names) or not sep.isascii():
        return None
    try:
        with open(path, "rb") as fh:
            if os.fstat(fh.fileno()).st_size == 0:
                return None
            with _mapped(fh) as mapped:
                cells, kinds, empties, rows = _parse(mapped, len(names), ord(sep))
    except (OSError, MemoryError):  # unreadable or too large to map: pandas says why
        return None
    if rows <= 0:
        return None  # not plain numbers (or no rows: pandas says so)
    floats = cells.view(np.float64)
    return NumericColumns(
        {name: cells[c, :rows] if kinds[c] == INT else floats[c, :rows] for c, name in enumerate(names)},
        frozenset(name for c, name in enumerate(names) if not empties[c]),
    )


def _mapped(fh) -> mmap.mmap:
    """The open file mapped read-only, its pages mapped in one call where the system can (Linux:
    a page fault per 4 KiB page costs more)."""
    populate = getattr(mmap, "MAP_POPULATE", 0)
    if populate:
        return mmap.mmap(fh.fileno(), 0, flags=mmap.MAP_SHARED | populate, prot=mmap.PROT_READ)
    return mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)


def _parse(mapped: mmap.mmap, columns: int, sep: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(cells, kinds, empties, rows) of `parse_numeric_rows` over the mapped file, a block of rows
    per thread (`row_blocks`); no view of the file is kept."""
    buf = np.frombuffer(mapped, dtype=np.uint8)
    try:
        line_end = np.flatnonzero(buf[: 1 << 20] == _NL)
        if not line_end.size:  # no data rows, or a header over 1 MiB: pandas says which
            nothing = np.zeros(columns, dtype=np.int64)
            return np.empty((columns, 0), dtype=np.int64), nothing, nothing, 0
        start = int(line_end[0]) + 1
        blocks = row_blocks(mapped, start, buf.size)
        head_rows = int(np.count_nonzero(buf[start : start + (1 << 16)] == _NL))
        row_bytes = max(1.0, min(1 << 16, buf.size - start) / max(1, head_rows))
        rooms = [int(_ROOM * (end - begin) / row_bytes) + 16 for begin, end in blocks]
        while True:  # rows counted exactly when the guess is short (a file of shorter rows later)
            try:
                cells = np.empty((columns, sum(rooms)), dtype=np.int64)
            except MemoryError:  # the guess is over an address-space limit: count, else pandas
                exact = _block_lines(buf, blocks)
                if sum(exact) >= sum(rooms):
                    raise
                rooms = exact
                continue
            kinds = np.full((len(blocks), columns), INT, dtype=np.int64)
            empties = np.zeros((len(blocks), columns), dtype=np.int64)
            firsts = [sum(rooms[:b]) for b in range(len(blocks))]
            parsed = _parse_blocks(buf, blocks, sep, cells, kinds, empties, firsts, rooms)
            if all(status != NO_ROOM for _rows, status in parsed):
                break
            rooms = _block_lines(buf, blocks)
        if any(status == NOT_PLAIN for _rows, status in parsed):
            return cells, kinds[0], empties[0], 0
        column_kinds, rows = _join_blocks(cells, kinds, firsts, [rows for rows, _status in parsed])
    finally:
        del buf  # the mapping closes only with no array left on it
    return cells, column_kinds, empties.max(axis=0), rows


def row_blocks(mapped: mmap.mmap | bytes, start: int, end: int) -> list[tuple[int, int]]:
    """(first byte, end) of each block of rows of mapped[start:end], one per usable core but each of
    at least `THREAD_MIN_BYTES`: cut just after a line break, so every block starts a row (a cut inside
    a quoted field or any row the fast path does not take is no matter: such a block stops NOT_PLAIN
    and the whole file goes to pandas)."""
    count = max(1, min(usable_cores(), (end - start) // THREAD_MIN_BYTES))
    cuts = [start]
    for block in range(1, count):
        line_break = mapped.find(b"\n", max(start + (end - start) * block // count, cuts[-1]), end)
        if line_break < 0 or line_break + 1 >= end:
            break
        cuts.append(line_break + 1)
    cuts.append(end)
    return [(begin, stop) for begin, stop in zip(cuts, cuts[1:], strict=False) if stop > begin] or [(start, end)]


def _block_lines(buf: np.ndarray, blocks: list[tuple[int, int]]) -> list[int]:
    """The most rows each block can hold: its line breaks, one more for a last row without one."""
    return [_count_lines(buf[begin:end], 0) + int(buf[end - 1] != _NL) for begin, end in blocks]


def _parse_blocks(
    buf: np.ndarray,
    blocks: list[tuple[int, int]],
    sep: int,
    cells: np.ndarray,
    kinds: np.ndarray,
    empties: np.ndarray,
    firsts: list[int],
    rooms: list[int],
) -> list[tuple[int, int]]:
    """(rows, status) of `parse_numeric_rows` of each block into its rows firsts[b] ..
    firsts[b] + rooms[b] of ``cells``, its kinds[b] and empties[b]: the first on this thread, each
    other on a thread of its own (the kernel runs without the GIL)."""
    floats = cells.view(np.float64)

    def parse(b: int) -> tuple[int, int]:
        begin, end = blocks[b]
        last = firsts[b] + rooms[b]
        return parse_numeric_rows(buf[begin:end], 0, sep, cells, floats, kinds[b], empties[b], firsts[b], last)

    if len(blocks) == 1:
        return [parse(0)]
    with ThreadPoolExecutor(len(blocks) - 1, thread_name_prefix="logscan-csv") as pool:
        later = [pool.submit(parse, b) for b in range(1, len(blocks))]
        return [parse(0)] + [future.result() for future in later]


def _join_blocks(cells: np.ndarray, kinds: np.ndarray, firsts: list[int], counts: list[int]) -> tuple[np.ndarray, int]:
    """(each column's kind, rows): the blocks' rows moved together at the start of ``cells``, a
    column FLOAT when any block found a non-integer in it (the integers of the other blocks turned
    into doubles, as the kernel turns those before its first decimal: the same correctly rounded
    double as the text parsed as a float)."""
    column_kinds = kinds.max(axis=0)  # FLOAT > INT
    floats = cells.view(np.float64)
    for b, (first, count) in enumerate(zip(firsts, counts, strict=True)):
        for c in np.flatnonzero(kinds[b] != column_kinds):
            floats[c, first : first + count] = cells[c, first : first + count].astype(np.float64)
    rows = 0
    for first, count in zip(firsts, counts, strict=True):
        _move_rows(cells, first, rows, count)
        rows += count
    return column_kinds, rows


def _move_rows(cells: np.ndarray, source: int, to: int, count: int) -> None:
    """cells[:, to : to + count] = cells[:, source : source + count], to <= source, the bits as they
    are; a column at a time in pieces of at most ``source - to`` rows, which do not overlap where
    they go (numpy copies a source whose bounds overlap its destination whole first: a 2-D piece's
    always do)."""
    step = source - to
    if step == 0 or count == 0:
        return
    pieces = range(0, count, step) if step * _MAX_MOVE_PIECES >= count else None
    for c in range(cells.shape[0]):
        if pieces is None:  # a narrow gap: through a copy
            cells[c, to : to + count] = cells[c, source : source + count].copy()
            continue
        for at in pieces:
            piece = min(step, count - at)
            cells[c, to + at : to + at + piece] = cells[c, source + at : source + at + piece]


follow_dependencies(__name__)  # the cached kernel is stamped with decimal_float's parsing too
