"""Arrays held on disk (`logscan.readers.spill`): a long ULog's held read keeps its records, framing and
channels in unlinked files whose pages this process gives back; the values are the same as in
memory, and a page given back is read again, not lost."""

from __future__ import annotations

import mmap
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from logscan.pipeline.held_window import HeldLog, whole_times, window_of
from logscan.readers import read_log, spill, ulog_columns, ulog_reader
from logscan.readers.common import ReadWindow

TESTDATA = Path(__file__).resolve().parents[2] / "shared" / "testdata"
ULOGS = sorted((TESTDATA / "px4-ulog").glob("*.ulg")) + sorted((TESTDATA / "px4-ulog-extra").glob("*.ulg"))
linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/pagemap")
# where arrays cannot be put on disk (no madvise, a temporary directory in memory), there is nothing to test
on_disk = pytest.mark.skipif(
    not (spill._CAN and spill._room_on_disk(0)), reason="the temporary directory is not on a disk"
)


def _resident_pages(array: np.ndarray) -> int:
    """Pages of ``array`` mapped in this process now (the present bit of /proc/self/pagemap)."""
    address = array.__array_interface__["data"][0]
    first, last = address // 4096, (address + array.nbytes - 1) // 4096
    with open("/proc/self/pagemap", "rb") as pagemap:
        pagemap.seek(first * 8)
        entries = np.frombuffer(pagemap.read((last - first + 1) * 8), np.uint64)
    return int(np.count_nonzero(entries >> np.uint64(63)))


@on_disk
def test_large_arrays_are_on_disk_only_within_spilling():
    assert not spill.on_disk(spill.empty(1 << 20, np.float64))
    with spill.spilling():
        big, small = spill.empty((4, 1 << 16), np.float32), spill.empty(16, np.int64)
        off = None
        with spill.spilling(False):
            off = spill.empty(1 << 20, np.uint8)
    assert spill.on_disk(big) and spill.on_disk(big[2]) and not spill.on_disk(small) and not spill.on_disk(off)
    assert big.shape == (4, 1 << 16) and big.dtype == np.float32 and big.flags.writeable


@linux_only
@on_disk
def test_pages_given_back_leave_the_process_and_come_back_with_their_values():
    with spill.spilling():
        array = spill.empty(1 << 21, np.float64)  # 16 MiB: a file of its own
    array[:] = np.arange(array.size)
    assert _resident_pages(array) == array.nbytes // 4096
    spill.give_back()
    assert _resident_pages(array) == 0
    np.testing.assert_array_equal(array, np.arange(array.size))  # read again from the file


@linux_only
@on_disk
@pytest.mark.skipif(mmap.PAGESIZE != 4096, reason="the bound counts 4-KiB pages")
def test_a_binary_search_over_an_array_on_disk_maps_pages_not_folios_of_megabytes():
    # each block's window of a held read searches its time arrays: mapped with read-ahead, each
    # probe mapped the page cache's whole large folio (ext4, Linux 6.16+): 6 MiB per search here
    with spill.spilling():
        times = spill.empty(7_000_000, np.int64)  # 56 MB: a file of its own, written as a read writes it
    for lo in range(0, times.size, 1 << 16):
        times[lo : lo + (1 << 16)] = np.arange(lo, min(lo + (1 << 16), times.size))
        spill.passed(1 << 19)
    spill.give_back()
    assert int(np.searchsorted(times, 4_500_001)) == 4_500_001
    assert _resident_pages(times) <= 16 * 24  # the kernel's fault-around, 64 KiB, per probe at most


@on_disk
@given(sizes=st.lists(st.integers(1, 3 << 20), min_size=1, max_size=12), seed=st.integers(0, 2**32 - 1))
@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_arrays_carved_from_one_file_never_overlap(sizes, seed, monkeypatch):  # the same constants each time
    monkeypatch.setattr(spill, "MIN_BYTES", 1)
    monkeypatch.setattr(spill, "SHARED_FILE_BYTES", 4 << 20)  # several files, some arrays each
    rng = np.random.default_rng(seed)
    with spill.spilling():
        arrays = [spill.empty(size, np.uint8) for size in sizes]
        expected = [rng.integers(0, 256, size, dtype=np.uint8) for size in sizes]
        for array, values in zip(arrays, expected, strict=True):
            array[:] = values
            spill.passed(array.nbytes)
    spill.give_back()
    for array, values in zip(arrays, expected, strict=True):
        np.testing.assert_array_equal(array, values)


def test_an_array_that_cannot_be_put_on_disk_is_an_ordinary_one(monkeypatch):
    def no_space(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(tempfile, "TemporaryFile", no_space)
    with spill.spilling():
        array = spill.empty(1 << 22, np.uint8)
    assert array.size == 1 << 22 and not spill.on_disk(array)


def test_without_a_usable_temporary_directory_the_arrays_stay_in_memory(monkeypatch):
    def none_usable():
        raise FileNotFoundError("No usable temporary directory found")

    monkeypatch.setattr(tempfile, "gettempdir", none_usable)  # a read-only container, say
    with spill.spilling():
        array = spill.empty(1 << 22, np.uint8)
    assert not spill.on_disk(array)


def test_nothing_is_put_on_disk_without_room_for_it():
    with spill.spilling(needs=1 << 62):  # more free space than any disk has
        array = spill.empty(1 << 22, np.uint8)
    assert not spill.on_disk(array)


@linux_only
def test_nothing_is_put_on_disk_where_the_temporary_directory_is_in_memory(monkeypatch):
    shm = Path("/dev/shm")
    mounts = Path("/proc/self/mounts").read_text()
    if not shm.is_dir() or not any(f" {shm} tmpfs " in line + " " for line in mounts.splitlines()):
        pytest.skip("no tmpfs at /dev/shm")
    monkeypatch.setattr(tempfile, "tempdir", str(shm))
    with spill.spilling():
        array = spill.empty(1 << 22, np.uint8)  # on tmpfs its file would be memory, reserved whole
    assert not spill.on_disk(array)


def _on_disk_everything(monkeypatch) -> None:
    """Every array of a held read on disk, converted a few records at a time (chunk borders everywhere)."""
    monkeypatch.setattr(ulog_reader, "SPILL_FROM_BYTES", 0)
    monkeypatch.setattr(spill, "MIN_BYTES", 1)
    monkeypatch.setattr(spill, "PASSED_BYTES", 4096)
    monkeypatch.setattr(spill, "CHUNK", 97)
    monkeypatch.setattr(ulog_columns, "HELD_CHUNK", 53)


@on_disk
@pytest.mark.testdata("px4-ulog")
@pytest.mark.parametrize("path", ULOGS, ids=lambda p: p.name)
def test_a_held_read_on_disk_is_the_held_read_in_memory(path, monkeypatch):
    memory = read_log(path, held=True)
    _on_disk_everything(monkeypatch)
    disk = read_log(path, held=True)
    assert disk.channels.keys() == memory.channels.keys()
    for name, channel in disk.channels.items():
        kept = memory.channels[name]
        assert channel.values.dtype == kept.values.dtype, name
        np.testing.assert_array_equal(channel.t, kept.t, err_msg=name)
        np.testing.assert_array_equal(channel.values, kept.values, err_msg=name)
    read = [channel for channel in disk.channels.values() if len(channel)]
    assert all(spill.on_disk(channel.t) for channel in read)
    # the values too, but a topic's with a sample dropped (timestamp 0): pyulog's columns, picked
    assert sum(spill.on_disk(channel.values) for channel in read) >= 0.9 * len(read)
    assert disk.source.topics == memory.source.topics
    assert disk.source.metadata == memory.source.metadata  # the parameter changes' and dropouts' times too
    assert disk.source.warnings == memory.source.warnings and disk.source.skipped == memory.source.skipped


@on_disk
@pytest.mark.testdata("px4-ulog")
def test_a_window_of_a_log_held_on_disk_is_the_window_in_memory(monkeypatch):
    path = ULOGS[0]
    memory = read_log(path, held=True)
    _on_disk_everything(monkeypatch)
    disk = read_log(path, held=True)
    held_disk, held_memory = (HeldLog(log, (0, 0), frozenset(), *whole_times(log)) for log in (disk, memory))
    for start in (0.0, 3.0, 11.5):
        window = ReadWindow(start, start + 4.0, margin_s=1.0)
        cut, kept = window_of(held_disk, window), window_of(held_memory, window)
        assert cut.channels.keys() == kept.channels.keys()
        for name, channel in cut.channels.items():
            np.testing.assert_array_equal(channel.t, kept.channels[name].t, err_msg=name)
            np.testing.assert_array_equal(channel.values, kept.channels[name].values, err_msg=name)
        assert cut.start_ns == kept.start_ns and cut.end_ns == kept.end_ns


@on_disk
@pytest.mark.testdata("px4-ulog/sample_px4_events.ulg")
def test_a_real_ulog_held_on_disk_is_analysed_in_blocks_as_in_memory(monkeypatch):
    from logscan.pipeline.blocks import analyze_blocked

    path = TESTDATA / "px4-ulog" / "sample_px4_events.ulg"
    memory = analyze_blocked(path, block_s=10.0).summary()
    _on_disk_everything(monkeypatch)
    disk = analyze_blocked(path, block_s=10.0).summary()
    assert disk == memory
    assert memory["warnings"] and memory["detectors"] and memory["filter"]  # figures that could differ


HUSKY_BAG = TESTDATA / "ros-robots" / "robot_localization_test1_husky.bag"


@on_disk
@pytest.mark.testdata("ros-robots/robot_localization_test1_husky.bag")
def test_a_held_bag_on_disk_is_the_bag_read_in_memory(monkeypatch):
    """A long ROS 1 bag held for block mode kept every decoded value in memory (8 hours of the
    Husky drive repeated: 1.16 GB peak): held, its chunks' values are joined a batch at a time into
    arrays on disk. Here every array and batch on disk, a few chunks a batch: the same channels."""
    from logscan.readers import rosbag1_chunks

    memory = read_log(HUSKY_BAG, held=True)
    monkeypatch.setattr(spill, "HELD_FROM_BYTES", 0)
    monkeypatch.setattr(spill, "MIN_BYTES", 1)
    monkeypatch.setattr(spill, "PASSED_BYTES", 4096)
    monkeypatch.setattr(rosbag1_chunks, "BATCH_BYTES", 50_000)  # batch borders everywhere
    disk = read_log(HUSKY_BAG, held=True)
    assert list(disk.channels) == list(memory.channels) and len(disk.channels) > 50
    for name, channel in disk.channels.items():
        kept = memory.channels[name]
        assert channel.values.dtype == kept.values.dtype, name
        np.testing.assert_array_equal(channel.t, kept.t, err_msg=name)
        np.testing.assert_array_equal(channel.values, kept.values, err_msg=name)
        assert spill.on_disk(channel.t) and spill.on_disk(channel.values), name
    assert disk.source.topics == memory.source.topics and disk.source.warnings == memory.source.warnings
    assert not any(spill.on_disk(c.values) for c in read_log(HUSKY_BAG).channels.values())  # not held: memory


@on_disk
@pytest.mark.testdata("ros-robots/robot_localization_test1_husky.bag")
def test_a_held_bag_read_message_by_message_is_decoded_in_batches_on_disk(monkeypatch, tmp_path):
    """A rosbag2 database (and a ROS 1 bag the chunk walk cannot take) is read message by message
    through rosbags; it held every message's bytes, then every decoded value, in memory (8 hours of
    the Husky drive as a .db3: 1.48 GB peak). Its messages are now decoded a batch at a time and,
    held, the batches wait on disk. Here a batch every few messages: the same channels, on disk."""
    from ros_edit import to_db3

    from logscan.readers import rosbag

    db3 = to_db3(HUSKY_BAG, tmp_path / "husky_db3")
    memory = read_log(db3, held=True)
    decoded = []
    monkeypatch.setattr(rosbag, "_decode_topic", _counting(rosbag._decode_topic, decoded))
    monkeypatch.setattr(rosbag, "RAW_BATCH_BYTES", 20_000)
    monkeypatch.setattr(spill, "HELD_FROM_BYTES", 0)
    monkeypatch.setattr(spill, "MIN_BYTES", 1)
    disk = read_log(db3, held=True)
    assert len(decoded) > 100  # batches, not one call per topic
    assert list(disk.channels) == list(memory.channels) and len(disk.channels) > 50
    for name, channel in disk.channels.items():
        np.testing.assert_array_equal(channel.t, memory.channels[name].t, err_msg=name)
        np.testing.assert_array_equal(channel.values, memory.channels[name].values, err_msg=name)
        assert spill.on_disk(channel.t) and spill.on_disk(channel.values), name
    assert disk.source.topics == memory.source.topics and disk.source.warnings == memory.source.warnings


def _counting(function, calls: list):
    def counted(*args, **kwargs):
        calls.append(args[0])
        return function(*args, **kwargs)

    return counted
