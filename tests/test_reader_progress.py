"""Every reader reports its byte progress to `read_log`'s ``progress(done, total)``: a block of the file
at a time (never per message), ``done`` never decreasing nor above ``total`` (the file's size), the
last call ``(total, total)``, and the Log read the same as without a callback."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from conftest import TESTDATA, need_testdata
from ros_edit import to_db3

import logscan.readers.rosbag as rosbag
import logscan.readers.ulog_reader as ulog_reader
from logscan.readers import read_log

ULOGS = sorted(TESTDATA.glob("px4-ulog*/*.ulg")) if TESTDATA.is_dir() else []
HUSKY_BAG = "ros-robots/robot_localization_test1_husky.bag"
HUSKY_ROS2 = "ros-robots/robot_localization_test1_husky_ros2"


def _read_with_progress(path: Path, topics=None) -> tuple[object, list[tuple[int, int]]]:
    calls: list[tuple[int, int]] = []
    log = read_log(path, topics, progress=lambda done, total: calls.append((done, total)))
    return log, calls


def _assert_honest(calls: list[tuple[int, int]], size: int, *, at_least: int = 2) -> None:
    assert len(calls) >= at_least
    assert all(total == size for _, total in calls)
    done = [d for d, _ in calls]
    assert done == sorted(done), "done went back"
    assert all(0 <= d <= size for d in done)
    assert calls[-1] == (size, size)


def _assert_same_log(log, reference) -> None:
    assert list(log.channels) == list(reference.channels)
    for name, channel in reference.channels.items():
        np.testing.assert_array_equal(log.channels[name].t, channel.t, err_msg=name)
        assert log.channels[name].values.tobytes() == channel.values.tobytes(), name  # NaN payloads too
    assert dataclasses.asdict(log.source) == dataclasses.asdict(reference.source)


@pytest.mark.testdata("px4-ulog")
@pytest.mark.parametrize("path", ULOGS, ids=[p.name for p in ULOGS])
def test_a_ulog_reports_its_framing_parse_and_topics(path):
    log, calls = _read_with_progress(path)
    _assert_honest(calls, path.stat().st_size, at_least=3 + 1)  # framed, parsed, a topic or more, end
    assert 0 < calls[0][0] < calls[1][0] < path.stat().st_size  # the framing pass, then pyulog's parse
    assert len(calls) == 2 + len(log.source.topics) + 1  # one per topic converted: none per message
    _assert_same_log(log, read_log(path))


@pytest.mark.testdata("px4-ulog")
def test_a_ulog_of_some_topics_reports_the_bytes_of_those(monkeypatch):
    path = ULOGS[-1]
    log, calls = _read_with_progress(path, ["vehicle_status_0"])
    _assert_honest(calls, path.stat().st_size)
    assert list(log.source.topics) == ["vehicle_status_0"]
    assert len(calls) == 2 + 1 + 1  # framed, parsed, the one topic, the end
    _assert_same_log(log, read_log(path, ["vehicle_status_0"]))


@pytest.mark.testdata("px4-ulog")
def test_a_ulog_read_the_careful_way_reports_at_least_its_end(monkeypatch):
    path = ULOGS[-1]
    monkeypatch.setattr(ulog_reader, "parse_clean", lambda *args: None)
    log, calls = _read_with_progress(path)
    _assert_honest(calls, path.stat().st_size)
    _assert_same_log(log, read_log(path))


def test_a_ros1_bag_reports_once_per_chunk():
    path = need_testdata(HUSKY_BAG)
    log, calls = _read_with_progress(path)
    size = path.stat().st_size
    _assert_honest(calls, size)
    from rosbags.rosbag1 import Reader

    with Reader(path) as reader:
        chunk_ends = sorted(chunk.datapos + chunk.datasize for chunk in reader.chunks.values())
    assert [done for done, _ in calls[:-1]] == chunk_ends  # every chunk holds some topic read here
    _assert_same_log(log, read_log(path))


def test_a_ros1_bag_read_through_rosbags_reports_every_4096_messages(monkeypatch):
    path = need_testdata(HUSKY_BAG)
    monkeypatch.setattr(rosbag, "_chunk_walk_possible", lambda reader, wire: False)
    log, calls = _read_with_progress(path)
    _assert_honest(calls, path.stat().st_size)
    messages = sum(info.message_count for info in log.source.topics.values())
    assert len(calls) == messages // rosbag._PROGRESS_MESSAGES + 1
    _assert_same_log(log, read_log(path))


def test_a_rosbag2_db3_reports_like_a_bag_read_through_rosbags(tmp_path):
    folder = to_db3(need_testdata(HUSKY_BAG), tmp_path / "husky_sqlite")
    log, calls = _read_with_progress(folder)
    size = sum(f.stat().st_size for f in folder.iterdir() if f.is_file())
    _assert_honest(calls, size)
    messages = sum(info.message_count for info in log.source.topics.values())
    assert len(calls) == messages // rosbag._PROGRESS_MESSAGES + 1
    _assert_same_log(log, read_log(folder))


def test_a_rosbag2_directory_of_one_mcap_reports_the_mcap_bytes():
    folder = need_testdata(HUSKY_ROS2)
    log, calls = _read_with_progress(folder)
    _assert_honest(calls, (folder / f"{folder.name}.mcap").stat().st_size)
    _assert_same_log(log, read_log(folder))


def _write_csv(path: Path, rows: int, *, text: bool = False) -> Path:
    t = np.arange(rows) * 0.01
    lines = ["time_s,a,b" + (",label" if text else "")]
    lines += [f"{x:.2f},{np.sin(x):.6f},{np.cos(x):.6f}" + (",on" if text else "") for x in t]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("text", [False, True], ids=["plain numbers", "pandas"])
def test_a_csv_file_reports_its_parse_and_columns(tmp_path, text):
    path = _write_csv(tmp_path / "run.csv", 200, text=text)
    log, calls = _read_with_progress(path)
    _assert_honest(calls, path.stat().st_size)
    assert calls[0] == (0, path.stat().st_size)  # before the parse
    assert len(calls) >= 2 + 3  # parse before and after (or a block), each column, the end
    assert sorted(log.channels) == ["/a", "/b"]
    _assert_same_log(log, read_log(path))


def test_a_large_csv_read_by_pandas_reports_each_block(tmp_path, monkeypatch):
    import logscan.readers.csv_blocks as csv_blocks

    monkeypatch.setattr(csv_blocks, "BLOCK_BYTES", 4096)  # blocks of 1000 rows (the least it takes)
    path = _write_csv(tmp_path / "run.csv", 60_000, text=True)  # 1.6 MB: 60 blocks
    log, calls = _read_with_progress(path)
    size = path.stat().st_size
    _assert_honest(calls, size)
    # the parse stage (below its share of the bar, _CSV_STAGE_SHARES) advances as pandas reads the
    # file, its read buffer (256 KiB) at a time: several distinct byte counts, not one at its end
    parse = {done for done, _ in calls if 0 < done < 0.8 * size}
    assert len(parse) >= 3
    _assert_same_log(log, read_log(path))
