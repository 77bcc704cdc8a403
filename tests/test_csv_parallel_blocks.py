"""A file of plain numbers parsed in blocks of rows on several threads (`csv_numeric.row_blocks`)
gives the columns of the single-threaded parse bit for bit (dtype, values, which columns are
complete); a cell or a row the fast path declines in a later block sends the whole file to pandas,
which judges it as before: the same message, with the same line number."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.errors import InputError
from logscan.readers import csv_blocks, csv_numeric
from logscan.readers.csv_reader import read_csv


def _blocks(patch: pytest.MonkeyPatch, cores: int) -> list[list[tuple[int, int]]]:
    """Make the parse cut every file into ``cores`` blocks (1: the single-threaded path); the list
    that fills with the blocks of each parse."""
    patch.setattr(csv_numeric, "THREAD_MIN_BYTES", 1 if cores > 1 else 1 << 62)
    patch.setattr(csv_numeric, "usable_cores", lambda: cores)
    seen: list[list[tuple[int, int]]] = []
    cut = csv_numeric.row_blocks

    def recorded(*args):
        seen.append(cut(*args))
        return seen[-1]

    patch.setattr(csv_numeric, "row_blocks", recorded)
    return seen


def _parse(path: Path, cores: int) -> tuple[csv_numeric.NumericColumns | None, int]:
    """(`numeric_columns` of the file, the blocks it was cut into) with ``cores`` usable cores."""
    header = csv_blocks._header_line(path)
    with pytest.MonkeyPatch.context() as patch:
        seen = _blocks(patch, cores)
        found = csv_numeric.numeric_columns(path, header, csv_blocks.sniff_delimiter(header))
    return found, len(seen[-1]) if seen else 0


def _pandas_columns(path: Path) -> dict[str, np.ndarray]:
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(csv_blocks, "numeric_columns", lambda *args: None)
        frame = csv_blocks.load_columns(path)
    return {name: frame[name].to_numpy() for name in frame.columns}


def _same_columns(found: dict[str, np.ndarray], expected: dict[str, np.ndarray]) -> None:
    assert list(found) == list(expected)
    for name, values in expected.items():
        assert found[name].dtype == values.dtype, name
        assert found[name].tobytes() == values.tobytes(), name  # NaN == NaN, -0.0 != 0.0


def _read_facts(path: Path, cores: int):
    with pytest.MonkeyPatch.context() as patch:
        seen = _blocks(patch, cores)
        log = read_csv(path, None)
    channels = {name: (c.t.tobytes(), c.values.tobytes()) for name, c in log.channels.items()}
    return (channels, repr(log.source)), len(seen[-1]) if seen else 0


def _cell_text(draw, kind: str) -> str:
    if kind == "int":
        value = draw(st.one_of(st.integers(-1000, 1000), st.integers(-(2**63) + 1, 2**63 - 1)))
        return str(value)
    if kind == "empty":
        return draw(st.sampled_from(["", " "]))
    value = draw(st.floats(allow_nan=False, allow_infinity=False, width=64))
    return draw(st.sampled_from([repr(value), f"{value:.6f}", f"{value:.3e}", f"{value:.17g}"]))


@st.composite
def plain_tables(draw) -> bytes:
    """A header and rows of numbers: integers, decimals and empty cells (a column can change kind
    from row to row), spaces around cells, LF or CRLF, with or without a last line break."""
    columns = draw(st.integers(1, 4))
    rows = draw(st.integers(1, 60))
    kinds = st.sampled_from(["int", "int", "float", "float", "empty"])
    lines = [",".join(["time_s"] + [f"c{k}" for k in range(columns)])]
    for row in range(rows):
        cells = [f"{row * 0.01:.2f}"] + [_cell_text(draw, draw(kinds)) for _ in range(columns)]
        if draw(st.integers(0, 9)) == 0:
            cells = [" " + cell + "  " for cell in cells]
        lines.append(",".join(cells))
    end = draw(st.sampled_from(["\n", "\r\n"]))
    return (end.join(lines) + draw(st.sampled_from([end, ""]))).encode()


@settings(max_examples=150, deadline=None)
@given(plain_tables(), st.sampled_from([2, 3, 5]))
def test_blocks_on_several_threads_give_the_single_threaded_columns(text, cores):
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "table.csv"
        path.write_bytes(text)
        one, _ = _parse(path, 1)
        several, _ = _parse(path, cores)
        if one is not None:
            assert several is not None
            _same_columns(several.values, one.values)
            assert several.complete == one.complete
        elif several is not None:
            # one pass declined an integer over 2**53 after a decimal (an undecided rounding) that a
            # block of integers took: converted, it is pandas' correctly rounded double all the same
            _same_columns(several.values, _pandas_columns(path))


def test_a_column_of_integers_in_one_block_and_decimals_in_another_is_float64(tmp_path):
    for first, second in (("{k}", "{k}.5"), ("{k}.5", "{k}"), ("{k}", ""), ("", "{k}")):
        rows = [f"{k * 0.01:.2f},{(first if k < 2000 else second).format(k=k)},{k}" for k in range(4000)]
        path = tmp_path / "kinds.csv"
        path.write_text("time_s,a,b\n" + "\n".join(rows) + "\n", encoding="utf-8")
        one, _ = _parse(path, 1)
        several, blocks = _parse(path, 2)
        assert blocks == 2
        assert several.values["a"].dtype == np.float64 and several.values["b"].dtype == np.int64
        _same_columns(several.values, one.values)
        _same_columns(several.values, _pandas_columns(path))
        assert several.complete == one.complete == ({"time_s", "b"} if "" in (first, second) else {"time_s", "a", "b"})


def test_later_blocks_of_shorter_rows_than_their_room_was_guessed_for_are_all_read(tmp_path):
    # the first 64 KiB set the guess of each block's rows (long rows: few); the rest are short rows
    path = tmp_path / "uneven.csv"
    long_rows = [f"{k},{k * 0.5}" + " " * 200 for k in range(400)]
    short_rows = [f"{k},{k}" for k in range(400, 40400)]
    path.write_text("t,a\n" + "\n".join(long_rows + short_rows) + "\n", encoding="utf-8")
    one, _ = _parse(path, 1)
    for cores in (2, 3):
        several, blocks = _parse(path, cores)
        assert blocks == cores and len(several.values["t"]) == 40400
        _same_columns(several.values, one.values)


def _flight(path: Path, rows: int = 6000) -> list[str]:
    lines = ["time_s,x,sparse,counter"]
    lines += [f"{k * 0.01:.2f},{np.sin(k):.9f},{'' if k % 3 else k * 0.5},{k * 1000}" for k in range(rows)]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return lines


def test_a_read_in_blocks_is_the_read_in_one_pass(tmp_path):
    path = tmp_path / "flight.csv"
    _flight(path)
    one, blocks_one = _read_facts(path, 1)
    several, blocks = _read_facts(path, 2)
    assert (blocks_one, blocks) == (1, 2)
    assert several == one


@pytest.mark.parametrize(
    "bad_line, message",
    [
        ("40.00,1,2,3,4", "Expected 4 fields in line 4002, saw 5"),  # more fields than the header
        ("40.00,1\u00e9,2,3", "not UTF-8"),
    ],
)
def test_a_bad_row_in_a_later_block_is_the_same_one_line_error(tmp_path, bad_line, message):
    path = tmp_path / "bad.csv"
    lines = _flight(path)
    lines[4001] = bad_line  # line 4002 of the file, in the second half: the second block
    path.write_bytes(("\n".join(lines) + "\n").encode("latin-1" if "\u00e9" in bad_line else "utf-8"))
    bad_row_at = sum(len(line) + 1 for line in lines[:4001])
    errors = []
    for cores in (1, 2):
        with pytest.MonkeyPatch.context() as patch:
            seen = _blocks(patch, cores)
            with pytest.raises(InputError) as caught:
                read_csv(path, None)
        assert len(seen[-1]) == cores and seen[-1][-1][0] < bad_row_at  # in the last block
        errors.append(caught.value.one_line())
    assert errors[0] == errors[1]
    assert message in errors[1] and str(path) in errors[1] and "\n" not in errors[1]


def test_a_cell_only_pandas_reads_in_a_later_block_sends_the_file_to_pandas(tmp_path):
    path = tmp_path / "words.csv"
    lines = _flight(path)
    lines[5000] = "49.99,NaN,,49990000"  # a written NaN: a sample pandas reads, not the fast path
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    assert _parse(path, 2) == (None, 2)
    one, _ = _read_facts(path, 1)
    several, _ = _read_facts(path, 2)
    assert several == one
    assert "1 NaN value(s) kept" in one[1]


def test_a_file_is_cut_after_line_breaks_into_one_block_per_usable_core(tmp_path, monkeypatch):
    path = tmp_path / "flight.csv"
    _flight(path)
    data = path.read_bytes()
    start = data.index(b"\n") + 1
    monkeypatch.setattr(csv_numeric, "THREAD_MIN_BYTES", 1 << 10)
    for cores, expected in ((1, 1), (2, 2), (3, 3)):
        monkeypatch.setattr(csv_numeric, "usable_cores", lambda cores=cores: cores)
        blocks = csv_numeric.row_blocks(data, start, len(data))
        assert len(blocks) == expected
        assert blocks[0][0] == start and blocks[-1][1] == len(data)
        assert all(a[1] == b[0] for a, b in zip(blocks, blocks[1:], strict=False))  # they tile the rows
        assert all(data[begin - 1 : begin] == b"\n" for begin, _ in blocks)  # each starts a row
    monkeypatch.setattr(csv_numeric, "THREAD_MIN_BYTES", len(data))  # too small to pay for a thread
    assert csv_numeric.row_blocks(data, start, len(data)) == [(start, len(data))]


@pytest.mark.parametrize("source, to, count", [(10, 7, 40), (50, 0, 40), (12, 0, 30), (2, 1, 40), (5, 5, 9), (9, 3, 0)])
def test_rows_moved_down_keep_their_bits_and_order(source, to, count):
    cells = np.arange(3 * 100, dtype=np.int64).reshape(3, 100)
    expected = cells.copy()
    expected[:, to : to + count] = cells[:, source : source + count]
    csv_numeric._move_rows(cells, source, to, count)
    assert np.array_equal(cells[:, : to + count], expected[:, : to + count])
