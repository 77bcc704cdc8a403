"""A CSV file read in blocks of rows into per-column pieces (`CsvColumns`), so memory follows the
typed columns, not pandas' tokens of the whole file; and the check that the last row was not cut.

A file of plain numbers (`csv_numeric`: most logs) is parsed from its mapped bytes by a numba
kernel straight into typed columns, one piece each, with the columns pandas would give; every
other file is read by pandas as below.

pandas' C parser reading a whole file at once holds every field as text (about 3x the file); read
``BLOCK_BYTES`` of rows at a time, each block's columns are copied out as their own Series and the
block is dropped. A column is joined when it is asked for (`CsvColumns.__getitem__`) and its
pieces are released once it is turned into a channel (`CsvColumns.release`).

Last row: a file that does not end with a line break and whose last line has fewer fields than
the header was cut mid-row (a copy or a logger stopped): that row is dropped and said
(`CsvColumns.cut_row`), so the read is partial; pandas would fill the missing fields with NaN.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from logscan.errors import InputError
from logscan.readers.csv_numeric import numeric_columns

if TYPE_CHECKING:
    import pandas as pd

BLOCK_BYTES = 16 << 20  # bytes of rows parsed at a time
_TAIL_BYTES = 1 << 20  # the end of the file read for the last row
# Cells that mean "no sample here" (pandas' default missing-value words without its NaN spellings,
# which are written values).
MISSING_CELLS = ("", "NA", "N/A", "n/a", "NULL", "null", "None", "<NA>", "#N/A", "#N/A N/A", "#NA")


class CsvColumns:
    """The raw columns of one CSV file, as pieces (one per block) joined on demand."""

    def __init__(
        self,
        names: list[str],
        pieces: dict[str, list[pd.Series]],
        rows: int,
        cut_row: str,
        complete: frozenset[str] = frozenset(),
    ):
        self.columns = names
        self._pieces = pieces
        self._joined: dict[str, pd.Series] = {}
        self.rows = rows
        self.cut_row = cut_row  # why the last row was dropped ("" when it was not)
        # columns known to hold a number in every row (no empty cell, no NaN: the parse saw them)
        self.complete = set(complete)

    @property
    def empty(self) -> bool:
        return self.rows == 0 or not self.columns

    def __len__(self) -> int:
        return self.rows

    def __getitem__(self, name: str) -> pd.Series:
        joined = self._joined.get(name)
        if joined is None:
            import pandas as pd

            parts = self._pieces.pop(name)
            joined = parts[0] if len(parts) == 1 else pd.concat(parts, ignore_index=True)
            self._joined[name] = joined.reset_index(drop=True)
        return self._joined[name]

    def assign(self, **columns: pd.Series) -> CsvColumns:
        """Replace columns (in place) by these Series of the same length."""
        for name, series in columns.items():
            self._pieces.pop(name, None)
            self._joined[name] = series.reset_index(drop=True)
            self.complete.discard(name)
        return self

    def release(self, name: str) -> None:
        """Drop a column's data once it is turned into a channel."""
        self._pieces.pop(name, None)
        self._joined.pop(name, None)


def sniff_delimiter(header: str) -> str:
    counts = {sep: header.count(sep) for sep in (",", ";", "\t", "|")}
    best = max(counts, key=lambda sep: counts[sep])
    return best if counts[best] else ","


def load_columns(path: Path, on_read: Callable[[int], None] | None = None) -> CsvColumns:
    """The file's raw columns, read a block of rows at a time; one-line InputErrors for every
    unreadable case. ``on_read(bytes of the file read)``: before and after the parse of a file of
    plain numbers (one kernel call), or after each block pandas reads."""
    header = _header_line(path)
    sep = sniff_delimiter(header)
    if on_read is not None:
        on_read(0)
    fast = _plain_numbers(path, header, sep)
    if fast is not None:
        if on_read is not None:
            on_read(path.stat().st_size)
        return fast
    names, pieces, rows = _read_blocks(path, sep, on_read)
    if not names:  # a header and no rows
        names = [str(c).strip() for c in next(csv.reader(io.StringIO(header), delimiter=sep), [])]
    if rows == 0:
        raise InputError(f"CSV has a header ({len(names)} column(s)) but no data rows", path=str(path))
    cut_row = _cut_last_row(path, sep, len(names))
    if cut_row:
        rows -= 1
        for parts in pieces.values():
            parts[-1] = parts[-1].iloc[:-1]
    return CsvColumns(names, pieces, rows, cut_row)


def _read_blocks(
    path: Path, sep: str, on_read: Callable[[int], None] | None
) -> tuple[list[str], dict[str, list[pd.Series]], int]:
    """(column names, each column's pieces, rows) read by pandas a block of rows at a time."""
    import pandas as pd  # here, not at module import: reading an MCAP never loads pandas

    names: list[str] = []
    pieces: dict[str, list[pd.Series]] = {}
    rows = 0
    try:
        reader = pd.read_csv(
            path,
            sep=sep,
            encoding="utf-8-sig",
            skipinitialspace=True,
            keep_default_na=False,
            na_values=list(MISSING_CELLS),
            on_bad_lines="error",
            chunksize=_block_rows(path),
        )
        with reader:
            for block in reader:
                if not isinstance(block.index, pd.RangeIndex):  # pandas made the surplus fields an index
                    raise InputError(
                        "malformed CSV: data rows have more fields than the header",
                        path=str(path),
                        hint="every row needs as many fields as the header",
                    )
                if not names:
                    names = [str(c).strip() for c in block.columns]
                    pieces = {name: [] for name in names}
                for name, column in zip(names, block.columns, strict=True):
                    pieces[name].append(block[column].copy())  # its own data: the block goes
                rows += len(block)
                del block
                if on_read is not None:
                    _report_read(reader, on_read)
    except UnicodeDecodeError as exc:
        raise InputError(
            f"not UTF-8 text (bad byte at offset {exc.start} of a block)", path=str(path), hint="save the CSV as UTF-8"
        ) from None
    except pd.errors.EmptyDataError:
        raise InputError("CSV file is empty", path=str(path)) from None
    except (pd.errors.ParserError, csv.Error, ValueError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(
            f"malformed CSV: {first}", path=str(path), hint="every row needs as many fields as the header"
        ) from None
    return names, pieces, rows


def _report_read(reader, on_read: Callable[[int], None]) -> None:
    """``on_read`` of the bytes pandas has read of the file: the position of the binary file under
    its text handle (ahead of the rows parsed by at most its read buffer); no call when pandas'
    handle does not say (its ``handles`` are not public API)."""
    handle = getattr(getattr(reader, "handles", None), "handle", None)
    tell = getattr(getattr(handle, "buffer", handle), "tell", None)
    if tell is None:
        return
    try:
        position = int(tell())
    except (OSError, ValueError, TypeError):
        return
    on_read(position)


def _plain_numbers(path: Path, header: str, sep: str) -> CsvColumns | None:
    """The columns of a file of plain numbers (`csv_numeric`): pandas' columns without its tokens."""
    import pandas as pd

    found = numeric_columns(path, header, sep)
    if found is None:
        return None
    columns = found.values
    rows = len(next(iter(columns.values())))
    pieces = {name: [pd.Series(v, copy=False)] for name, v in columns.items()}
    return CsvColumns(list(columns), pieces, rows, "", found.complete)


def _header_line(path: Path) -> str:
    try:
        with open(path, encoding="utf-8-sig") as fh:
            header = fh.readline()
    except FileNotFoundError:
        raise InputError("no such file", path=str(path)) from None
    except UnicodeDecodeError as exc:
        raise InputError(
            f"not UTF-8 text (bad byte at {exc.start} of the first line)", path=str(path), hint="save the CSV as UTF-8"
        ) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=str(path)) from None
    if not header.strip():
        raise InputError(
            "CSV file is empty (no header line)",
            path=str(path),
            hint="a CSV needs a header with a time column and data rows",
        )
    return header


def _block_rows(path: Path) -> int:
    """Rows per block: ``BLOCK_BYTES`` by the mean line length of the file's first 64 KiB."""
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    lines = max(1, head.count(b"\n"))
    return max(1000, BLOCK_BYTES // max(1, len(head) // lines))


def _cut_last_row(path: Path, sep: str, fields: int) -> str:
    """Why the last row is dropped: the file ends inside it (no line break) and it has fewer
    fields than the header; "" otherwise."""
    with open(path, "rb") as fh:
        fh.seek(0, 2)
        size = fh.tell()
        fh.seek(max(0, size - _TAIL_BYTES))
        tail = fh.read()
    if not tail or tail.endswith((b"\n", b"\r")):
        return ""
    last = tail.rsplit(b"\n", 1)[-1].decode("utf-8", "replace")
    found = len(next(csv.reader(io.StringIO(last), delimiter=sep, skipinitialspace=True), []))
    if found >= fields:
        return ""
    return (
        f"the file ends inside its last row ({found} of {fields} fields, no line break): "
        "cut mid-row, the row was dropped"
    )
