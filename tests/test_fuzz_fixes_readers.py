"""Reader fixes for bugs the fuzzing campaign found (tests/fuzz_regressions/README.md): each test
names its bug id and checks the exit code and the message the user sees."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import one_state_profile

from logscan.errors import CorruptLogError
from logscan.readers import read_log
from logscan.readers.flatten import flatten_messages
from logscan.readers.json_decoder import json_columns
from logscan.readers.mcap import iter_raw_messages

REGRESSIONS = Path(__file__).resolve().parent / "fuzz_regressions"
HUGE = "1" + "0" * 400  # beyond float range (~1.8e308)
HUGE_WHY = "integer beyond float range (read as NaN)"


# -- json-huge-integer -------------------------------------------------------------------------------


def test_a_json_integer_beyond_float_range_is_a_counted_nan_on_every_path():
    """Fast (template) path, generic path, first message or a later one: NaN, counted, never inf or
    an OverflowError; a float literal beyond range (1e400) stays what json.loads makes it (inf)."""
    one = b'{"a": 1.5, "b": 2}'
    huge = b'{"a": 2.5, "b": ' + HUGE.encode() + b"}"
    negative = b'{"a": 3.5, "b": -' + HUGE.encode() + b"}"
    written_inf = b'{"a": 4.5, "b": 1e400}'
    for messages in ([one, huge, written_inf, negative], [huge, one], [huge, huge], [huge]):
        flat, failed = json_columns(messages)
        assert failed == []
        b = flat.columns["b"][1]
        expected = [np.nan if m in (huge, negative) else json.loads(m)["b"] for m in messages]
        np.testing.assert_array_equal(b, expected)
        assert flat.skipped == {("b", HUGE_WHY): sum(m in (huge, negative) for m in messages)}
    flat = flatten_messages([json.loads(one), json.loads(huge)])  # decoded messages (other encodings)
    np.testing.assert_array_equal(flat.columns["b"][1], [2.0, np.nan])
    assert flat.skipped == {("b", HUGE_WHY): 1}


def test_json_huge_integer_reproducer_analyses_without_error(cli_process):
    """`json-huge-integer`: was OverflowError, exit 3."""
    path = REGRESSIONS / "json_huge_integer.mcap"
    result = cli_process("analyze", path, "--no-report", "--json", "-")
    assert result.exit_code == 0, result.stderr
    assert "Error" not in result.stderr and "Warning" not in result.stderr  # no traceback, no numpy warning
    entry = json.loads(result.stdout)["logs"][0]
    assert {"what": "/cmd/thrust", "why": HUGE_WHY, "count": 1} in entry["log"]["skipped"]
    assert not entry["log"]["partial"]
    assert np.isnan(read_log(path).channels["/cmd/thrust"].values).sum() == 1


# -- ulog-missing-timestamp --------------------------------------------------------------------------

UNTIMED_WHY = "its message format has no timestamp field, which the ULog spec requires: the definition is damaged"
LINEAR_PROFILE = one_state_profile("/act_0/thrust", "/acc_0/z", "untimed topic")


def _ulog(topics: list[tuple[str, str]], n: int = 400) -> bytes:
    """A ULog: header, flag bits, one format and subscription per (name, fields) and ``n`` data
    messages of each at 100 Hz, interleaved; every format is a uint64 then a float."""
    import math
    import struct

    def message(kind: str, body: bytes) -> bytes:
        return struct.pack("<HB", len(body), ord(kind)) + body

    out = b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0) + message("B", bytes(40))
    out += b"".join(message("F", f"{name}:{fields}".encode()) for name, fields in topics)
    out += b"".join(message("A", struct.pack("<BH", 0, i) + name.encode()) for i, (name, _) in enumerate(topics))
    for k in range(n):
        for i in range(len(topics)):
            out += message("D", struct.pack("<HQf", i, 1_000_000 + 10_000 * k, math.sin(k / 10)))
    return out


def test_ulog_missing_timestamp_reproducer_is_a_one_line_error(cli):
    """`ulog-missing-timestamp`: was KeyError 'timestamp', exit 3; its only topic has no timestamp."""
    path = REGRESSIONS / "ulog_missing_timestamp.ulg"
    result = cli("inspect", path)
    assert result.exit_code == 2
    assert result.stderr.strip() == (
        f"logscan: error: {path}: no data to read: topic sensor_combined_0 skipped, {UNTIMED_WHY} "
        "(re-export or re-record the log)"
    )


def test_a_ulog_topic_without_timestamp_is_skipped_and_the_rest_read_as_partial(cli, tmp_path):
    """Its data come first in the file: pyulog alone stops reading there and loses the other topic."""
    path = tmp_path / "untimed.ulg"
    path.write_bytes(_ulog([("acc", "uint64_t time_stamp;float z;"), ("act", "uint64_t timestamp;float thrust;")]))
    log = read_log(path)
    assert list(log.source.topics) == ["act_0"] and log.source.topics["act_0"].message_count == 400
    assert log.source.partial and f"topic acc_0 not read: {UNTIMED_WHY}" in log.source.partial_reason
    assert log.source.warnings == [f"topic acc_0 skipped: {UNTIMED_WHY}"]
    assert [(s.what, s.why, s.count) for s in log.source.skipped] == [("topic acc_0", UNTIMED_WHY, 400)]
    result = cli("inspect", path)
    assert result.exit_code == 0 and "PARTIAL" in result.stdout and "topic acc_0 skipped" in result.stdout


def test_a_ulog_missing_the_profiles_topic_for_lack_of_timestamp_is_never_no_alarms(cli, tmp_path):
    profile = tmp_path / "linear.toml"
    profile.write_text(LINEAR_PROFILE)
    intact = tmp_path / "intact.ulg"
    intact.write_bytes(_ulog([("acc", "uint64_t timestamp;float z;"), ("act", "uint64_t timestamp;float thrust;")]))
    assert cli("analyze", intact, "--profile", profile, "--no-report").exit_code == 0
    for untimed, topic in (("acc", "acc_0"), ("act", "act_0")):
        path = tmp_path / f"no_{untimed}_timestamp.ulg"
        fields = {"acc": "uint64_t timestamp;float z;", "act": "uint64_t timestamp;float thrust;"}
        fields[untimed] = fields[untimed].replace("timestamp", "time_stamp")
        path.write_bytes(_ulog(list(fields.items())))
        result = cli("analyze", path, "--profile", profile, "--no-report", "--json", "-")
        assert result.exit_code == 2, result.stderr
        assert "no alarms" not in result.stdout
        assert f"'/{topic}/" in result.stderr  # the profile's channel that the log lacks


# -- mcap-chunk-skipped ------------------------------------------------------------------------------


def _records(data: bytes) -> list[tuple[int, int, int]]:
    """(opcode, record start, record end) of the top-level records, up to the footer."""
    import struct

    out, pos = [], 8
    while pos + 9 <= len(data):
        op, length = struct.unpack_from("<BQ", data, pos)
        out.append((op, pos, pos + 9 + length))
        pos += 9 + length
        if op == 0x02:
            break
    return out


def _imu_mcap() -> bytes:
    """2 s of one 200 Hz topic in 4 KiB chunks, without metadata: data-section CRC and Statistics."""
    from logscan.readers.mcap.writer import TopicData, mcap_bytes

    t = np.arange(400, dtype=np.int64) * 5_000_000
    topic = TopicData("Imu", t, {"accel.x": np.sin(t / 1e9), "accel.y": np.cos(t / 1e9)})
    return mcap_bytes({"/imu": topic}, chunk_size=4 * 1024)


def _set_data_crc(data: bytearray, crc: int | None = None) -> None:
    """Set the DataEnd record's CRC to ``crc``, or to the CRC of the (edited) data section."""
    import struct
    import zlib

    (data_end,) = [start for op, start, _end in _records(bytes(data)) if op == 0x0F]
    struct.pack_into("<I", data, data_end + 9, zlib.crc32(bytes(data[:data_end])) if crc is None else crc)


def test_mcap_chunk_opcode_reproducer_is_partial_never_no_alarms(cli):
    """`mcap-chunk-skipped`: a chunk's opcode 0x06 -> 0x86 was skipped with a warning: exit 0, "no alarms"."""
    path = REGRESSIONS / "mcap_chunk_opcode.mcap"
    profile = REGRESSIONS / "mcap_chunk_opcode.toml"
    result = cli("analyze", path, "--profile", profile, "--no-report", "--json", "-")
    assert result.exit_code == 2, result.stderr
    entry = json.loads(result.stdout)["logs"][0]
    assert entry["log"]["partial"] and "not fully checked" in entry["verdict"]
    reason = entry["log"]["partial_reason"]
    assert reason.startswith("data section CRC mismatch (DataEnd record at byte 197596)")
    assert "counts 1920 messages in 19 chunks, the data section holds 1816 in 18" in reason
    assert "the record at byte 94042 has the private-use opcode 0x86" in reason
    assert "recovered 1816 messages" in reason
    assert not any("CRC" in warning for warning in entry["log"]["warnings"])


def test_a_chunk_skipped_for_its_opcode_makes_the_mcap_read_partial(tmp_path):
    data = _imu_mcap()
    chunks = [start for op, start, _end in _records(data) if op == 0x06]
    assert len(chunks) >= 3
    intact = tmp_path / "intact.mcap"
    intact.write_bytes(data)
    whole = read_log(intact)
    assert not whole.source.partial and len(whole.channels["/imu/accel.x"]) == 400
    damaged = bytearray(data)
    damaged[chunks[1]] = 0x86  # the middle chunk now reads as a private record
    path = tmp_path / "opcode.mcap"
    path.write_bytes(bytes(damaged))
    log = read_log(path)
    kept = len(log.channels["/imu/accel.x"])
    assert log.source.partial and kept < 400
    assert "data section CRC mismatch" in log.source.partial_reason
    assert f"counts 400 messages in {len(chunks)} chunks, the data section holds {kept}" in log.source.partial_reason
    assert f"the record at byte {chunks[1]} has the private-use opcode 0x86" in log.source.partial_reason
    # without a data-section CRC the Statistics record still shows it
    _set_data_crc(damaged, 0)
    path.write_bytes(bytes(damaged))
    log = read_log(path)
    assert log.source.partial and "data section CRC" not in log.source.partial_reason
    assert f"counts 400 messages in {len(chunks)} chunks" in log.source.partial_reason
    with pytest.raises(CorruptLogError, match="counts 400 messages"):
        list(iter_raw_messages(path))  # the strict view refuses it too


def test_a_private_record_with_matching_crc_and_statistics_is_skipped_and_the_read_whole(tmp_path):
    """Opcodes 0x80-0xff are the spec's private records: skipped, not damage, when nothing says otherwise."""
    import struct
    import zlib

    data = _imu_mcap()
    (data_end,) = [start for op, start, _end in _records(data) if op == 0x0F]
    private = bytes([0x86]) + struct.pack("<Q", 5) + b"hello"  # before DataEnd: no chunk moves
    edited = bytearray(data[:data_end] + private + data[data_end:])
    _set_data_crc(edited)
    shift = len(private)  # the summary moved: its offsets, in the SummaryOffset records and the footer
    for op, start, _end in _records(bytes(edited)):
        if op == 0x0E:
            (group_start,) = struct.unpack_from("<Q", edited, start + 10)
            struct.pack_into("<Q", edited, start + 10, group_start + shift)
    footer = len(edited) - 8 - 29  # summary_start, summary_offset_start, summary_crc
    summary_start, offsets_start, _crc = struct.unpack_from("<QQI", edited, footer + 9)
    struct.pack_into("<QQ", edited, footer + 9, summary_start + shift, offsets_start + shift)
    struct.pack_into("<I", edited, footer + 25, zlib.crc32(bytes(edited[summary_start + shift : footer + 25])))
    path = tmp_path / "private.mcap"
    path.write_bytes(bytes(edited))
    log = read_log(path)
    assert not log.source.partial and log.source.warnings == []
    assert len(log.channels["/imu/accel.x"]) == 400
    assert len(list(iter_raw_messages(path))) == 400
    from mcap.reader import SeekingReader  # the file is valid for the mcap library too

    with open(path, "rb") as fh:
        reader = SeekingReader(fh, validate_crcs=True)
        assert reader.get_summary().statistics.message_count == sum(1 for _ in reader.iter_messages()) == 400


def test_a_header_stamp_beyond_int64_nanoseconds_keeps_the_log_time(tmp_path):
    """--header-stamp: a stamp of 1e300 s, inf or NaN used to become a junk time and a numeric
    warning; now that message keeps its log_time and the skip is counted."""
    from mcap.writer import Writer

    from logscan.readers.mcap import read_mcap

    path = tmp_path / "stamped.mcap"
    with open(path, "wb") as fh:
        writer = Writer(fh)
        writer.start()
        schema = writer.register_schema("S", "jsonschema", b"{}")
        channel = writer.register_channel("/v", "json", schema)
        for k in range(50):
            sec = {10: "1e300", 11: "Infinity", 12: "NaN"}.get(k, str(100 + k))
            text = f'{{"header": {{"stamp": {{"sec": {sec}, "nanosec": 5}}}}, "x": {k}}}'
            writer.add_message(channel, 1_000 + k, text.encode(), 1_000 + k)
        writer.finish()
    log = read_mcap(path, None, use_header_stamp=True)
    t = log.channels["/v/x"].t
    assert 100 * 1_000_000_000 + 5 in t.tolist()  # the first message's stamp
    assert {1_010, 1_011, 1_012} <= set(t.tolist())  # the three bad stamps kept their log_time
    assert t.size == 50
    skipped = {s.what: s for s in log.source.skipped}
    assert skipped["/v header.stamp"].count == 3
