"""Numbers written with a decimal comma (``12,5``: a spreadsheet's export in a locale that writes
them so, mostly ';'-separated), refused with what to do.

logscan reads '.' as the decimal mark only, and guessing the mark per file is not safe: ``1,250``
is one and a quarter in one locale and a thousand two hundred and fifty in another. To the reader
such a column is text; a time column of it would be "no numbers or dates" and a value column
would be skipped as text without a word, so either says what it holds instead.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from logscan.errors import InputError

if TYPE_CHECKING:
    import pandas as pd

_DECIMAL_COMMA = r"[+-]?\d+,\d+(?:[eE][+-]?\d+)?"
_CELLS_LOOKED_AT = 1000  # the column's first filled cells: enough to tell, cheap on a long file
_MIN_FRACTION = 0.5  # of them numbers with a decimal comma, as a numeric column's share of numbers


def refuse_decimal_comma(series: pd.Series, column: str, path: Path) -> None:
    """InputError when the text column ``column`` holds numbers with a decimal comma (at least
    `_MIN_FRACTION` of its first filled cells), naming one and saying how to convert the file."""
    cells = series.dropna().head(_CELLS_LOOKED_AT).astype(str).str.strip()
    cells = cells[cells != ""]
    if cells.empty:
        return
    comma = cells.str.fullmatch(_DECIMAL_COMMA)
    if comma.sum() < _MIN_FRACTION * len(cells):
        return
    raise InputError(
        f"column {column!r} holds numbers with a decimal comma (e.g. {cells[comma].iloc[0]!r}): logscan reads "
        "'.' decimals only",
        path=str(path),
        hint="export the file with '.' decimals, or replace its decimal commas by '.'; in a ';'-separated file: "
        "sed 's/,/./g' run.csv > run_dot.csv",
    )
