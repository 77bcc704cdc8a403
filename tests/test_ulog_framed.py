"""The framed ULog read (logscan.readers.ulog_framed) gives what the careful read gives, appended data too."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import hypothesis.strategies as st
import numpy as np
import pytest
from conftest import need_testdata
from hypothesis import example, given, settings

import logscan.readers.ulog_framed as ulog_framed
import logscan.readers.ulog_reader as ulog_reader
from logscan.log import Channel
from logscan.readers.ulog_framed import _frame, parse_clean
from logscan.readers.ulog_reader import read_ulog

TESTDATA = Path(__file__).resolve().parents[2] / "shared" / "testdata"
ULOGS = sorted(TESTDATA.glob("px4-ulog*/*.ulg")) if TESTDATA.is_dir() else []
APPENDED = TESTDATA / "px4-ulog" / "sample_appended_multiple.ulg"


def _careful(path: Path, monkeypatch) -> object:
    with monkeypatch.context() as patch:
        patch.setattr(ulog_reader, "parse_clean", lambda *args: None)
        return read_ulog(path, None)


def _assert_same(a, b) -> None:
    assert list(a.channels) == list(b.channels)
    for name, channel in a.channels.items():
        other = b.channels[name]
        assert channel.t.dtype == other.t.dtype and channel.values.dtype == other.values.dtype
        np.testing.assert_array_equal(channel.t, other.t, err_msg=name)
        assert channel.values.tobytes() == other.values.tobytes(), name  # NaN payloads too
    assert dataclasses.asdict(a.source) == dataclasses.asdict(b.source)


@pytest.mark.parametrize("path", ULOGS, ids=[p.name for p in ULOGS])
def test_framed_read_equals_careful_read(path, monkeypatch):
    assert parse_clean(str(path), None) is not None  # every real sample is undamaged
    _assert_same(read_ulog(path, None), _careful(path, monkeypatch))


def _flag_offsets(data: bytes) -> tuple[int, list[int]]:
    at = 16  # the flag bits message is the first after the header
    assert data[at + 2 : at + 3] == b"B"
    start = at + 3 + 16
    return start, list(np.frombuffer(data[start : start + 24], dtype="<u8"))


def test_appended_data_on_message_starts_is_read_framed(monkeypatch):
    need_testdata(APPENDED)
    data = APPENDED.read_bytes()
    _, offsets = _flag_offsets(data)
    assert [o for o in offsets if o]  # the sample has appended data
    log = read_ulog(APPENDED, None)
    assert parse_clean(str(APPENDED), None) is not None
    assert log.source.metadata["ulog.log"]["data_appended"] == "true"
    _assert_same(log, _careful(APPENDED, monkeypatch))


@pytest.mark.parametrize("shift", [1, -1])
def test_appended_offset_off_a_message_start_is_read_the_careful_way(tmp_path, monkeypatch, shift):
    need_testdata(APPENDED)
    data = bytearray(APPENDED.read_bytes())
    start, offsets = _flag_offsets(bytes(data))
    offsets[0] = int(offsets[0]) + shift  # pyulog cuts the section inside a message there
    data[start : start + 24] = np.asarray(offsets, dtype="<u8").tobytes()
    path = tmp_path / "moved.ulg"
    path.write_bytes(bytes(data))
    assert parse_clean(str(path), None) is None
    _assert_same(read_ulog(path, None), _careful(path, monkeypatch))


def test_appended_offset_before_data_messages_is_read_the_careful_way(tmp_path):
    need_testdata(APPENDED)
    data = bytearray(APPENDED.read_bytes())
    start, offsets = _flag_offsets(bytes(data))
    buf = np.frombuffer(bytes(data), dtype=np.uint8)
    starts, _, types, _, _ = _frame(buf, 16, buf.size)
    data_starts = starts[types == ord("D")]
    offsets[0] = int(data_starts[data_starts.size // 2])  # a message start with data messages after it
    data[start : start + 24] = np.asarray(offsets, dtype="<u8").tobytes()
    path = tmp_path / "early.ulg"
    path.write_bytes(bytes(data))
    assert parse_clean(str(path), None) is None


def test_channel_keeps_arrays_of_its_types_and_converts_others():
    t = np.arange(3, dtype=np.int64)
    values = np.array([1.0, 2.0, 3.0])
    channel = Channel("/a", t, values)
    assert channel.t is t and channel.values is values
    snan = np.array([0x7FA00000, 0, 1], dtype="<u4").view(np.float32)  # a float32 signalling NaN
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        converted = Channel("/b", [0, 1, 2], snan)
    assert converted.t.dtype == np.int64 and converted.values.dtype == np.float64
    assert np.isnan(converted.values[0]) and converted.values[2] == np.float32(snan[2])
    swapped = Channel("/c", t.astype(">i8"), values.astype(">f8"))
    assert swapped.t.dtype == np.dtype(np.int64) and swapped.values.dtype == np.dtype(np.float64)
    with pytest.raises(ValueError, match="equal length"):
        Channel("/d", t, values[:2])


@pytest.mark.parametrize("path", ULOGS, ids=[p.name for p in ULOGS])
def test_framed_a_page_at_a_time_equals_careful_read(path, monkeypatch):
    """The framing walks, gathers and copies a slice of the file at a time, its pages given back
    after each (`_FRAME_BYTES`): slices of one page give what the careful read gives."""
    given_back = []
    monkeypatch.setattr(ulog_framed, "_FRAME_BYTES", 4096)
    monkeypatch.setattr(ulog_framed, "drop_mapped_pages", lambda mapped, stop: given_back.append(stop))
    framed = read_ulog(path, None)
    assert len(given_back) > path.stat().st_size // 4096  # a walk of every page, and the gathers
    _assert_same(framed, _careful(path, monkeypatch))


def test_a_message_cut_in_a_later_slice_is_read_the_careful_way(tmp_path, monkeypatch):
    need_testdata(APPENDED)
    data = APPENDED.read_bytes()
    path = tmp_path / "cut.ulg"
    path.write_bytes(data[: len(data) - 7])  # the last message cut
    monkeypatch.setattr(ulog_framed, "_FRAME_BYTES", 4096)
    assert parse_clean(str(path), None) is None


def test_a_data_message_too_short_for_its_id_in_a_later_slice_is_read_the_careful_way(tmp_path, monkeypatch):
    # a data message of a single byte, no room for its message id, is pyulog's to judge (each slice
    # notes its shortest as it is framed: a long log's sizes are then kept on disk)
    original = TESTDATA / "px4-ulog" / "sample_px4_events.ulg"
    need_testdata(original)
    path = tmp_path / "short.ulg"
    path.write_bytes(original.read_bytes() + b"\x01\x00D\x07")  # size 1, type 'D', one byte
    monkeypatch.setattr(ulog_framed, "_FRAME_BYTES", 4096)
    assert parse_clean(str(original), None) is not None
    assert parse_clean(str(path), None) is None
    # refused by the framing's plan itself, not only later when the topic is gathered
    assert ulog_framed._clean_plan(np.fromfile(original, np.uint8), lambda offset: None) is not None
    assert ulog_framed._clean_plan(np.fromfile(path, np.uint8), lambda offset: None) is None


@settings(max_examples=200, deadline=None)
@given(
    steps=st.lists(st.integers(3, 70_000), min_size=0, max_size=60),
    frame=st.integers(1, 200_000),
)
def test_file_slices_cover_every_offset_once_each_within_a_slice_of_the_file(steps, frame):
    offsets = np.cumsum(np.asarray([16, *steps], dtype=np.int64))[: len(steps)]
    slices = ulog_framed._file_slices(offsets, frame)
    covered = [i for lo, hi in slices for i in range(lo, hi)]
    assert covered == list(range(offsets.size))
    assert all(hi > lo and offsets[hi - 1] - offsets[lo] < frame for lo, hi in slices)


@settings(max_examples=80, deadline=None)
@example(ids=[int(i) for i in np.random.default_rng(3).choice([0, 1, 7, 300, 65535], 400)], gaps=[5] * 400, start=16)
@given(
    ids=st.lists(st.sampled_from([0, 1, 7, 300, 65535]), min_size=17, max_size=400),  # past insertion sort's 16
    gaps=st.lists(st.integers(3, 40), min_size=400, max_size=400),
    start=st.integers(16, 5000),
)
def test_a_slices_messages_grouped_by_id_are_each_ids_in_file_order(ids, gaps, start):
    """`_Part`'s one stable sort by id gives what a pass over every id gives: each id's offsets
    and sizes in file order, its count and its first message; nothing for an id not in the slice."""
    ids_arr = np.array(ids, np.uint16)
    offsets = start + np.cumsum(np.array(gaps[: ids_arr.size], np.int64))
    sizes = (offsets % 251 + 2).astype(np.uint16)
    part = ulog_framed._Part(offsets, sizes, ids_arr)
    for msg_id in (0, 1, 7, 300, 65535, 9):
        chosen = np.flatnonzero(ids_arr == msg_id)
        got_offsets, got_sizes = part.offsets_of(msg_id)
        np.testing.assert_array_equal(got_offsets, offsets[chosen])
        np.testing.assert_array_equal(got_sizes, sizes[chosen])
        assert got_offsets.dtype == np.int64
        assert part.counts.get(msg_id, 0) == chosen.size
        assert part.first.get(msg_id) == (int(offsets[chosen[0]]) if chosen.size else None)
