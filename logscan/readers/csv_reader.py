"""CSV input: one wide CSV file, or a directory of per-topic CSVs in PX4 `ulog2csv` layout.

Rules (documented in docs/inputs.md):

* Wide file: the time column is the leftmost column named ``time``, ``timestamp``, ``t`` or
  ``stamp`` (case-insensitive, a leading ``%`` ignored), optionally with a unit suffix such as
  ``time_s``, ``timestamp_us``, ``time [ms]``, ``stamp(ns)``, ``time_usec``. A suffix states the
  unit (a column whose numbers contradict it, e.g. ``time_s`` holding epoch nanoseconds, is an
  InputError naming the unit they fit: `check_stated_unit`); without one it is inferred from the
  median step and the magnitude (relative time since boot or epoch time) and the inference is
  reported as a warning and in ``source.time_unit``.
  ISO 8601 date-time text (``2024-03-18 14:49:10.126``) is read as epoch time under any time
  column name (it states its own unit: `logscan.readers.csv_dates`), cells without an offset as UTC.
  Every other numeric column becomes a channel ``/<column>`` (a column already starting with
  ``/`` keeps its name). An empty cell (or a missing-value word: ``NA``, ``null``, ``None``,
  ``N/A``...) means "no sample at this time": a channel holds the rows where its cell is filled,
  so the columns of a multi-rate wide file keep their own rates. Text columns are skipped and
  counted; a mostly-numeric column with a few non-numbers keeps the numbers and reads the rest as
  NaN (counted). Written ``nan`` / ``inf`` values are samples: they stay in the values, counted in
  a warning (alignment masks them). Rows without a valid time are dropped and counted. Timestamps are kept
  in file order: unsorted or duplicate times are reported with counts; alignment sorts and
  deduplicates them.
* Directory: a file whose stem is ``<log>_<topic>_<instance>`` and whose first column is
  ``timestamp`` (microseconds) is a ulog2csv topic ``<topic>_<instance>`` with channels
  ``/<topic>_<instance>/<field>`` (the naming of the ULog reader; rows with timestamp 0 are
  dropped as the ULog reader drops them). ``<log>`` is found as the
  directory's name, the stem of a ``.ulg`` beside the CSVs, or the longest ``_``-separated prefix
  all such files share. Any other ``.csv`` is read as a wide file with topic = its stem and
  channels ``/<stem>/<column>``. A directory without such per-topic pieces of one log (no
  ``<log>`` found) is a folder of separate logs, whatever its files' names say (per-topic wide
  files cannot be told from separate flights): reading it is an InputError saying to pass the
  files or make them one log (`logscan.fleet.expand_logs` expands it to one log per file).
* Sidecars beside the log (``run.csv`` or directory ``run/``): ``run.truth.json`` (ground truth)
  and ``run.profile.toml`` (the profile, as `logscan simulate` writes them).
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from logscan.errors import InputError, where_in_text
from logscan.input_files import MAX_PROFILE_SIDECAR_BYTES, MAX_TRUTH_BYTES, read_input_text
from logscan.log import Channel, Log, SourceInfo, TopicInfo
from logscan.readers.common import (
    ZERO_TIMESTAMP_WHY,
    StagedBytes,
    channel_wanted,
    report_time_order,
    topic_wanted,
)
from logscan.readers.csv_blocks import CsvColumns, _header_line, load_columns, sniff_delimiter
from logscan.readers.csv_dates import datetime_ns, naive_example
from logscan.readers.csv_decimal_comma import refuse_decimal_comma
from logscan.readers.csv_time import (
    MAX_TIME_NS,
    NS_PER_UNIT,
    TimeUnit,
    check_stated_unit,
    infer_time_unit,
    time_column_unit,
)

if TYPE_CHECKING:
    import pandas as pd

_ULOG2CSV_RE = re.compile(r"^(?P<rest>.+)_(?P<instance>\d+)$")
_MIXED_MIN_NUMERIC_FRACTION = 0.5  # a column with at least this share of numbers is numeric
# The NaN spellings, read as NaN samples (the words meaning "no sample": csv_blocks.MISSING_CELLS).
_NAN_WORDS = frozenset({"nan", "-nan", "+nan", "1.#ind", "-1.#ind", "1.#qnan", "-1.#qnan"})
# Shares of a wide CSV read's CPU time: the parse, then the columns turned into channels. A file of
# plain numbers (1e6 rows x 10 columns, 97 MB) spends about 80% in its one parse kernel; pandas'
# read of a file with a text column about 40% in its blocks and 60% in the columns (pd.to_numeric).
# The first is most logs.
_CSV_STAGE_SHARES = (0.8, 0.2)


def read_csv(
    path: str | os.PathLike, wanted: set[str] | None, *, progress: Callable[[int, int], None] | None = None
) -> Log:
    """Read one wide CSV file into a Log (see the module docstring for the rules). ``progress(done,
    file size)`` (`StagedBytes`): the bytes parsed (before and after a file of plain numbers, after
    each block pandas reads), then each column turned into channels, and (size, size) at the end."""
    source = SourceInfo(path=str(path), format="csv", time_source="csv column")
    steps = None if progress is None else StagedBytes(progress, os.path.getsize(path), _CSV_STAGE_SHARES)
    frame = load_columns(Path(path), None if steps is None else partial(steps.at_bytes, 0))
    on_column = None if steps is None else partial(steps.at, 1)
    channels = _frame_channels(frame, Path(path), source, wanted, topic=None, on_column=on_column)
    if steps is not None:
        steps.finish()
    return Log(
        channels=channels,
        source=source,
        truth=read_truth_sidecar(Path(path)),
        profile_text=read_profile_sidecar(Path(path)),
    )


def csv_files(directory: Path) -> list[Path]:
    """The ``.csv`` files of ``directory``, sorted."""
    return sorted(p for p in directory.iterdir() if p.suffix.lower() == ".csv" and p.is_file())


def csv_log_name(directory: Path, files: list[Path] | None = None) -> str:
    """The ``<log>`` name the directory's ulog2csv pieces share ("" when its CSVs are not the
    per-topic pieces of one log, e.g. a folder of separate wide-CSV flights)."""
    files = csv_files(directory) if files is None else files
    return _log_prefix(directory, [f.stem for f in _ulog2csv_files(files)])


def read_csv_dir(
    path: str | os.PathLike, wanted: set[str] | None, *, progress: Callable[[int, int], None] | None = None
) -> Log:
    """Read a directory of per-topic CSVs (PX4 ulog2csv layout, plus wide files beside them) into
    one Log; a directory of separate CSV logs is an InputError naming its files. ``progress(bytes
    read, bytes of the files to read)`` after each file read."""
    directory = Path(path)
    files = csv_files(directory)
    if not files:
        raise InputError("directory holds no .csv files", path=str(directory), hint="give an MCAP, ULog or CSV file")
    log_name = csv_log_name(directory, files)
    if not log_name:
        shown = ", ".join(f.name for f in files[:3]) + (f" and {len(files) - 3} more" if len(files) > 3 else "")
        raise InputError(
            f"the directory's {len(files)} CSV file(s) ({shown}) are separate logs: a folder is one log only in "
            "ulog2csv layout, <log>_<topic>_<n>.csv with a first column 'timestamp' in microseconds",
            path=str(directory),
            hint="pass one file (`logscan analyze DIR/` analyses each file as its own log); for one log of "
            "per-topic files, join them into one wide CSV or name and stamp them as ulog2csv does",
        )
    source = SourceInfo(path=str(directory), format="csv-dir", time_source="csv column")
    topics = _topic_names(files, log_name)
    channels: dict[str, Channel] = {}
    read = [f for f in files if topic_wanted(topics[f][0], wanted)]
    total, done = (sum(file.stat().st_size for file in read), 0) if progress is not None else (0, 0)
    for file in read:
        topic, px4 = topics[file]
        frame = load_columns(file)
        if px4 and "timestamp" not in frame.columns:
            px4 = False
        channels.update(_frame_channels(frame, file, source, wanted, topic=topic, stated_us=px4))
        if progress is not None:
            done += file.stat().st_size
            progress(done, total)
    units = sorted({t.schema for t in source.topics.values()})
    source.time_unit = "us" if units == ["ulog2csv"] else _dir_time_unit(source)
    return Log(
        channels=channels,
        source=source,
        truth=read_truth_sidecar(directory),
        profile_text=read_profile_sidecar(directory),
    )


def _dir_time_unit(source: SourceInfo) -> str:
    units = sorted(set(source.metadata.get("csv.time_units", {}).values()))
    return units[0] if len(units) == 1 else "mixed: " + ",".join(units)


def _topic_names(files: list[Path], prefix: str) -> dict[Path, tuple[str, bool]]:
    """Topic name of each file and whether it is in ulog2csv layout (pieces of log ``prefix``)."""
    layout = _ulog2csv_files(files)
    names: dict[Path, tuple[str, bool]] = {}
    for file in files:
        if file in layout and file.stem.startswith(prefix + "_"):
            names[file] = (file.stem[len(prefix) + 1 :], True)
        else:
            names[file] = (file.stem, file in layout)
    return names


def _ulog2csv_files(files: list[Path]) -> list[Path]:
    """Files named ``<...>_<n>.csv`` whose first column is ``timestamp`` (ulog2csv layout)."""
    return [f for f in files if _ULOG2CSV_RE.match(f.stem) and _first_column(f) == "timestamp"]


def _log_prefix(directory: Path, stems: list[str]) -> str:
    """The ``<log>`` part shared by ulog2csv file stems ``<log>_<topic>_<instance>``."""
    if not stems:
        return ""

    def fits(prefix: str) -> bool:
        return bool(prefix) and all(
            s.startswith(prefix + "_") and _ULOG2CSV_RE.match(s[len(prefix) + 1 :]) for s in stems
        )

    hints = [directory.resolve().name] + sorted(p.stem for p in directory.glob("*.ulg"))
    for hint in hints:
        if fits(hint):
            return hint
    if len(stems) < 2:
        return ""
    words = [s.split("_") for s in stems]
    common: list[str] = []
    for column in zip(*words):
        if len(set(column)) != 1:
            break
        common.append(column[0])
    while common and not fits("_".join(common)):
        common.pop()
    return "_".join(common)


def _first_column(file: Path) -> str:
    try:
        with open(file, encoding="utf-8-sig", errors="replace") as fh:
            header = fh.readline()
    except OSError:
        return ""
    return header.split(sniff_delimiter(header))[0].strip()


def _numeric_column(series: pd.Series) -> tuple[np.ndarray | None, int]:
    """(float64 values or None for a text column, count of non-numbers read as NaN)."""
    import pandas as pd

    if series.dtype == bool:
        return series.to_numpy(dtype=np.float64), 0
    if pd.api.types.is_numeric_dtype(series.dtype):
        return series.to_numpy(dtype=np.float64, na_value=np.nan), 0
    try:
        numbers = pd.to_numeric(series, errors="coerce")
    except OverflowError:  # integers beyond float range (pandas keeps them as Python ints): non-numbers
        numbers = pd.to_numeric(series.map(_float_or_none), errors="coerce")
    text = series.astype(str).str.strip()
    present = series.notna().to_numpy() & text.ne("").to_numpy()
    parsed = numbers.notna().to_numpy() | text.str.lower().isin(_NAN_WORDS).to_numpy()
    n_present = int(present.sum())
    if n_present == 0 or parsed.sum() < _MIXED_MIN_NUMERIC_FRACTION * n_present:
        return None, 0
    return numbers.to_numpy(dtype=np.float64, na_value=np.nan), int((present & ~parsed).sum())


def _float_or_none(value: object) -> object:
    """``value``, or None for an integer too large for a float64 (more than 309 digits)."""
    if isinstance(value, int) and not isinstance(value, bool):
        try:
            float(value)
        except OverflowError:
            return None
    return value


def _time_ns(series: pd.Series, unit: str) -> tuple[np.ndarray, np.ndarray]:
    """(int64 ns of the valid rows, bool mask of valid rows) for a time column in ``unit``."""
    import pandas as pd

    factor = NS_PER_UNIT[unit]
    limit = MAX_TIME_NS // factor  # a time whose ns do not fit int64 is not a valid time
    if pd.api.types.is_integer_dtype(series.dtype):
        valid = (series.notna() & (series <= limit) & (series >= -limit)).to_numpy(dtype=bool, na_value=False).copy()
        raw = series[valid].to_numpy(dtype=np.int64)
        return raw * factor, valid
    values, _ = _numeric_column(series)
    if values is None:
        values = np.full(len(series), np.nan)
    valid = (values < limit) & (values > -limit)  # |values| < limit, False for NaN and infinities too
    ns = values * factor if valid.all() else values[valid] * factor
    return np.round(ns, out=ns).astype(np.int64), valid


def _pick_time_column(frame: CsvColumns, path: Path) -> tuple[str, str | None]:
    for name in frame.columns:
        is_time, unit = time_column_unit(name)
        if is_time:
            return name, unit
    shown = ", ".join(repr(c) for c in list(frame.columns)[:12])
    more = f" and {len(frame.columns) - 12} more" if len(frame.columns) > 12 else ""
    raise InputError(
        f"no time column among {shown}{more}",
        path=str(path),
        hint="name it time, timestamp, t or stamp, optionally with a unit: time_s, timestamp_us",
    )


def _check_time_header(path: Path) -> None:
    """The InputError of `_pick_time_column` when the header line of the wide CSV ``path`` names
    no time column (read from the header alone, as the full read names the columns)."""
    import csv
    import io

    header = _header_line(path)
    names = [name.strip() for name in next(csv.reader(io.StringIO(header), delimiter=sniff_delimiter(header)), [])]
    _pick_time_column(CsvColumns(names, {}, 0, ""), path)


def _frame_channels(
    frame: CsvColumns,
    path: Path,
    source: SourceInfo,
    wanted: set[str] | None,
    *,
    topic: str | None,
    stated_us: bool = False,
    on_column: Callable[[float], None] | None = None,
) -> dict[str, Channel]:
    """Channels of one CSV table; fills the topic facts, skips and warnings into ``source``.
    ``on_column(share of the columns done)`` as each column is taken up."""
    label = topic or path.name
    frame, time_name, t_ns, valid = _table_times(frame, path, source, label, stated_us)
    channels, fields = _value_channels(frame, time_name, t_ns, valid, source, wanted, topic, path, on_column)
    source.topics[topic or path.stem] = TopicInfo(
        name=topic or path.stem,
        message_count=int(t_ns.size),
        encoding="csv",
        schema="ulog2csv" if stated_us else "wide",
        first_ns=int(t_ns.min()) if t_ns.size else None,
        last_ns=int(t_ns.max()) if t_ns.size else None,
        fields=fields,
    )
    return channels


def _table_times(
    frame: CsvColumns, path: Path, source: SourceInfo, label: str, stated_us: bool
) -> tuple[CsvColumns, str, np.ndarray, np.ndarray]:
    """(frame, time column, t_ns of the valid rows, valid rows): the table's times read, their
    unit and the rows skipped noted in ``source``."""
    frame, time_name, unit = _time_column(frame, path, source, label, stated_us)
    source.time_unit = unit.unit
    source.metadata.setdefault("csv.time_units", {})[label] = unit.unit
    source.metadata.setdefault("csv.time_columns", {})[label] = f"{time_name!r} in {unit.unit}: {unit.reason}"
    t_ns, valid = _time_ns(frame[time_name], unit.unit)
    frame.release(time_name)
    if frame.cut_row:
        source.skip(f"rows of {label}", "cut mid-row: the file ends inside it")
        source.partial = True
        source.partial_reason = "; ".join(filter(None, [source.partial_reason, f"{label}: {frame.cut_row}"]))
    if not valid.all():
        source.skip(f"rows of {label}", "time is empty, not a number or out of range", int((~valid).sum()))
    if stated_us and (t_ns == 0).any():  # the ULog reader's rule, so both readers agree
        nonzero = t_ns != 0
        source.skip(f"messages of {label}", ZERO_TIMESTAMP_WHY, int((~nonzero).sum()))
        valid[np.flatnonzero(valid)[~nonzero]] = False
        t_ns = t_ns[nonzero]
    report_time_order(t_ns, label, source)
    return frame, time_name, t_ns, valid


def _value_channels(
    frame: CsvColumns,
    time_name: str,
    t_ns: np.ndarray,
    valid: np.ndarray,
    source: SourceInfo,
    wanted: set[str] | None,
    topic: str | None,
    path: Path,
    on_column: Callable[[float], None] | None = None,
) -> tuple[dict[str, Channel], list[str]]:
    """(channels, numeric fields): every numeric column of the table, the wanted ones as channels
    on the valid rows (an empty cell is no sample); text columns, garbage cells and NaNs noted."""
    label = topic or path.name
    channels: dict[str, Channel] = {}
    fields: list[str] = []
    nan_counts: dict[str, int] = {}
    every_valid = bool(valid.all())
    for index, column in enumerate(frame.columns):
        if on_column is not None:
            on_column(index / len(frame.columns))
        if column == time_name:
            continue
        if topic is None:
            name = column if column.startswith("/") else "/" + column
        else:
            name = f"/{topic}/{column}"
        series = frame[column]
        values, garbage = _numeric_column(series)
        if values is None:
            refuse_decimal_comma(series, column, path)
            source.skip(f"text column {column!r} of {label}", "not numeric")
            continue
        fields.append(column)
        if garbage:
            source.skip(f"cells of column {column!r} of {label}", "not a number, read as NaN", garbage)
        if not channel_wanted(name, topic or path.stem, wanted):
            source.unread.append(name)
            continue
        # an empty cell is no sample, not a NaN
        filled, nan_free = (None, True) if column in frame.complete else _filled_cells(series, values)
        frame.release(column)
        if not every_valid:
            filled, values = None if filled is None else filled[valid], values[valid]
        every = filled is None or bool(filled.all())
        values = values if every else values[filled]
        n_nan = 0 if nan_free else int(np.count_nonzero(np.isnan(values)))
        if n_nan:
            nan_counts[name] = n_nan
        # a column filled on every row shares the table's times (one array, not one per column)
        channels[name] = Channel(name, t_ns if every else t_ns[filled], values)
    if nan_counts:
        listed = ", ".join(f"{k}: {v}" for k, v in list(nan_counts.items())[:5])
        more = f", ... ({len(nan_counts)} channels)" if len(nan_counts) > 5 else ""
        source.warnings.append(
            f"{label}: {sum(nan_counts.values())} NaN value(s) kept ({listed}{more}); alignment masks them"
        )
    return channels, fields


def _filled_cells(series: pd.Series, values: np.ndarray) -> tuple[np.ndarray | None, bool]:
    """(the rows whose cell is filled: ``series.notna()``, None when all are; whether ``values`` of
    those rows hold no NaN). A numpy float64 column is ``values`` itself, its empty cells its NaNs
    (what notna tests): one pass instead of notna's and then isnan's; an int64 column has no empty
    cell."""
    if series.dtype == np.int64:
        return None, True
    if series.dtype == np.float64:
        empty = np.isnan(values)
        return (~empty if empty.any() else None), True
    return series.notna().to_numpy(), False


def _time_column(
    frame: CsvColumns, path: Path, source: SourceInfo, label: str, stated_us: bool
) -> tuple[CsvColumns, str, TimeUnit]:
    """The table's time column and its unit (stated, or inferred with a warning into ``source``);
    the frame comes back with ISO 8601 date-times replaced by epoch nanoseconds."""
    if stated_us:
        return frame, "timestamp", TimeUnit("us", "stated", "ulog2csv layout: timestamp in microseconds")
    time_name, stated = _pick_time_column(frame, path)
    raw, _ = _numeric_column(frame[time_name])
    if raw is None:  # date-times state their unit: one in the name (timestamp_ns) does not apply
        return _date_time_column(frame, time_name, path, source, label), time_name, _DATE_TIMES
    if stated:
        check_stated_unit(raw, time_name, stated, path)
        return frame, time_name, TimeUnit(stated, "stated", f"unit stated by the column name {time_name!r}")
    unit = infer_time_unit(raw)
    source.warnings.append(
        f"{label}: time column {time_name!r} read as {unit.unit} inferred from {unit.reason}; "
        f"name it e.g. '{time_name}_{unit.unit}' to state the unit"
    )
    return frame, time_name, unit


_DATE_TIMES = TimeUnit("ns", "epoch", "ISO 8601 date-times (UTC unless an offset is given)")


def _date_time_column(frame: CsvColumns, time_name: str, path: Path, source: SourceInfo, label: str) -> CsvColumns:
    """The frame with its time column of date-time text replaced by epoch ns; an InputError when
    the column holds neither numbers nor date-times; a warning when cells give no UTC offset."""
    text = frame[time_name]
    dates = datetime_ns(text)
    if dates is None:
        refuse_decimal_comma(text, time_name, path)
        raise InputError(
            f"time column {time_name!r} holds no numbers or dates",
            path=str(path),
            hint="use seconds, or ISO 8601 date-times",
        )
    naive = naive_example(text, dates)
    if naive is not None:
        source.warnings.append(
            f"{label}: time column {time_name!r} holds date-times without a UTC offset (e.g. {naive!r}): read as "
            "UTC; write the offset (Z, +02:00) if they are local times"
        )
    return frame.assign(**{time_name: dates})


def _sidecar(path: Path, suffix: str) -> Path:
    """``run.csv`` -> ``run<suffix>``; a directory ``logs/run/`` -> ``logs/run<suffix>``."""
    return path.with_name(path.name + suffix) if path.is_dir() else path.with_suffix(suffix)


def read_truth_sidecar(path: Path) -> dict | None:
    """Ground truth from the ``<log>.truth.json`` sidecar, when present."""
    import json

    sidecar = _sidecar(path, ".truth.json")
    if not os.path.lexists(sidecar):
        return None
    # a regular file under a size limit: a FIFO or a device there is refused, never read
    text = read_input_text(sidecar, what="the ground-truth sidecar", limit=MAX_TRUTH_BYTES)
    try:
        return json.loads(text)
    except RecursionError:
        raise InputError("ground-truth sidecar is nested too deeply to be truth JSON", path=str(sidecar)) from None
    except ValueError as exc:
        raise InputError(f"ground-truth sidecar is not valid JSON{where_in_text(exc)}", path=str(sidecar)) from None


def read_profile_sidecar(path: Path) -> str | None:
    """Profile text from the ``<log>.profile.toml`` sidecar (written by `logscan simulate`). A wide
    CSV without one is first checked for a time column: a file that is no log says so before "no
    profile"."""
    sidecar = _sidecar(path, ".profile.toml")
    if not os.path.lexists(sidecar):
        if path.is_file():
            _check_time_header(path)
        return None
    # a regular file under a size limit: a FIFO or a device there is refused, never read
    return read_input_text(sidecar, what="the profile sidecar", limit=MAX_PROFILE_SIDECAR_BYTES)
