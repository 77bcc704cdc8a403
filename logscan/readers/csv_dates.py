"""Date-time text in a CSV time column: ISO 8601 read as epoch nanoseconds (`datetime_ns`), and
the cells that give no UTC offset, which are read as UTC (`naive_example`).

A date-time states its own unit, so a time column of date-times needs no unit in its name, and a
unit in its name (``timestamp_ns``) does not apply to it. What it may leave unstated is its time
zone: such cells are read as UTC, which the reader says, since local times would shift every
clock time the report prints.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

# A column with at least this share of date-times is a time column of date-times (the share
# csv_reader asks of a numeric column's numbers).
DATE_MIN_FRACTION = 0.5
# A time of day (h:mm, optionally :ss and a fraction) followed by its offset: Z or +hh[:mm]/-hh[:mm].
# The time of day is required: a bare date "2024-03-18" ends with "-18", which is no offset.
_OFFSET_RE = re.compile(r"\d:\d{2}(?::\d{2}(?:[.,]\d+)?)?\s*(?:[zZ]|[+-]\d{2}(?::?\d{2})?)$")


def datetime_ns(series: pd.Series) -> pd.Series | None:
    """Date-time text (``2024-03-18 14:49:10.126``, ISO 8601) as nullable int64 epoch ns; None when
    fewer than `DATE_MIN_FRACTION` of its filled cells are date-times."""
    import pandas as pd

    try:
        stamps = pd.to_datetime(series, errors="coerce", utc=True, format="ISO8601")
    except (ValueError, TypeError):
        return None
    valid = stamps.notna()
    if valid.sum() < DATE_MIN_FRACTION * max(1, int(series.notna().sum())):
        return None
    ns = stamps.dt.tz_convert(None).astype("datetime64[ns]").astype("int64", errors="ignore")
    return pd.Series(np.where(valid, ns, 0), index=series.index).astype("Int64").where(valid)


def naive_example(series: pd.Series, dates: pd.Series) -> str | None:
    """The first cell of ``series`` read as a date-time (``dates``: `datetime_ns` of it) that gives
    no UTC offset, or None when every one gives its offset."""
    text = series[dates.notna()].astype(str).str.strip()
    naive = ~text.str.contains(_OFFSET_RE, regex=True)
    return str(text[naive].iloc[0]) if naive.any() else None
