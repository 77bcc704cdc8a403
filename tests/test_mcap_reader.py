"""MCAP reader: conformance files, corrupt variants, every message encoding, flattening rules."""

from __future__ import annotations

import io
import json
import struct
from pathlib import Path

import numpy as np
import pytest
from conftest import need_testdata
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.writer import CompressionType, Writer

from logscan.errors import CorruptLogError, InputError
from logscan.log import Log
from logscan.readers import read_log
from logscan.readers.mcap import inspect_mcap, iter_raw_messages, read_mcap
from logscan.readers.mcap.writer import TopicData, mcap_bytes

CONFORMANCE = Path(__file__).resolve().parents[2] / "shared" / "testdata" / "mcap-conformance"
CONFORMANCE_FILES = sorted(CONFORMANCE.glob("*/*.mcap")) if CONFORMANCE.is_dir() else []


# --------------------------------------------------------------------------------------------
# conformance


def _expected_messages(json_path: Path) -> list[tuple]:
    records = json.loads(json_path.read_text())["records"]
    topics: dict[str, str] = {}
    out = []
    for record in records:
        fields = dict(record["fields"])
        if record["type"] == "Channel":
            topics[fields["id"]] = fields["topic"]
        elif record["type"] == "Message":
            out.append(
                (
                    topics[fields["channel_id"]],
                    int(fields["log_time"]),
                    int(fields["publish_time"]),
                    int(fields["sequence"]),
                    bytes(int(b) for b in fields["data"]),
                )
            )
    return out


def test_conformance_suite_is_complete():
    need_testdata(CONFORMANCE)
    assert len(CONFORMANCE_FILES) == 416


@pytest.mark.testdata("mcap-conformance")
@pytest.mark.parametrize("path", CONFORMANCE_FILES, ids=lambda p: p.stem)
def test_conformance_file_yields_exactly_its_messages(path: Path):
    expected = _expected_messages(path.with_suffix(".json"))
    got = [(m.topic, m.log_time, m.publish_time, m.sequence, m.data) for m in iter_raw_messages(path)]
    assert got == expected

    log = read_mcap(path, None)
    assert not log.source.partial
    assert sum(info.message_count for info in log.source.topics.values()) == len(expected)
    if expected:
        # their message encodings ("a", "text") have no decoder: skipped, counted, named
        skipped = {(s.what, s.count) for s in log.source.skipped}
        assert skipped == {("example", len(expected))}
        assert "no decoder for message encoding" in log.source.skipped[0].why
        assert any("example" in w for w in log.source.warnings)
    assert log.channels == {}


def test_conformance_metadata_record_is_read():
    path = CONFORMANCE / "OneMetadata" / "OneMetadata.mcap"
    need_testdata(path)
    log = read_mcap(path, None)
    assert log.source.metadata == {"myMetadata": {"foo": "bar"}}


# --------------------------------------------------------------------------------------------
# corrupt variants of a file we write


def _imu_topics(n: int = 3000) -> dict[str, TopicData]:
    t = np.arange(n, dtype=np.int64) * 10_000_000 + 1_000_000_000
    rng = np.random.default_rng(7)
    return {
        "/imu": TopicData("test/Imu", t, {f"accel.{a}": rng.normal(size=n) for a in "xyz"}),
        "/gps": TopicData("test/Gps", t[::10] + 3, {"position.x": np.arange(n // 10, dtype=float)}),
    }


class _Valid(tuple):
    """(path, bytes, Log) of the valid file, with a short repr for hypothesis reports."""

    def __repr__(self) -> str:
        return f"<valid file {self[0]}>"


@pytest.fixture(scope="module")
def valid_file(tmp_path_factory) -> tuple[Path, bytes, Log]:
    data = mcap_bytes(_imu_topics(), metadata={"logscan.truth": {"json": '{"events": []}'}}, chunk_size=16 * 1024)
    path = tmp_path_factory.mktemp("mcap") / "valid.mcap"
    path.write_bytes(data)
    log = read_mcap(path, None)
    assert not log.source.partial and log.source.warnings == []
    return _Valid((path, data, log))


def _check_outcome(path: Path, original: Log) -> str:
    """Read ``path``: an input error (exit 2), a Log equal to the original, or a partial prefix."""
    try:
        log = read_log(path)
    except InputError as exc:  # CorruptLogError, or UnsupportedFormatError for a broken magic
        line = exc.one_line()
        assert str(path) in line and "\n" not in line
        return "error"
    if not log.source.partial:
        assert set(log.channels) == set(original.channels)
        for name, channel in log.channels.items():
            np.testing.assert_array_equal(channel.t, original.channels[name].t)
            np.testing.assert_array_equal(channel.values, original.channels[name].values)
        return "intact"
    assert "recovered" in log.source.partial_reason
    assert set(log.channels) <= set(original.channels)
    for name, channel in log.channels.items():  # samples of the original (damaged chunks are skipped)
        whole = original.channels[name]
        at = np.minimum(np.searchsorted(whole.t, channel.t), len(whole) - 1)
        np.testing.assert_array_equal(channel.t, whole.t[at])
        np.testing.assert_array_equal(channel.values, whole.values[at])
    return "partial"


def test_truncated_file_reads_a_partial_prefix_or_fails_cleanly(valid_file, tmp_path):
    path, data, original = valid_file
    outcomes = []
    for cut in [8, 20, 200, len(data) // 3, len(data) // 2, len(data) - 200, len(data) - 9]:
        cut_path = tmp_path / f"cut{cut}.mcap"
        cut_path.write_bytes(data[:cut])
        outcomes.append(_check_outcome(cut_path, original))
    assert outcomes[0] == "error" and outcomes[1] == "error"
    assert outcomes[3] == "partial" and outcomes[-1] == "partial"
    half = read_mcap(tmp_path / f"cut{len(data) // 2}.mcap", None)
    assert 0 < len(half.channels["/imu/accel.x"]) < len(original.channels["/imu/accel.x"])
    assert "messages" in half.source.partial_reason and "log_time" in half.source.partial_reason


def test_bad_magic_is_a_corrupt_log_error(valid_file, tmp_path):
    _, data, _ = valid_file
    bad = tmp_path / "bad_magic.mcap"
    bad.write_bytes(b"\x89MCAX0\r\n" + data[8:])
    with pytest.raises(CorruptLogError, match="magic"):
        read_mcap(bad, None)


def _first_chunk_crc_offset(data: bytes) -> int:
    pos = 8
    while True:
        op, length = struct.unpack_from("<BQ", data, pos)
        if op == 0x06:
            return pos + 9 + 24  # after message start/end time and uncompressed size
        pos += 9 + length


def test_a_chunk_failing_its_crc_is_skipped_and_the_read_goes_on(valid_file, tmp_path):
    path, data, original = valid_file
    offset = _first_chunk_crc_offset(data)
    broken = bytearray(data)
    broken[offset] ^= 0xFF
    bad = tmp_path / "bad_crc.mcap"
    bad.write_bytes(bytes(broken))
    log = read_mcap(bad, None)  # the writer repeats the channel records in every chunk
    assert log.source.partial
    assert "1 damaged chunk(s) skipped" in log.source.partial_reason and "CRC" in log.source.partial_reason
    assert 0 < len(log.channels["/imu/accel.x"]) < len(original.channels["/imu/accel.x"])
    # a later chunk: the messages around it are recovered and the Log says so
    second = data.index(b"\x06", offset + 100)
    while True:
        broken = bytearray(data)
        try:
            op, length = struct.unpack_from("<BQ", data, second)
        except struct.error:
            pytest.fail("no second chunk")
        if op == 0x06 and 0 < length < len(data):
            break
        second = data.index(b"\x06", second + 1)
    broken[second + 9 + 24] ^= 0x01
    bad.write_bytes(bytes(broken))
    assert _check_outcome(bad, original) in ("partial", "error")


def test_data_section_crc_guards_the_metadata_records(valid_file, tmp_path):
    path, data, _ = valid_file
    at = data.index(b'{"events": []}')
    broken = bytearray(data)
    broken[at + 2] ^= 0x20  # "events" -> "Events": only the data-section CRC can tell
    bad = tmp_path / "meta.mcap"
    bad.write_bytes(bytes(broken))
    with pytest.raises(CorruptLogError, match="data section CRC"):
        read_mcap(bad, None)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(position=st.floats(0, 1, exclude_max=True), xor=st.integers(1, 255))
def test_any_flipped_byte_gives_error_or_honest_result(valid_file, tmp_path, position, xor):
    path, data, original = valid_file
    broken = bytearray(data)
    broken[int(position * len(data))] ^= xor
    bad = tmp_path / "flip.mcap"
    bad.write_bytes(bytes(broken))
    _check_outcome(bad, original)


# --------------------------------------------------------------------------------------------
# message encodings


def _json_file(path: Path, topics: dict[str, list[tuple[int, object]]]) -> None:
    with open(path, "wb") as fh:
        writer = Writer(fh, compression=CompressionType.NONE)
        writer.start()
        for topic, messages in topics.items():
            schema = writer.register_schema("Thing", "jsonschema", b"{}")
            channel = writer.register_channel(topic, "json", schema)
            for log_time, message in messages:
                data = message if isinstance(message, bytes) else json.dumps(message).encode()
                writer.add_message(channel, log_time, data, log_time)
        writer.finish()


def test_json_nested_arrays_bools_and_non_numeric_fields(tmp_path):
    path = tmp_path / "j.mcap"
    _json_file(
        path,
        {
            "/robot": [
                (10, {"pose": {"x": 1.0, "y": 2}, "ranges": [1, 2, 3], "ok": True, "frame": "map", "v": None}),
                (20, {"pose": {"x": 1.5, "y": 3}, "ranges": [4], "ok": False, "frame": "map", "v": None}),
                (30, {"pose": {"x": 2.5, "y": 4}, "ranges": [5, 6], "ok": True, "frame": "odom", "v": None}),
            ]
        },
    )
    log = read_mcap(path, None)
    ch = log.channels
    np.testing.assert_array_equal(ch["/robot/pose.x"].values, [1.0, 1.5, 2.5])
    np.testing.assert_array_equal(ch["/robot/pose.x"].t, [10, 20, 30])
    np.testing.assert_array_equal(ch["/robot/ok"].values, [1, 0, 1])
    # variable-length array: each index only where present, never zero-padded
    np.testing.assert_array_equal(ch["/robot/ranges[0]"].t, [10, 20, 30])
    np.testing.assert_array_equal(ch["/robot/ranges[1]"].t, [10, 30])
    np.testing.assert_array_equal(ch["/robot/ranges[1]"].values, [2, 6])
    np.testing.assert_array_equal(ch["/robot/ranges[2]"].values, [3])
    assert "/robot/frame" not in ch
    skipped = {(s.what, s.why): s.count for s in log.source.skipped}
    assert skipped[("/robot/frame", "non-numeric")] == 3
    assert skipped[("/robot/v", "null value")] == 3
    info = log.source.topics["/robot"]
    assert info.message_count == 3 and info.encoding == "json" and info.schema == "Thing"
    assert (info.first_ns, info.last_ns) == (10, 30)
    assert "pose.x" in info.fields and "ranges[2]" in info.fields


def test_topic_without_leading_slash_and_scalar_message(tmp_path):
    path = tmp_path / "s.mcap"
    _json_file(path, {"imu": [(1, {"accel": {"x": 0.5}})], "/speed": [(1, 3.25), (2, 4.0)]})
    log = read_mcap(path, None)
    assert set(log.channels) == {"imu/accel.x", "/speed"}
    np.testing.assert_array_equal(log.channels["/speed"].values, [3.25, 4.0])


def test_only_wanted_topics_are_decoded(tmp_path):
    path = tmp_path / "w.mcap"
    _json_file(path, {"/a": [(1, {"x": 1.0})], "/b": [(1, b"not json {")]})
    everything = read_mcap(path, None)
    assert any(s.what == "/b" and "do not decode" in s.why for s in everything.source.skipped)
    only_a = read_mcap(path, {"/a/x"})
    assert set(only_a.channels) == {"/a/x"}
    assert only_a.source.skipped == []  # /b was never decoded
    assert only_a.source.topics["/b"].message_count == 1  # but it is still counted


def test_script_topic_name_survives_as_data(tmp_path):
    path = tmp_path / "x.mcap"
    topic = "<script>alert('x')</script>"
    _json_file(path, {topic: [(1, {"v": 1.0})]})
    log = read_mcap(path, None)
    assert list(log.channels) == [topic + "/v"]
    assert topic in log.source.topics


def test_out_of_order_messages_are_sorted_with_a_warning(tmp_path):
    path = tmp_path / "o.mcap"
    _json_file(path, {"/a": [(30, {"x": 3.0}), (10, {"x": 1.0}), (20, {"x": 2.0})]})
    log = read_mcap(path, None)
    np.testing.assert_array_equal(log.channels["/a/x"].t, [10, 20, 30])
    np.testing.assert_array_equal(log.channels["/a/x"].values, [1.0, 2.0, 3.0])
    assert any("sorted" in w for w in log.source.warnings)


def test_json_header_stamp_option(tmp_path):
    path = tmp_path / "h.mcap"
    stamp = {"sec": 100, "nanosec": 5}
    _json_file(path, {"/a": [(1, {"header": {"stamp": stamp}, "x": 1.0})], "/b": [(2, {"x": 2.0})]})
    plain = read_mcap(path, None)
    assert plain.channels["/a/x"].t.tolist() == [1] and plain.source.time_source == "log_time"
    stamped = read_mcap(path, None, use_header_stamp=True)
    assert stamped.channels["/a/x"].t.tolist() == [100_000_000_005]
    assert stamped.channels["/b/x"].t.tolist() == [2]
    assert stamped.source.time_source == "header.stamp (log_time for /b)"


ROS2_SUBTYPES = """
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: geometry_msgs/Point
float64 x
float64 y
float64 z
"""


ROS2_POSE = (
    """std_msgs/Header header
geometry_msgs/Point position
float64[] ranges
int32[3] counts
bool ok
string label
"""
    + ROS2_SUBTYPES
)


def test_ros2_cdr_round_trip_with_header_stamp(tmp_path):
    from mcap_ros2.writer import Writer as Ros2Writer

    path = tmp_path / "r2.mcap"
    with open(path, "wb") as fh:
        writer = Ros2Writer(fh)
        schema = writer.register_msgdef("test_msgs/msg/Pose", ROS2_POSE)
        for k in range(3):
            writer.write_message(
                "/pose",
                schema,
                {
                    "header": {"stamp": {"sec": 50 + k, "nanosec": 7}, "frame_id": "map"},
                    "position": {"x": 1.0 * k, "y": 2.0, "z": -1.0},
                    "ranges": [0.5] * (k + 1),
                    "counts": [1, 2, 3],
                    "ok": k % 2 == 0,
                    "label": "a",
                },
                log_time=1000 + k,
            )
        writer.finish()
    log = read_mcap(path, None)
    ch = log.channels
    np.testing.assert_array_equal(ch["/pose/position.x"].values, [0.0, 1.0, 2.0])
    np.testing.assert_array_equal(ch["/pose/position.x"].t, [1000, 1001, 1002])
    np.testing.assert_array_equal(ch["/pose/counts[2]"].values, [3, 3, 3])
    np.testing.assert_array_equal(ch["/pose/ranges[2]"].t, [1002])
    np.testing.assert_array_equal(ch["/pose/ok"].values, [1, 0, 1])
    np.testing.assert_array_equal(ch["/pose/header.stamp.sec"].values, [50, 51, 52])
    assert log.source.topics["/pose"].encoding == "cdr"
    assert log.source.topics["/pose"].schema == "test_msgs/msg/Pose"
    whys = {(s.what, s.why) for s in log.source.skipped}
    assert ("/pose/header.frame_id", "non-numeric") in whys and ("/pose/label", "non-numeric") in whys
    stamped = read_mcap(path, None, use_header_stamp=True)
    assert stamped.channels["/pose/position.x"].t.tolist() == [k * 1_000_000_000 + 7 for k in (50, 51, 52)]
    assert stamped.source.time_source == "header.stamp"


ROS1_POSE = """Header header
float64[] ranges
float32 speed
================================================================================
MSG: std_msgs/Header
uint32 seq
time stamp
string frame_id
"""


def test_ros1_round_trip_with_header_stamp(tmp_path):
    from mcap_ros1._vendor.genpy import dynamic
    from mcap_ros1.writer import Writer as Ros1Writer

    msg_class = dynamic.generate_dynamic("test_msgs/Pose", ROS1_POSE)["test_msgs/Pose"]
    path = tmp_path / "r1.mcap"
    with open(path, "wb") as fh:
        writer = Ros1Writer(fh)
        for k in range(2):
            message = msg_class()
            message.header.stamp.secs = 20 + k
            message.header.stamp.nsecs = 9
            message.header.frame_id = "odom"
            message.ranges = [1.5, 2.5][: k + 1]
            message.speed = 0.25 * (k + 1)
            writer.write_message("/ros1", message, log_time=500 + k)
        writer.finish()
    log = read_mcap(path, None)
    np.testing.assert_array_equal(log.channels["/ros1/speed"].values, [0.25, 0.5])
    np.testing.assert_array_equal(log.channels["/ros1/ranges[1]"].values, [2.5])
    np.testing.assert_array_equal(log.channels["/ros1/header.stamp.secs"].values, [20, 21])
    assert log.source.topics["/ros1"].encoding == "ros1"
    stamped = read_mcap(path, None, use_header_stamp=True)
    assert stamped.channels["/ros1/speed"].t.tolist() == [20_000_000_009, 21_000_000_009]


def _protobuf_class():
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    file_proto = descriptor_pb2.FileDescriptorProto(name="logscan_test.proto", package="lstest", syntax="proto3")
    vec = file_proto.message_type.add(name="Vec")
    for number, name in enumerate("xyz", start=1):
        vec.field.add(
            name=name,
            number=number,
            type=descriptor_pb2.FieldDescriptorProto.TYPE_DOUBLE,
            label=descriptor_pb2.FieldDescriptorProto.LABEL_OPTIONAL,
        )
    pose = file_proto.message_type.add(name="Pose")
    F = descriptor_pb2.FieldDescriptorProto
    pose.field.add(name="position", number=1, type=F.TYPE_MESSAGE, type_name=".lstest.Vec", label=F.LABEL_OPTIONAL)
    pose.field.add(name="velocity", number=2, type=F.TYPE_MESSAGE, type_name=".lstest.Vec", label=F.LABEL_OPTIONAL)
    pose.field.add(name="cov", number=3, type=F.TYPE_DOUBLE, label=F.LABEL_REPEATED)
    pose.field.add(name="frame", number=4, type=F.TYPE_STRING, label=F.LABEL_OPTIONAL)
    pose.field.add(name="ok", number=5, type=F.TYPE_BOOL, label=F.LABEL_OPTIONAL)
    pool = descriptor_pool.DescriptorPool()
    pool.Add(file_proto)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName("lstest.Pose"))


def test_protobuf_round_trip(tmp_path):
    from mcap_protobuf.writer import Writer as ProtobufWriter

    Pose = _protobuf_class()
    path = tmp_path / "pb.mcap"
    with open(path, "wb") as fh:
        writer = ProtobufWriter(fh)
        first = Pose(frame="map", ok=True)
        first.position.x, first.position.y, first.position.z = 1.0, 2.0, 3.0
        first.cov.extend([0.1, 0.2])
        writer.write_message("/pb", first, log_time=10)
        second = Pose(frame="map")
        second.position.x = 4.0
        second.velocity.z = 9.0
        writer.write_message("/pb", second, log_time=20)
        writer.finish()
    log = read_mcap(path, None)
    ch = log.channels
    np.testing.assert_array_equal(ch["/pb/position.x"].values, [1.0, 4.0])
    np.testing.assert_array_equal(ch["/pb/position.z"].values, [3.0, 0.0])  # proto3 default
    np.testing.assert_array_equal(ch["/pb/velocity.z"].t, [20])  # unset sub-message: absent
    np.testing.assert_array_equal(ch["/pb/cov[1]"].values, [0.2])
    np.testing.assert_array_equal(ch["/pb/ok"].values, [1, 0])
    assert log.source.topics["/pb"].encoding == "protobuf"
    assert any(s.what == "/pb/frame" and s.count == 2 for s in log.source.skipped)


def test_schema_that_does_not_parse_skips_the_topic_with_its_reason(tmp_path):
    path = tmp_path / "bad_schema.mcap"
    buffer = io.BytesIO()
    writer = Writer(buffer)
    writer.start()
    schema = writer.register_schema("x/msg/Bad", "ros2msg", b"this is not a ros2 definition [[[")
    channel = writer.register_channel("/bad", "cdr", schema)
    writer.add_message(channel, 1, b"\x00\x01\x00\x00", 1)
    writer.finish()
    path.write_bytes(buffer.getvalue())
    log = read_mcap(path, None)
    assert log.channels == {}
    assert log.source.skipped[0].what == "/bad" and "cannot be parsed" in log.source.skipped[0].why


# --------------------------------------------------------------------------------------------
# the fast paths give exactly what decoding + the generic walk give


def _generic_columns(messages):
    from logscan.readers.flatten import flatten_messages

    flat = flatten_messages(messages)
    return flat.fields, {k: (i.tolist(), v.tolist()) for k, (i, v) in flat.columns.items()}, flat.skipped


def _same_columns(fast, generic) -> None:
    fields, columns, skipped = generic
    assert fast.fields == fields
    assert fast.skipped == skipped
    for name, (index, values) in columns.items():
        got_index, got_values = fast.columns[name]
        assert got_index.tolist() == index
        np.testing.assert_array_equal(got_values, values)


def test_json_fast_path_matches_json_loads_on_mixed_messages():
    from logscan.readers.json_decoder import json_columns

    texts = [
        b'{"a": {"x": 1.5, "y": -2}, "ok": true, "s": "map", "n": null, "v": [1, 2e-3]}',
        b'{"a": {"x": -0.0, "y": 12345678901234567890}, "ok": false, "s": "map", "n": null, "v": [NaN, -Infinity]}',
        b'{"a": {"x": 3.25, "y": 1}, "ok": true, "s": "odom", "n": null, "v": [1, 2]}',  # other string
        b'{"a": {"x": 4.0, "y": 2}, "ok": true, "s": "map", "n": 7, "v": [1, 2]}',  # null became a number
        b'{"a": {"x": 5.0, "y": 3},  "ok": true, "s": "map", "n": null, "v": [1, 2]}',  # other spacing
        b'{"a": {"x": 6.0, "y": 4}, "ok": true, "s": "map", "n": null, "v": [1, 2, 3]}',  # longer array
        b'{"a": {"x": 1e400, "y": 5}, "ok": true, "s": "map", "n": null, "v": [1, 2]}',
        b'{"a": {"x": 7.0, "y": 6}, "ok": true, "s": "map", "n": null, "v": [1, 2]}',
        b"not json at all",
        b'{"a": {"x": "8", "y": 7}, "ok": true, "s": "map", "n": null, "v": [1, 2]}',  # string number
    ]
    flat, failed = json_columns(texts)
    assert failed == [8]
    messages = [json.loads(t) for k, t in enumerate(texts) if k != 8]
    fields, columns, skipped = _generic_columns(messages)
    renumber = [k for k in range(len(texts)) if k != 8]
    columns = {name: ([renumber[i] for i in index], values) for name, (index, values) in columns.items()}
    _same_columns(flat, (fields, columns, skipped))


@settings(max_examples=40, deadline=None)
@given(
    st.lists(
        st.tuples(st.floats(allow_nan=False, width=64), st.integers(-(2**70), 2**70), st.booleans()),
        min_size=2,
        max_size=30,
    )
)
def test_json_fast_path_parses_numbers_like_json_loads(rows):
    from logscan.readers.json_decoder import json_columns

    texts = [json.dumps({"f": f, "i": i, "b": b, "t": "x"}).encode() for f, i, b in rows]
    flat, failed = json_columns(texts)
    assert failed == []
    _same_columns(flat, _generic_columns([json.loads(t) for t in texts]))


ROS2_FIXED = (
    """std_msgs/Header header
int8 a
uint16 b
int32 c
uint64 d
float32 e
bool f
float64[3] g
uint8[2] h
string[2] names
geometry_msgs/Point[2] pts
int64 z
"""
    + ROS2_SUBTYPES
)


def test_ros2_fast_cdr_path_matches_the_mcap_ros2_decoder(tmp_path):
    from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory
    from mcap_ros2.writer import Writer as Ros2Writer

    from logscan.readers.mcap.cdr import cdr_fast, cdr_layout
    from logscan.readers.mcap.scan_records import SchemaRec

    rng = np.random.default_rng(5)
    path = tmp_path / "fixed.mcap"
    with open(path, "wb") as fh:
        writer = Ros2Writer(fh)
        schema = writer.register_msgdef("test_msgs/msg/Fixed", ROS2_FIXED)
        for k in range(20):
            writer.write_message(
                "/fixed",
                schema,
                {
                    "header": {"stamp": {"sec": k, "nanosec": 3 * k}, "frame_id": "f" * (k % 5)},
                    "a": int(rng.integers(-128, 128)),
                    "b": int(rng.integers(0, 65536)),
                    "c": int(rng.integers(-(2**31), 2**31)),
                    "d": int(rng.integers(0, 2**63)),
                    "e": float(np.float32(rng.normal())),
                    "f": bool(k % 2),
                    "g": rng.normal(size=3).tolist(),
                    "h": bytes([k, 2 * k]),
                    "names": ["n" * k, "m"],
                    "z": -k * 10**12,
                    "pts": [{"x": float(k), "y": 1.0, "z": 2.0}, {"x": 3.0, "y": float(-k), "z": 4.0}],
                },
                log_time=k,
            )
        writer.finish()
    raw = list(iter_raw_messages(path))
    datas = [m.data for m in raw]
    from mcap.records import Schema

    layout = cdr_layout(SchemaRec(1, "test_msgs/msg/Fixed", "ros2msg", ROS2_FIXED.encode()))
    assert layout is not None
    fast = cdr_fast(layout, datas)
    assert fast is not None
    schema = Schema(id=1, name="test_msgs/msg/Fixed", encoding="ros2msg", data=ROS2_FIXED.encode())
    decode = Ros2DecoderFactory().decoder_for("cdr", schema)
    _same_columns(fast, _generic_columns([decode(d) for d in datas]))
    assert "pts[1].y" in fast.fields and ("header.frame_id", "non-numeric") in fast.skipped
    # read_mcap takes the fast path and names channels as usual
    log = read_mcap(path, None)
    np.testing.assert_array_equal(log.channels["/fixed/pts[1].y"].values, [-float(k) for k in range(20)])


@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.LZ4, CompressionType.NONE])
@pytest.mark.parametrize("chunked", [True, False])
def test_library_written_files_read_back_in_every_layout(tmp_path, compression, chunked):
    path = tmp_path / "lib.mcap"
    with open(path, "wb") as fh:
        writer = Writer(fh, compression=compression, use_chunking=chunked, chunk_size=2048)
        writer.start()
        writer.add_metadata("logscan.profile", {"toml": "x = 1\n"})
        schema = writer.register_schema("S", "jsonschema", b"{}")
        channel = writer.register_channel("/v", "json", schema)
        for k in range(300):
            writer.add_message(channel, 1000 + k, json.dumps({"k": k, "half": k / 2}).encode(), 1000 + k)
        writer.finish()
    log = read_mcap(path, None)
    assert not log.source.partial
    np.testing.assert_array_equal(log.channels["/v/k"].values, np.arange(300))
    np.testing.assert_array_equal(log.channels["/v/half"].t, 1000 + np.arange(300))
    assert log.profile_text == "x = 1\n"


# --------------------------------------------------------------------------------------------
# packed message bytes: the bulk paths read chunk buffers in place, the generic path gets bytes


def _mixed_json_file(path: Path, chunked: bool) -> None:
    """Two JSON topics over many small chunks; /mix changes layout and has undecodable messages."""
    with open(path, "wb") as fh:
        writer = Writer(fh, compression=CompressionType.LZ4, use_chunking=chunked, chunk_size=1024)
        writer.start()
        schema = writer.register_schema("S", "jsonschema", b"{}")
        steady = writer.register_channel("/steady", "json", schema)
        mixed = writer.register_channel("/mix", "json", schema)
        writer.add_metadata("between", {"k": "v"})  # splits an unchunked file's top-level runs
        for k in range(400):
            writer.add_message(steady, 10 * k, json.dumps({"a": k / 3, "b": {"c": -k}}).encode(), 10 * k)
            if k % 7 == 3:
                data = b"{broken"
            else:
                data = json.dumps({"v": list(range(k % 4)), "s": "x" * (k % 2), "ok": k % 3 == 0}).encode()
            writer.add_message(mixed, 10 * k + 5, data, 10 * k + 5)
        writer.finish()


def _read_both_paths(monkeypatch, path: Path, topics: set[str] | None) -> tuple[Log, Log]:
    import logscan.readers.mcap.reader as reader

    fast = read_mcap(path, topics)
    with monkeypatch.context() as patch:
        patch.setattr(reader, "cdr_layout", lambda schema: None)  # no CDR layout kernel
        patch.setattr(reader, "JsonDecoder", type("NoBulkJson", (), {}))  # no JSON template path
        slow = read_mcap(path, topics)
    return fast, slow


@pytest.mark.parametrize("layout", ["json", "ros2", "mixed-chunked", "mixed-unchunked"])
def test_bulk_paths_on_packed_chunks_match_the_generic_decoders(tmp_path, monkeypatch, layout):
    path = tmp_path / f"{layout}.mcap"
    if layout.startswith("mixed"):
        _mixed_json_file(path, chunked=layout == "mixed-chunked")
        topics = None
    else:
        path.write_bytes(mcap_bytes(_imu_topics(), encoding=layout, chunk_size=4096))
        topics = {"/imu"}
    if layout != "mixed-unchunked":
        chunks = len(_chunk_indexes(path))
        assert chunks > 10
    fast, slow = _read_both_paths(monkeypatch, path, topics)
    assert sorted(fast.channels) == sorted(slow.channels) and fast.channels
    for name, channel in fast.channels.items():
        np.testing.assert_array_equal(channel.t, slow.channels[name].t)
        np.testing.assert_array_equal(channel.values, slow.channels[name].values)
    assert [(s.what, s.why, s.count) for s in fast.source.skipped] == [
        (s.what, s.why, s.count) for s in slow.source.skipped
    ]
    if layout.startswith("mixed"):
        assert ("/mix", "message bytes do not decode", 57) in [(s.what, s.why, s.count) for s in fast.source.skipped]
        assert fast.channels["/mix/v[2]"].values.size == 400 // 4 - 15
    else:
        assert set(fast.channels) == {"/imu/accel.x", "/imu/accel.y", "/imu/accel.z"}


def _chunk_indexes(path: Path) -> list:
    from mcap.reader import make_reader

    with open(path, "rb") as fh:
        return make_reader(fh).get_summary().chunk_indexes


# --------------------------------------------------------------------------------------------
# metadata without the messages: the summary's metadata index, else the walk

SAMPLE_LOGS = sorted((Path(__file__).resolve().parents[1] / "sample_logs").glob("*.mcap"))


def _no_walk(monkeypatch) -> None:
    import logscan.readers.mcap.metadata as metadata

    def walked(*args, **kwargs):
        raise AssertionError("the whole file was walked")

    monkeypatch.setattr(metadata, "scan_file", walked)


@pytest.mark.parametrize("path", SAMPLE_LOGS, ids=lambda p: p.stem)
def test_metadata_of_sample_logs_comes_from_the_summary_index(path, monkeypatch):
    from logscan.readers import read_embedded_profile
    from logscan.readers.mcap import read_mcap_metadata

    expected = read_mcap(path, set())
    _no_walk(monkeypatch)
    metadata = read_mcap_metadata(path)
    assert metadata == expected.source.metadata
    if path.name == "ros2_ins.mcap":  # a ROS 2 recording: no truth, no profile (it gets the built-in one)
        assert metadata == {} and expected.profile_text is None
        return
    assert set(metadata) == {"logscan.truth", "logscan.profile"}
    assert read_embedded_profile(path) == expected.profile_text
    assert "[vehicle]" in expected.profile_text


def test_metadata_matches_the_walk_on_every_conformance_file():
    from logscan.readers.mcap import read_mcap_metadata

    need_testdata(CONFORMANCE)
    for path in CONFORMANCE_FILES:
        assert read_mcap_metadata(path) == read_mcap(path, set()).source.metadata, path.name


def test_metadata_of_a_truncated_file_comes_from_the_walk(valid_file, tmp_path):
    from logscan.readers.mcap import read_mcap_metadata

    _, data, _ = valid_file
    for cut in [len(data) // 2, len(data) - 9, len(data) - 40]:
        cut_path = tmp_path / f"cut{cut}.mcap"
        cut_path.write_bytes(data[:cut])
        assert read_mcap_metadata(cut_path) == {"logscan.truth": {"json": '{"events": []}'}}
    early = tmp_path / "early.mcap"
    early.write_bytes(data[: data.index(b"\x06", data.index(b"logscan.truth"))])  # before any chunk
    with pytest.raises(CorruptLogError, match="no messages could be recovered") as caught:
        read_mcap_metadata(early)
    assert str(early) in caught.value.one_line()
    with pytest.raises(CorruptLogError, match="magic"):
        read_mcap_metadata(_write(tmp_path / "magic.mcap", b"\x89MCAX0\r\n" + data[8:]))


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def test_a_summary_that_fails_its_checks_is_not_trusted(valid_file, tmp_path, monkeypatch):
    from logscan.readers.mcap import read_mcap_metadata

    _, data, _ = valid_file
    expected = {"logscan.truth": {"json": '{"events": []}'}}
    assert read_mcap_metadata(_write(tmp_path / "ok.mcap", data)) == expected
    index_at = data.rindex(b"logscan.truth")  # the name in the summary's MetadataIndex record
    renamed = bytearray(data)
    renamed[index_at] ^= 0x20
    crc_off = bytearray(renamed)
    crc_off[-12:-8] = b"\0\0\0\0"  # summary_crc 0: not checked, the name check must catch it
    for variant in (renamed, crc_off):
        assert read_mcap_metadata(_write(tmp_path / "v.mcap", bytes(variant))) == expected  # walked
    with monkeypatch.context() as patch:
        _no_walk(patch)
        with pytest.raises(AssertionError, match="walked"):
            read_mcap_metadata(tmp_path / "v.mcap")
        assert read_mcap_metadata(tmp_path / "ok.mcap") == expected


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(position=st.floats(0.9, 1, exclude_max=True), xor=st.integers(1, 255))
def test_flipped_summary_byte_gives_the_metadata_or_a_corrupt_log_error(valid_file, tmp_path, position, xor):
    from logscan.readers.mcap import read_mcap_metadata

    data = valid_file[1]
    at = int(position * len(data))
    path = _write(tmp_path / "flip.mcap", data[:at] + bytes([data[at] ^ xor]) + data[at + 1 :])
    try:
        metadata = read_mcap_metadata(path)
    except CorruptLogError:
        return
    assert metadata == {"logscan.truth": {"json": '{"events": []}'}}


def test_embedded_profile_of_csv_and_ulog_logs(tmp_path):
    from logscan.readers import read_embedded_profile

    csv = Path(__file__).resolve().parents[1] / "sample_logs" / "quad_healthy.csv"
    if not csv.exists():
        pytest.skip("sample CSV absent")
    assert read_embedded_profile(csv) == csv.with_suffix(".profile.toml").read_text(encoding="utf-8")
    bare = _write(tmp_path / "bare.csv", b"time_s,x\n0,1\n0.1,2\n")
    assert read_embedded_profile(bare) is None
    ulogs = sorted((Path(__file__).resolve().parents[2] / "shared" / "testdata" / "px4-ulog").glob("*.ulg"))
    if ulogs:
        assert read_embedded_profile(ulogs[0]) is None


def test_exact_json_number_kernel_is_correctly_rounded_or_declines():
    import re

    from logscan.readers.decimal_float import decimal_number

    grammar = re.compile(r"-?(0|[1-9][0-9]*)(\.[0-9]+)?([eE][+-]?[0-9]+)?\Z")
    rng = np.random.default_rng(11)
    doubles = rng.integers(0, 2**63, size=3000, dtype=np.uint64).view(np.float64)
    tokens = [repr(float(x)) for x in doubles if np.isfinite(x)]
    tokens += [f"{x:.{d}g}" for x, d in zip(rng.normal(0, 100, 3000), rng.integers(1, 17, 3000))]
    tokens += [
        "0",
        "-0.0",
        "0e5",
        "1e22",
        "1e23",
        "1E+2",
        "1e-22",
        "9007199254740992",
        "9007199254740993",
        "00",
        "1.",
        ".5",
        "+1",
        "1e",
        "-",
        "01.5",
        "NaN",
        "-Infinity",
        "5e-324",
        "0.1",
        "0.3",
        "0.0012345678901234567",  # zeros after the point are not significant digits
        "-0.000000000000000000012345678901234567",
        "9999999999999999999",  # 19 digits, above 2**63
        "1.8446744073709551615e-7",
        "12345678901234567890",  # 20 digits: declined
        "123456789.12345678901",
    ]
    taken = 0
    for token in tokens:
        text = np.frombuffer(token.encode(), dtype=np.uint8)
        value, exact, stop = decimal_number(text, 0, text.size)
        if exact and stop == text.size:
            taken += 1
            assert grammar.match(token), token
            assert np.float64(value).tobytes() == np.float64(float(token)).tobytes(), token
        elif not exact:
            assert np.isnan(value)
    assert taken > 5500  # the short decimals loggers write and 17-digit repr floats take the exact path
    text = np.frombuffer(b"1.5 -2 1e400 7 ", dtype=np.uint8)  # a token ends where the number stops
    assert decimal_number(text, 0, text.size)[1:] == (True, 3)
    assert decimal_number(text, 4, text.size)[1:] == (True, 6)
    assert decimal_number(text, 7, text.size)[1] is False  # 1e400: beyond float64, declined
    for token, taken_here in ((b"9999999999999999999", True), (b"12345678901234567890", False)):
        assert decimal_number(np.frombuffer(token, dtype=np.uint8), 0, len(token))[1] is taken_here


@pytest.mark.parametrize("stream_goes_back", [False, True])
def test_a_topic_on_two_channels_is_out_of_order_only_if_a_channel_is(tmp_path, stream_goes_back):
    """Two channels of one topic interleave in the file; each channel's batch is decoded together,
    so the pieces join out of order although the file is in order: sorted without a warning then,
    with one when a channel's own messages go back in time (read and inspected alike)."""
    path = tmp_path / "two.mcap"
    firsts = [10, 30, 50, 70] if not stream_goes_back else [10, 50, 30, 70]
    with open(path, "wb") as fh:
        writer = Writer(fh, compression=CompressionType.NONE)
        writer.start()
        schema = writer.register_schema("Thing", "jsonschema", b"{}")
        one, two = (writer.register_channel("/a", "json", schema) for _ in range(2))
        for t in firsts:
            writer.add_message(one, t, json.dumps({"x": t}).encode(), t)
            writer.add_message(two, t + 10, json.dumps({"x": t + 10}).encode(), t + 10)
        writer.finish()
    log = read_mcap(path, None)
    assert log.channels["/a/x"].t.tolist() == list(range(10, 90, 10))
    assert log.channels["/a/x"].values.tolist() == list(range(10, 90, 10))
    inspected, _ = inspect_mcap(path, None)
    for source in (log.source, inspected.source):
        warned = [w for w in source.warnings if "not in time order" in w]
        assert warned == (
            ["1 channel(s) not in time order in the file, sorted by time: /a/x"] if stream_goes_back else []
        )
