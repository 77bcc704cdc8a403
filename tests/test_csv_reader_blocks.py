"""CSV read in blocks of rows: the same channels and facts whatever the block size (numbers, empty
cells, text and mixed columns, date-times crossing blocks), and a last row cut mid-row dropped and
counted as damage (the read is partial)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from logscan.readers import csv_blocks
from logscan.readers.csv_reader import read_csv

ROWS = 3000


def _wide_csv(path: Path, *, dates: bool = False) -> Path:
    lines = ["time,a,b,label,mixed" if dates else "time_s,a,b,label,mixed"]
    for i in range(ROWS):
        t = f"2024-03-18 14:{i // 600:02d}:{(i % 600) / 10:06.3f}" if dates else f"{i * 0.01:.2f}"
        b = "" if i % 7 == 0 else f"{i * 0.5:.1f}"  # empty cells: no sample
        mixed = "oops" if i == 2500 else f"{i}"  # one non-number late in the file
        lines.append(f"{t},{np.sin(i):.6f},{b},word{i % 3},{mixed}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _facts(log):
    channels = {name: (c.t.tobytes(), c.values.tobytes()) for name, c in log.channels.items()}  # NaN == NaN
    source = log.source
    return channels, repr(source.topics), repr(source.skipped), source.warnings, source.partial, source.time_unit


@pytest.mark.parametrize("dates", [False, True], ids=["seconds", "iso-dates"])
def test_small_blocks_read_the_same_log_as_one_block(tmp_path, monkeypatch, dates):
    path = _wide_csv(tmp_path / "wide.csv", dates=dates)
    whole = _facts(read_csv(path, None))
    monkeypatch.setattr(csv_blocks, "BLOCK_BYTES", 1)  # the 1000-row floor: 3 blocks
    assert csv_blocks._block_rows(path) == 1000
    assert _facts(read_csv(path, None)) == whole
    assert len(whole[0]["/b"][0]) == 8 * (ROWS - len(range(0, ROWS, 7)))


def test_a_last_row_cut_mid_row_is_dropped_and_makes_the_read_partial(tmp_path):
    path = _wide_csv(tmp_path / "cut.csv")
    text = path.read_text(encoding="utf-8")
    last = text.rstrip("\n").rsplit("\n", 1)[1]
    path.write_text(text.rstrip("\n")[: -(len(last) - last.index(",", last.index(",") + 1))], encoding="utf-8")
    log = read_csv(path, None)
    assert log.source.partial
    assert "cut.csv: the file ends inside its last row (2 of 5 fields, no line break)" in log.source.partial_reason
    assert len(log.channels["/a"]) == ROWS - 1  # the cut row is not read as a row of NaNs
    assert any(s.why.startswith("cut mid-row") for s in log.source.skipped)


def test_a_last_row_without_a_line_break_but_all_fields_is_read(tmp_path):
    path = _wide_csv(tmp_path / "nobreak.csv")
    path.write_text(path.read_text(encoding="utf-8").rstrip("\n"), encoding="utf-8")
    log = read_csv(path, None)
    assert not log.source.partial and len(log.channels["/a"]) == ROWS
