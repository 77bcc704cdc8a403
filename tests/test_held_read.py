"""A ULog read to be held for block mode's windows (`read_log`'s ``held``): the fields of a type
float32 holds exactly are float32, the others float64, every value the plain read's; widened, the
log is the plain read's; the float32 rows are converted a chunk of records at a time."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from logscan.pipeline.held_window import narrow, widened
from logscan.readers import read_log, ulog_columns
from logscan.readers.ulog_columns import TYPE_CODES, ColumnLayout

ULOG_DIR = Path(__file__).resolve().parents[2] / "shared" / "testdata" / "px4-ulog"
ULOGS = sorted(ULOG_DIR.glob("*.ulg")) if ULOG_DIR.is_dir() else []
_NARROW_KINDS = ("int8_t", "bool", "uint8_t", "int16_t", "uint16_t", "float")


def _kinds(path: Path) -> dict[str, str]:
    """Channel name -> its field's ULog type, from pyulog's own read."""
    from pyulog import ULog

    kinds = {}
    for data in ULog(str(path)).data_list:
        for field in data.field_data:
            kinds[f"/{data.name}_{data.multi_id}/{field.field_name}"] = field.type_str
    return kinds


@pytest.mark.testdata("px4-ulog")
@pytest.mark.parametrize("path", ULOGS, ids=lambda p: p.name)
def test_a_held_read_keeps_the_exact_types_as_float32_and_every_value(path):
    plain, held = read_log(path), read_log(path, held=True)
    kinds = _kinds(path)
    assert held.channels.keys() == plain.channels.keys()
    narrowed = 0
    for name, channel in held.channels.items():
        expected = np.float32 if kinds[name] in _NARROW_KINDS else np.float64
        assert channel.values.dtype == expected, name
        narrowed += expected is np.float32
        np.testing.assert_array_equal(channel.t, plain.channels[name].t)
        np.testing.assert_array_equal(channel.values.astype(np.float64), plain.channels[name].values, err_msg=name)
    assert narrowed > len(held.channels) // 2  # most of a PX4 log
    assert held.source.topics == plain.source.topics
    widened(held)
    for name, channel in held.channels.items():
        assert channel.values.dtype == np.float64
        np.testing.assert_array_equal(channel.values, plain.channels[name].values)


@pytest.mark.testdata("px4-ulog")
def test_narrowing_a_held_read_keeps_its_float32_arrays():
    held = read_log(ULOGS[0], held=True)
    before = {name: channel.values for name, channel in held.channels.items()}
    narrow(held)
    for name, channel in held.channels.items():
        if before[name].dtype == np.float32:
            assert channel.values is before[name]


def test_held_rows_a_chunk_at_a_time_are_the_rows(monkeypatch):
    kinds = ["uint64_t", "float", "int16_t", "double", "uint8_t", "int32_t"]
    dtypes = ["<u8", "<f4", "<i2", "<f8", "u1", "<i4"]
    names = [f"f{k}" for k in range(len(kinds))]
    rng = np.random.default_rng(3)
    count = 1000
    records = np.zeros(count, dtype=list(zip(names, dtypes, strict=True)))
    for name, dtype in zip(names, dtypes, strict=True):
        info = np.iinfo(dtype) if np.dtype(dtype).kind in "iu" else None
        records[name] = rng.integers(info.min, info.max, count, dtype=dtype) if info else rng.normal(size=count)
    records["f1"][7] = np.nan
    layout = ColumnLayout(names, kinds, [np.dtype(d).itemsize for d in dtypes])
    raw = records.view(np.uint8)
    monkeypatch.setattr(ulog_columns, "HELD_CHUNK", 64)  # 16 chunks, the last short
    rows = layout.held_rows(raw, names)
    whole = layout.rows(raw, names)
    for k, (kind, row) in enumerate(zip(kinds, rows, strict=True)):
        assert row.dtype == (np.float32 if TYPE_CODES[kind] in ulog_columns.EXACT_IN_FLOAT32 else np.float64)
        np.testing.assert_array_equal(row.astype(np.float64), whole[k])
