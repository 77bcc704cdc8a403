"""The CSV fast path (`csv_numeric`): a file of plain numbers gives pandas' columns bit for bit
(dtype, values, empty cells), and anything else is left to pandas, which judges it as before."""

from __future__ import annotations

import random
from pathlib import Path

import numpy as np
import pytest

from logscan.errors import InputError
from logscan.readers import csv_blocks
from logscan.readers.csv_numeric import numeric_columns
from logscan.readers.csv_reader import read_csv


def _pandas_columns(path: Path, monkeypatch) -> dict[str, np.ndarray]:
    with monkeypatch.context() as patch:
        patch.setattr(csv_blocks, "numeric_columns", lambda *args: None)
        frame = csv_blocks.load_columns(path)
    return {name: frame[name].to_numpy() for name in frame.columns}


def _fast_columns(path: Path) -> dict[str, np.ndarray] | None:
    header = csv_blocks._header_line(path)
    found = numeric_columns(path, header, csv_blocks.sniff_delimiter(header))
    return None if found is None else found.values


def _same(fast: dict[str, np.ndarray], slow: dict[str, np.ndarray]) -> None:
    assert list(fast) == list(slow)
    for name in slow:
        assert fast[name].dtype == slow[name].dtype, name
        assert fast[name].tobytes() == slow[name].tobytes(), name  # NaN == NaN, -0.0 != 0.0


def _cell(rng: random.Random, kind: str) -> str:
    if kind == "int":
        return str(rng.choice([0, 1, -7, 10**17, 2**63 - 1, -(2**63) + 1, rng.randint(-(10**12), 10**12)]))
    if rng.random() < 0.1:
        return rng.choice(["", " ", "0", "-5", "1e5", "1E-300", "2.5e+3", "123456789012345678"])
    value = rng.gauss(0, 10.0 ** rng.randint(-20, 12))  # up to 19 significant digits in any format
    return rng.choice([repr(value), f"{value:.6f}", f"{value:.3e}", f"{value:.17g}"])


@pytest.mark.parametrize("seed", range(12))
def test_plain_numbers_give_pandas_columns_bit_for_bit(tmp_path, monkeypatch, seed):
    rng = random.Random(seed)
    kinds = [rng.choice(["int", "float"]) for _ in range(rng.randint(1, 6))]
    sep = rng.choice([",", ";", "\t", "|"])
    names = ["time_s"] + [f"c{k}" for k in range(len(kinds))]
    lines = [sep.join(names)]
    for row in range(rng.randint(1, 400)):
        cells = [f"{row * 0.01:.2f}"] + [_cell(rng, kind) for kind in kinds]
        if rng.random() < 0.05:
            cells = [" " + cell + "  " for cell in cells]  # spaces around numbers
        lines.append(sep.join(cells))
    end = rng.choice(["\n", "\r\n"])
    text = end.join(lines) + rng.choice([end, ""])
    path = tmp_path / "plain.csv"
    path.write_bytes(("\ufeff" if seed % 5 == 0 else "").encode() + text.encode())
    fast = _fast_columns(path)
    assert fast is not None
    _same(fast, _pandas_columns(path, monkeypatch))


def test_integer_columns_stay_int64_and_turn_float_on_a_decimal_or_an_empty_cell(tmp_path, monkeypatch):
    path = tmp_path / "kinds.csv"
    path.write_text("t,a,b,c\n1,2,3,\n2,5,4.5,\n3,1700000000123456789,7,\n", encoding="utf-8")
    fast = _fast_columns(path)
    assert [fast[name].dtype.kind for name in "tabc"] == ["i", "i", "f", "f"]
    assert fast["a"][2] == 1700000000123456789  # exact: no trip through float64
    _same(fast, _pandas_columns(path, monkeypatch))


@pytest.mark.parametrize(
    "text",
    [
        't,"a"\n1,2\n',  # quotes
        "t,a\n1,NaN\n",  # a NaN spelling: a written value pandas reads
        "t,a\n1,NA\n",  # a missing-value word
        "t,a\n1,word\n",  # text
        "t,a\n1,-0\n",  # -0: 0 as an integer, -0.0 as a float
        "t,a\n1,01\n",  # a leading zero
        "t,a\n1,+1\n",
        "t,a\n1,9223372036854775808\n",  # beyond int64 (pandas: uint64)
        "t,a\n1,2\n\n3,4\n",  # a blank line
        "t,a\n1,2,3\n",  # more fields than the header
        "t,a\n1\n",  # fewer
        "t,a\n1,2\r3,4\n",  # a lone carriage return
        "t,t\n1,2\n",  # a repeated name (pandas renames it)
        "t,\n1,2\n",  # an empty name
        "t,a\n1,2.5x\n",
        "t,a\n1,\u00e92\n",  # not ASCII
        "t,a\n",  # no rows
    ],
)
def test_anything_else_is_left_to_pandas(tmp_path, text):
    path = tmp_path / "other.csv"
    path.write_text(text, encoding="utf-8")
    assert _fast_columns(path) is None


def test_bad_input_is_still_one_clear_error(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("time_s,a\n0.1,1,2\n0.2,3\n", encoding="utf-8")
    with pytest.raises(InputError, match="more fields than the header"):
        read_csv(path, None)
    path.write_text("time_s,a\n", encoding="utf-8")
    with pytest.raises(InputError, match="no data rows"):
        read_csv(path, None)


def test_a_read_through_the_fast_path_is_the_read_through_pandas(tmp_path, monkeypatch):
    path = tmp_path / "flight.csv"
    rows = [f"{k * 0.01:.2f},{np.sin(k):.9f},{'' if k % 3 else k},{k * 1000}" for k in range(500)]
    path.write_text("time_s,x,sparse,counter\n" + "\n".join(rows) + "\n", encoding="utf-8")
    assert _fast_columns(path) is not None
    fast = read_csv(path, None)
    monkeypatch.setattr(csv_blocks, "numeric_columns", lambda *args: None)
    slow = read_csv(path, None)
    assert list(fast.channels) == list(slow.channels)
    for name, channel in slow.channels.items():
        assert fast.channels[name].t.tobytes() == channel.t.tobytes()
        assert fast.channels[name].values.tobytes() == channel.values.tobytes()
    assert repr(fast.source) == repr(slow.source)


def test_rows_shorter_than_the_first_ones_are_all_read(tmp_path, monkeypatch):
    # the first 64 KiB set the guess of the row count (long rows: few); the rest are short rows
    path = tmp_path / "uneven.csv"
    long_rows = [f"{k},{k * 0.5}" + " " * 200 for k in range(400)]
    short_rows = [f"{k},{k}" for k in range(400, 20400)]
    path.write_text("t,a\n" + "\n".join(long_rows + short_rows) + "\n", encoding="utf-8")
    fast = _fast_columns(path)
    assert fast is not None and len(fast["t"]) == 20400
    _same(fast, _pandas_columns(path, monkeypatch))
