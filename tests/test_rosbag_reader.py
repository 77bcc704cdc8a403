"""ROS 1 bags, rosbag2 .db3 files and rosbag2 directories read to the channels of the same messages
in a ROS 2 MCAP; damaged bags are one clear error or a partial read; ArduPilot logs are refused."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import need_testdata
from ros_edit import to_db3
from rosbags.typesys import Stores, get_typestore

from logscan.errors import InputError, UnsupportedFormatError
from logscan.readers import detect_format, read_embedded, read_log

HUSKY_BAG = "ros-robots/robot_localization_test1_husky.bag"
HUSKY_ROS2 = "ros-robots/robot_localization_test1_husky_ros2"
ODOM = "/husky_velocity_controller/odom"
TOPICS = ("/imu/data", "/fix", ODOM)


@pytest.fixture(scope="module")
def husky_bag() -> Path:
    return need_testdata(HUSKY_BAG)


@pytest.fixture(scope="module")
def bag_log(husky_bag):
    return read_log(husky_bag)


@pytest.fixture(scope="module")
def mcap_log():
    folder = need_testdata(HUSKY_ROS2)
    return read_log(folder / f"{folder.name}.mcap")


@pytest.fixture(scope="module")
def husky_db3_dir(husky_bag, tmp_path_factory) -> Path:
    """The Husky bag converted to a rosbag2 directory with sqlite3 storage, by rosbags itself."""
    out = tmp_path_factory.mktemp("db3") / "husky_ros2_sqlite"
    to_db3(husky_bag, out)
    return out


def _topic_channels(log, topic: str) -> dict:
    return {name: c for name, c in log.channels.items() if name.startswith(topic + "/")}


def assert_same_channels(log, reference, *, exact: bool = True) -> None:
    assert sorted(log.channels) == sorted(reference.channels)
    for name, channel in reference.channels.items():
        np.testing.assert_array_equal(log.channels[name].t, channel.t, err_msg=name)
        if exact:
            np.testing.assert_array_equal(log.channels[name].values, channel.values, err_msg=name)
        else:
            np.testing.assert_allclose(log.channels[name].values, channel.values, rtol=1e-6, atol=1e-7, err_msg=name)


def test_ros1_bag_gives_the_channel_names_of_the_ros2_mcap(bag_log, mcap_log):
    assert sorted(bag_log.channels) == sorted(mcap_log.channels)
    for name in (
        "/imu/data/linear_acceleration.x",
        "/fix/position_covariance[0]",
        f"{ODOM}/twist.twist.linear.x",
        "/imu/data/header.stamp.sec",
        "/imu/data/header.stamp.nanosec",
    ):
        assert name in bag_log.channels
    # the ROS 1 header's seq is dropped, its stamp named as in ROS 2
    assert not [name for name in bag_log.channels if "seq" in name or "secs" in name]


@pytest.mark.parametrize("topic", TOPICS)
def test_ros1_bag_and_ros2_mcap_give_the_same_samples(bag_log, mcap_log, topic):
    bag, mcap = _topic_channels(bag_log, topic), _topic_channels(mcap_log, topic)
    assert bag and sorted(bag) == sorted(mcap)
    counts = {len(c) for c in bag.values()}
    assert counts == {mcap_log.source.topics[topic].message_count}
    for name, channel in mcap.items():
        np.testing.assert_array_equal(bag[name].t, channel.t)
        np.testing.assert_allclose(bag[name].values, channel.values, rtol=1.2e-7, atol=1e-30, err_msg=name)


def test_ros1_bag_topics_are_described_in_ros2_terms(bag_log, mcap_log):
    source = bag_log.source
    assert source.format == "ros1bag" and not source.partial
    assert {name: t.schema for name, t in source.topics.items()} == {
        "/imu/data": "sensor_msgs/msg/Imu",
        "/fix": "sensor_msgs/msg/NavSatFix",
        ODOM: "nav_msgs/msg/Odometry",
    }
    for name, info in source.topics.items():
        ros2 = mcap_log.source.topics[name]
        assert info.encoding == "ros1"
        assert (info.message_count, info.first_ns, info.last_ns) == (ros2.message_count, ros2.first_ns, ros2.last_ns)
        assert info.fields == ros2.fields
    assert [(s.what, s.why, s.count) for s in source.skipped] == [
        (s.what, s.why, s.count) for s in mcap_log.source.skipped
    ]


def test_only_the_wanted_topics_are_decoded_but_all_are_listed(husky_bag):
    log = read_log(husky_bag, topics={"/fix"})
    assert log.channels and all(name.startswith("/fix/") for name in log.channels)
    assert set(log.source.topics) == set(TOPICS)
    assert log.source.topics["/imu/data"].message_count == 11865
    assert read_log(husky_bag, topics=()).channels == {}


def test_header_stamp_times_as_in_the_mcap_reader(husky_bag, mcap_log):
    bag = read_log(husky_bag, topics={"/fix"}, use_header_stamp=True)
    folder = need_testdata(HUSKY_ROS2)
    mcap = read_log(folder / f"{folder.name}.mcap", topics={"/fix"}, use_header_stamp=True)
    assert bag.source.time_source == mcap.source.time_source == "header.stamp"
    sec, nsec = bag.channels["/fix/header.stamp.sec"], bag.channels["/fix/header.stamp.nanosec"]
    expected = sec.values.astype(np.int64) * 1_000_000_000 + nsec.values.astype(np.int64)
    np.testing.assert_array_equal(np.sort(expected), bag.channels["/fix/latitude"].t)
    np.testing.assert_array_equal(bag.channels["/fix/latitude"].t, mcap.channels["/fix/latitude"].t)


@pytest.mark.parametrize("path", ["rosbags iteration + CDR kernel", "deserializer"])
def test_every_ros1_path_gives_the_chunk_walk_channels(husky_bag, bag_log, monkeypatch, path):
    import logscan.readers.rosbag as rosbag
    import logscan.readers.rosbag_types as rosbag_types

    monkeypatch.setattr(rosbag, "_chunk_walk_possible", lambda reader, wire: False)
    if path == "deserializer":
        monkeypatch.setattr(rosbag_types, "cdr_layout", lambda schema: None)
    slow = read_log(husky_bag)
    assert_same_channels(slow, bag_log)
    assert [(s.what, s.why, s.count) for s in slow.source.skipped] == [
        (s.what, s.why, s.count) for s in bag_log.source.skipped
    ]
    assert slow.source.topics == bag_log.source.topics


def test_husky_types_are_decoded_in_place(husky_bag):
    from rosbags.rosbag1 import Reader

    import logscan.readers.rosbag1_chunks as chunks
    from logscan.readers.rosbag_types import bag_typestore

    with Reader(husky_bag) as reader:
        store, bad, wire = bag_typestore(list(reader.connections), ros1=True)
        layouts = {c.msgtype: chunks.ros1_layout(wire, store, c.msgtype) for c in reader.connections}
    assert not bad and all(layout is not None for layout in layouts.values())
    assert "header.stamp.sec" in layouts["sensor_msgs/msg/Imu"].paths
    assert not [p for p in layouts["sensor_msgs/msg/Imu"].paths if "seq" in p]


def test_rosbag2_sqlite_directory_and_db3_read_to_the_bag_channels(husky_db3_dir, bag_log):
    db3 = next(husky_db3_dir.glob("*.db3"))
    assert detect_format(husky_db3_dir) == "rosbag2" and detect_format(db3) == "rosbag2"
    for path in (husky_db3_dir, db3):
        log = read_log(path)
        assert log.source.format == "rosbag2" and not log.source.partial
        assert_same_channels(log, bag_log)
        info = log.source.topics["/imu/data"]
        assert (info.encoding, info.schema, info.message_count) == ("cdr", "sensor_msgs/msg/Imu", 11865)
        assert info.first_ns == bag_log.source.topics["/imu/data"].first_ns


def test_rosbag2_directory_with_mcap_storage_reads_to_the_bag_channels(bag_log):
    folder = need_testdata(HUSKY_ROS2)
    assert detect_format(folder) == "rosbag2"
    log = read_log(folder)
    assert (log.source.format, log.source.path) == ("rosbag2", str(folder))
    assert_same_channels(log, bag_log)


def test_bags_embed_no_profile(husky_bag, husky_db3_dir):
    assert read_embedded(husky_bag) == (None, None)
    assert read_embedded(husky_db3_dir) == (None, None)


def test_truncated_bag_is_one_input_error_naming_the_file(husky_bag, tmp_path, cli):
    cut = tmp_path / "cut.bag"
    cut.write_bytes(husky_bag.read_bytes()[:500_000])
    assert detect_format(cut) == "ros1bag"
    with pytest.raises(InputError, match="ROS 1 bag") as caught:
        read_log(cut)
    assert caught.value.path == str(cut) and "rosbag reindex" in caught.value.hint
    result = cli("inspect", cut)
    assert result.exit_code == 2 and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and str(cut) in result.stderr


def test_truncated_db3_is_one_input_error(husky_db3_dir, tmp_path):
    db3 = next(husky_db3_dir.glob("*.db3"))
    cut = tmp_path / "cut.db3"
    cut.write_bytes(db3.read_bytes()[: db3.stat().st_size // 2])
    with pytest.raises(InputError, match="rosbag2") as caught:
        read_log(cut)
    assert caught.value.path == str(cut)


@pytest.mark.parametrize("at", [5_000, 600_000])
def test_a_damaged_chunk_is_skipped_and_the_rest_read(husky_bag, tmp_path, at):
    data = bytearray(husky_bag.read_bytes())
    data[at : at + 1000] = b"\xff" * 1000
    damaged = tmp_path / "damaged.bag"
    damaged.write_bytes(bytes(data))
    log = read_log(damaged)
    assert log.source.partial and "1 damaged chunk(s) skipped" in log.source.partial_reason
    assert "recovered" in log.source.partial_reason
    assert 11865 // 2 < len(log.channels["/imu/data/linear_acceleration.x"]) < 11865


@pytest.mark.parametrize("compression", [None, "BZ2", "LZ4"])
def test_ros1_bag_written_by_rosbags_reads_variable_length_arrays(tmp_path, compression):
    """No shared data needed: a bag with a fixed-layout type (decoded in place), a variable-length
    one (decoded per message) and an empty one, in each chunk compression."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    Header, Time = store.types["std_msgs/msg/Header"], store.types["builtin_interfaces/msg/Time"]
    Vector3 = store.types["geometry_msgs/msg/Vector3"]
    JointState = store.types["sensor_msgs/msg/JointState"]
    path = tmp_path / "small.bag"
    writer = Writer(path)
    if compression:
        writer.set_compression(Writer.CompressionFormat[compression])
    with writer:
        accel = writer.add_connection("/accel", "geometry_msgs/msg/Vector3", typestore=store)
        empty = writer.add_connection("/tick", "std_msgs/msg/Empty", typestore=store)
        joints = writer.add_connection("/joints", "sensor_msgs/msg/JointState", typestore=store)
        for k in range(20):
            t = 1_000_000_000 + k * 10_000_000
            writer.write(accel, t, store.serialize_ros1(Vector3(x=k, y=-k, z=0.5), "geometry_msgs/msg/Vector3"))
            n = 1 + k % 2
            header = Header(seq=k, stamp=Time(sec=1, nanosec=k * 10_000_000 + 5), frame_id="base")
            msg = JointState(
                header=header,
                name=["a", "b"][:n],
                position=np.arange(n, dtype=np.float64) + k,
                velocity=np.zeros(0),
                effort=np.zeros(0),
            )
            writer.write(joints, t + 1, store.serialize_ros1(msg, "sensor_msgs/msg/JointState"))
            writer.write(empty, t + 2, store.serialize_ros1(store.types["std_msgs/msg/Empty"](), "std_msgs/msg/Empty"))
    log = read_log(path)
    assert log.source.topics["/tick"].message_count == 20 and not log.source.partial
    assert log.source.format == "ros1bag"
    np.testing.assert_array_equal(log.channels["/accel/x"].values, np.arange(20))
    assert len(log.channels["/joints/position[0]"]) == 20 and len(log.channels["/joints/position[1]"]) == 10
    np.testing.assert_array_equal(log.channels["/joints/position[1]"].values, np.arange(1, 20, 2) + 1)
    assert "/joints/header.stamp.nanosec" in log.channels and "/joints/header.seq" not in log.channels
    assert log.source.topics["/joints"].schema == "sensor_msgs/msg/JointState"
    stamped = read_log(path, topics={"/joints"}, use_header_stamp=True)
    assert stamped.channels["/joints/position[0]"].t[3] == 1_030_000_005


def _dataflash() -> bytes:
    # FMT message describing itself: header A3 95, type 128, type, length, name, format, columns
    fmt = (
        b"\xa3\x95\x80"
        + bytes([128, 89])
        + b"FMT\x00"
        + b"BBnNZ".ljust(16, b"\x00")
        + b"Type,Length".ljust(64, b"\x00")
    )
    return fmt * 5


def _tlog(version: int) -> bytes:
    out = b""
    for k in range(4):
        stamp = (1_700_000_000_000_000 + k * 1000).to_bytes(8, "big")
        payload = bytes(9)
        if version == 1:
            frame = bytes([0xFE, len(payload), k, 1, 1, 0]) + payload + b"\x00\x00"
        else:
            frame = bytes([0xFD, len(payload), 0, 0, k, 1, 1, 0, 0, 0]) + payload + b"\x00\x00"
        out += stamp + frame
    return out


@pytest.mark.parametrize(
    ("name", "content", "words"),
    [
        ("flight.bin", _dataflash(), "ArduPilot DataFlash log: not supported yet"),
        ("00000042.BIN", _dataflash(), "ArduPilot DataFlash log"),
        ("renamed.log", _dataflash(), "ArduPilot DataFlash log"),
        ("flight.tlog", _tlog(1), "MAVLink telemetry log (ArduPilot"),
        ("flight2.tlog", _tlog(2), "MAVLink telemetry log (ArduPilot"),
        ("renamed.dat", _tlog(2), "MAVLink telemetry log (ArduPilot"),
        ("odd.tlog", b"\x00\x01\x02junk", "MAVLink telemetry log (ArduPilot"),
    ],
)
def test_ardupilot_logs_are_refused_with_what_to_do(tmp_path, cli, name, content, words):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(UnsupportedFormatError, match="ArduPilot") as caught:
        detect_format(path)
    assert words in caught.value.message and "mavlogdump.py --format csv" in caught.value.hint
    result = cli("inspect", path)
    assert result.exit_code == 2 and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and words in result.stderr


def test_random_bytes_named_bin_are_not_called_dataflash(tmp_path):
    path = tmp_path / "firmware.bin"
    path.write_bytes(np.random.default_rng(1).integers(0, 256, 5000, dtype=np.uint8).tobytes())
    with pytest.raises(UnsupportedFormatError, match="nor a ROS bag") as caught:
        detect_format(path)
    assert "ArduPilot" not in caught.value.message and ".db3" in caught.value.hint


def test_format_detection_by_content(tmp_path):
    (tmp_path / "a.bag").write_bytes(b"#ROSBAG V2.0\n" + bytes(100))
    (tmp_path / "b.anything").write_bytes(b"SQLite format 3\x00" + bytes(100))
    (tmp_path / "old.bag").write_bytes(b"#ROSBAG V1.2\n" + bytes(100))
    bag_dir, csv_dir, both = tmp_path / "bag", tmp_path / "csvs", tmp_path / "both"
    for folder in (bag_dir, csv_dir, both):
        folder.mkdir()
    (bag_dir / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (csv_dir / "x.csv").write_text("t,a\n0,1\n")
    (both / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (both / "x.csv").write_text("t,a\n0,1\n")
    assert detect_format(tmp_path / "a.bag") == "ros1bag"
    assert detect_format(tmp_path / "b.anything") == "rosbag2"
    assert detect_format(bag_dir) == "rosbag2" and detect_format(both) == "rosbag2"
    assert detect_format(csv_dir) == "csv-dir"
    with pytest.raises(UnsupportedFormatError, match="ROS bag version 1.2"):
        detect_format(tmp_path / "old.bag")


def test_broken_bag_metadata_is_one_input_error(tmp_path):
    folder = tmp_path / "bag"
    folder.mkdir()
    (folder / "metadata.yaml").write_text("rosbag2_bagfile_information: {version: 9}\n")
    with pytest.raises(InputError, match="rosbag2 cannot be opened") as caught:
        read_log(folder)
    assert caught.value.path == str(folder)


def test_sqlite_file_not_named_db3_says_what_to_do(tmp_path):
    path = tmp_path / "bag.sqlite"
    path.write_bytes(b"SQLite format 3\x00" + bytes(100))
    with pytest.raises(InputError, match="not named .db3"):
        read_log(path)


def test_inspect_shows_the_bag_in_ros2_terms(husky_bag, cli):
    result = cli("inspect", husky_bag)
    assert result.exit_code == 0, result.stderr
    assert "ros1bag" in result.stdout and "ros1 / sensor_msgs/msg/Imu" in result.stdout
    assert "unknown magic bytes" not in result.stdout + result.stderr


def test_inspect_of_a_rosbag2_directory_names_the_directory(cli):
    folder = need_testdata(HUSKY_ROS2)
    result = cli("inspect", folder, "--json", "-")
    assert result.exit_code == 0, result.stderr
    facts = json.loads(result.stdout)
    assert (facts["file"], facts["format"]) == (str(folder), "rosbag2")
    assert facts["topics"]["/imu/data"]["message_count"] == 11865
    assert facts["channels"]["/imu/data/linear_acceleration.x"]["samples"] == 11865


def test_a_topic_whose_definition_does_not_parse_is_skipped_and_named(tmp_path):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    path = tmp_path / "odd.bag"
    with Writer(path) as writer:
        good = writer.add_connection("/accel", "geometry_msgs/msg/Vector3", typestore=store)
        odd = writer.add_connection("/odd", "odd_msgs/msg/Odd", msgdef="float64[ x", md5sum="0" * 32)
        for k in range(5):
            vector = store.types["geometry_msgs/msg/Vector3"](x=k, y=0.0, z=0.0)
            writer.write(good, 10 + k, store.serialize_ros1(vector, "geometry_msgs/msg/Vector3"))
            writer.write(odd, 10 + k, b"\x00" * 8)
    log = read_log(path)
    assert list(log.channels) == ["/accel/x", "/accel/y", "/accel/z"]
    assert "topics skipped (no decoder): /odd" in log.source.warnings
    assert [(s.what, s.count) for s in log.source.skipped if s.what == "/odd"] == [("/odd", 5)]
    assert "does not parse" in next(s.why for s in log.source.skipped if s.what == "/odd")


def test_db3_without_message_definitions_uses_the_ros2_types(husky_db3_dir, bag_log, tmp_path):
    import shutil
    import sqlite3

    bare = tmp_path / "bare.db3"
    shutil.copy(next(husky_db3_dir.glob("*.db3")), bare)
    with sqlite3.connect(bare) as db:
        db.execute("DELETE FROM message_definitions")
    db.close()
    log = read_log(bare)
    assert_same_channels(log, bag_log)
    assert not log.source.warnings


def _bag_writer(path, chunk_threshold: int):
    """rosbags' ROS 1 writer, its chunks closed at ``chunk_threshold`` bytes (20: a chunk a message)."""
    from rosbags.rosbag1 import Writer

    writer = Writer(path)
    writer.chunk_threshold = chunk_threshold
    return writer


@pytest.mark.parametrize("chunk_threshold", [20, 1 << 20])  # a chunk per message; one chunk
@pytest.mark.parametrize("stream_goes_back", [False, True])
def test_a_topic_recorded_under_two_types_is_out_of_order_only_if_a_type_is(
    tmp_path, chunk_threshold, stream_goes_back
):
    """Two publishers of one topic with different types interleave in the file; each type's
    messages are read together, so the topic's pieces join out of order although the file is in
    order: no warning then, but one when a type's own messages go back in time."""
    store = get_typestore(Stores.ROS1_NOETIC)
    F64, F32 = store.types["std_msgs/msg/Float64"], store.types["std_msgs/msg/Float32"]
    path = tmp_path / "two_types.bag"
    with _bag_writer(path, chunk_threshold) as writer:
        wide = writer.add_connection("/x", "std_msgs/msg/Float64", typestore=store)
        narrow = writer.add_connection("/x", "std_msgs/msg/Float32", typestore=store)
        seconds = [1, 3, 5, 7, 9, 11]
        if stream_goes_back:
            seconds[3], seconds[4] = seconds[4], seconds[3]
        for s in seconds:
            writer.write(wide, s * 10**9, store.serialize_ros1(F64(data=float(s)), "std_msgs/msg/Float64"))
            writer.write(narrow, (s + 1) * 10**9, store.serialize_ros1(F32(data=float(s + 1)), "std_msgs/msg/Float32"))
    log = read_log(path)
    channel = log.channels["/x/data"]
    assert channel.t.tolist() == [s * 10**9 for s in range(1, 13)]
    np.testing.assert_array_equal(channel.values, np.arange(1.0, 13.0))
    warned = [w for w in log.source.warnings if "not in time order" in w]
    assert warned == (
        ["1 channel(s) not in time order in the file, sorted by time: /x/data"] if stream_goes_back else []
    )


def _index_of_rosbags_and_table(path):
    from rosbags.rosbag1 import Reader

    from logscan.readers.rosbag1_index import TableIndexReader

    with Reader(path) as own, TableIndexReader(path) as table:
        table.index_objects()
        copies = [
            ([c._replace(owner=None) for c in r.connections], {i: [tuple(x) for x in e] for i, e in r.indexes.items()})
            for r in (own, table)
        ]
        return *copies, table.index


@pytest.mark.parametrize("chunk_threshold", [20, 1 << 20])
def test_the_index_table_is_rosbags_index(tmp_path, chunk_threshold):
    """The bag's index kept as a table holds what rosbags' reader indexes, message for message:
    its counts, and (made back into rosbags' objects for its own reads) the same index in the same
    order, times going back and equal times across chunks included."""
    store = get_typestore(Stores.ROS1_NOETIC)
    F64 = store.types["std_msgs/msg/Float64"]
    path = tmp_path / "index.bag"
    with _bag_writer(path, chunk_threshold) as writer:
        one = writer.add_connection("/a", "std_msgs/msg/Float64", typestore=store)
        two = writer.add_connection("/b", "std_msgs/msg/Float64", typestore=store)
        writer.add_connection("/never", "std_msgs/msg/Float64", typestore=store)
        for k, seconds in enumerate([5, 1, 3, 3, 2, 9, 3, 7]):
            data = store.serialize_ros1(F64(data=float(k)), "std_msgs/msg/Float64")
            writer.write(one if k % 3 else two, seconds * 10**9 + 4_000_000_000 * 10**9, data)
    rosbags_index, table_index, table = _index_of_rosbags_and_table(path)
    assert table_index == rosbags_index
    assert [c.msgcount for c in table_index[0]] == [5, 3, 0]
    assert table.shape == (8, 4) and table[:, 1].min() == 4_000_000_001 * 10**9  # seconds near uint32's end, in ns


def test_the_index_table_is_rosbags_index_on_a_real_drive(husky_bag):
    rosbags_index, table_index, _ = _index_of_rosbags_and_table(husky_bag)
    assert table_index == rosbags_index


@pytest.mark.parametrize("field", ["data length", "header length"])
def test_a_damaged_index_length_is_one_error_without_reading_the_rest(tmp_path, field):
    """A damaged length in an index record (after the first chunk) is refused before it is read:
    a 0xFFFFFFF0 length read the rest of the file first (4 GiB at the most). Here the bag ends in
    a sparse gigabyte, which such a read would hold."""
    import os
    import struct
    import tracemalloc

    from rosbags.rosbag1 import Reader

    store = get_typestore(Stores.ROS1_NOETIC)
    F64 = store.types["std_msgs/msg/Float64"]
    path = tmp_path / "damaged_index.bag"
    with _bag_writer(path, 20) as writer:
        connection = writer.add_connection("/a", "std_msgs/msg/Float64", typestore=store)
        for k in range(5):
            writer.write(connection, (k + 1) * 10**9, store.serialize_ros1(F64(data=k), "std_msgs/msg/Float64"))
    with Reader(path) as reader:
        chunk = reader.chunks[min(reader.chunks)]
        at = chunk.datapos + chunk.datasize  # the chunk's first index record
    with open(path, "r+b") as fh:
        fh.seek(at)
        header_bytes = struct.unpack("<I", fh.read(4))[0]
        fh.seek(at if field == "header length" else at + 4 + header_bytes)
        fh.write(struct.pack("<I", 0xFFFFFFF0))
    os.truncate(path, path.stat().st_size + (1 << 30))
    tracemalloc.start()
    try:
        with pytest.raises(InputError, match="cannot be opened"):
            read_log(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 64 << 20


def test_without_rosbags_a_bag_is_one_error_saying_what_to_install(husky_bag, monkeypatch):
    from logscan.readers import rosbag1_index

    monkeypatch.setattr(rosbag1_index, "ROSBAGS_MISSING", ImportError("No module named 'rosbags'"))
    with pytest.raises(InputError, match="needs the rosbags library"):
        read_log(husky_bag)
