"""ULog reader on real PX4 logs: naming, metadata, topic filter, damaged files, ulog2csv round trip."""

from __future__ import annotations

import contextlib
import io
import struct
from pathlib import Path

import numpy as np
import pytest
from conftest import need_testdata

from logscan.errors import CorruptLogError, LogscanError
from logscan.readers import read_log
from logscan.readers.csv_reader import read_csv_dir
from logscan.readers.ulog_reader import message_filter, read_ulog

ULOG_DIR = Path(__file__).resolve().parents[2] / "shared" / "testdata" / "px4-ulog"
ULOGS = sorted(ULOG_DIR.glob("*.ulg")) if ULOG_DIR.is_dir() else []


def ulog(name: str) -> Path:
    path = ULOG_DIR / name
    need_testdata(path)
    return path


@pytest.fixture(scope="module")
def small_log():
    return read_ulog(ulog("sample_log_small.ulg"), None)


@pytest.mark.testdata("px4-ulog")
@pytest.mark.parametrize("path", ULOGS, ids=lambda p: p.name)
def test_every_real_log_reads_fully_with_named_topics_and_channels(path):
    log = read_log(path)
    assert log.source.format == "ulog" and not log.source.partial
    assert log.source.topics and log.channels
    for name, info in log.source.topics.items():
        base, _, instance = name.rpartition("_")
        assert instance.isdigit() and base == info.schema
        assert info.message_count >= 0
        for field in info.fields:
            assert f"/{name}/{field}" in log.channels
    for channel in log.channels.values():
        assert channel.t.dtype == np.int64 and channel.values.dtype == np.float64
        assert len(channel) == log.source.topics[channel.name.split("/")[1]].message_count
    assert 1.0 < log.duration_s < 1300.0


def test_channels_have_array_names_and_times_in_ns(small_log):
    imu = [name for name in small_log.channels if name.startswith("/vehicle_imu_0/")]
    assert "/vehicle_imu_0/delta_velocity[2]" in imu
    ch = small_log.channel("/vehicle_imu_0/delta_velocity[2]")
    # PX4 timestamps are microseconds: every ns value is a multiple of 1000
    assert np.all(ch.t % 1000 == 0) and np.all(np.diff(ch.t) > 0)
    assert small_log.source.time_unit == "us"
    assert small_log.duration_s == pytest.approx(1192.94, abs=0.1)


def test_metadata_holds_system_info_parameters_dropouts_and_messages(small_log):
    meta = small_log.source.metadata
    assert meta["ulog.info"]["sys_name"] == "PX4"
    assert meta["ulog.info"]["ver_hw"] == "CUBEPILOT_CUBEORANGE"
    assert len(meta["ulog.parameters"]) == 980
    assert meta["ulog.log"]["dropouts"] == "1" and meta["ulog.log"]["dropout_total_ms"] == "30"
    assert meta["ulog.log"]["logged_messages"] == str(len(meta["ulog.messages"])) == "3"
    assert any("dropout" in w for w in small_log.source.warnings)


def test_timestamp_zero_messages_are_dropped_and_counted():
    log = read_ulog(ulog("sample_appended_multiple.ulg"), None)
    assert log.source.topics["sensor_preflight_0"].message_count == 0
    skipped = {s.what: s for s in log.source.skipped}
    assert skipped["messages of sensor_preflight_0"].count == 184
    assert log.start_ns > 0


def test_message_filter_maps_topics_and_channels_to_message_names():
    assert message_filter(None) is None
    assert message_filter({"vehicle_imu_0", "/vehicle_imu_1/accel[0]", "/battery_status_0"}) == [
        "battery_status",
        "vehicle_imu",
    ]


def test_only_wanted_topics_are_decoded():
    log = read_ulog(ulog("sample_log_small.ulg"), {"/vehicle_imu_1/delta_angle[0]"})
    assert list(log.source.topics) == ["vehicle_imu_1"]
    assert list(log.channels) == ["/vehicle_imu_1/delta_angle[0]"]
    whole_topic = read_ulog(ulog("sample_log_small.ulg"), {"vehicle_imu_1"})
    assert len(whole_topic.channels) == len(whole_topic.source.topics["vehicle_imu_1"].fields) > 5


def test_absent_wanted_topic_gives_a_warning_not_an_error():
    log = read_ulog(ulog("sample_log_small.ulg"), {"no_such_topic_0"})
    assert not log.channels
    assert any("none of the requested topics" in w for w in log.source.warnings)


# ---- damaged files ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def source_bytes():
    return ulog("sample_appended_multiple.ulg").read_bytes()


@pytest.mark.parametrize("fraction", [0.2, 0.5, 0.9, 0.999])
def test_truncated_log_is_a_partial_read_that_says_so(tmp_path, source_bytes, fraction):
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(source_bytes[: int(len(source_bytes) * fraction)])
    log = read_log(cut)
    full = read_log(ulog("sample_appended_multiple.ulg"))
    assert log.source.partial and "truncated" in log.source.partial_reason
    assert log.end_ns <= full.end_ns
    if fraction <= 0.5:  # the last 10 % of this file is an appended crash dump, not data
        samples = sum(len(c) for c in log.channels.values())
        assert samples < sum(len(c) for c in full.channels.values())


@pytest.mark.parametrize("length", [10, 200, 1460, 24336])
def test_log_cut_before_any_data_is_a_corrupt_log_error(tmp_path, source_bytes, length):
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(source_bytes[:length])
    with pytest.raises(CorruptLogError) as info:
        read_log(cut)
    assert "\n" not in info.value.one_line() and str(cut) in info.value.one_line()


@pytest.mark.parametrize("seed", range(6))
def test_flipped_bytes_never_raise_anything_but_logscan_errors(tmp_path, source_bytes, seed):
    rng = np.random.default_rng(seed)
    damaged = bytearray(source_bytes)
    for pos in rng.integers(16, len(damaged), 20):
        damaged[pos] ^= 0xFF
    path = tmp_path / "flipped.ulg"
    path.write_bytes(bytes(damaged))
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        try:
            log = read_log(path)
        except LogscanError:
            return
    assert out.getvalue() == "", "pyulog printed to stdout"
    damage_seen = log.source.partial or any(
        "may be damaged" in w or w.startswith("pyulog:") for w in log.source.warnings
    )
    # ULog has no checksums: a flip inside a float payload is invisible; flips in framing or
    # timestamps are reported (20 flips over 487 kB hit one of those in these seeds)
    assert damage_seen


def test_garbage_after_the_magic_is_reported(tmp_path, source_bytes):
    path = tmp_path / "garbage.ulg"
    rng = np.random.default_rng(1)
    path.write_bytes(source_bytes[:16] + rng.integers(0, 256, 5000, dtype=np.uint8).tobytes())
    try:
        log = read_log(path)
    except LogscanError as exc:
        assert "\n" not in exc.one_line()
    else:
        assert log.source.partial


def _message_offsets(data: bytes) -> list[tuple[int, int, str]]:
    """(offset, payload size, type) of every ULog message after the 16-byte file header."""
    out, pos = [], 16
    while pos + 3 <= len(data):
        size, kind = struct.unpack_from("<HB", data, pos)
        out.append((pos, size, chr(kind)))
        pos += 3 + size
    return out


def _total_messages(log) -> int:
    return sum(t.message_count for t in log.source.topics.values())


@pytest.mark.testdata("px4-ulog")
@pytest.mark.parametrize("size", [0, 0xFFFF])
@pytest.mark.parametrize("path", ULOGS, ids=lambda p: p.name)
def test_a_data_message_with_a_broken_size_field_makes_a_partial_read_that_says_how_much(tmp_path, path, size):
    data = bytearray(path.read_bytes())
    messages = [m for m in _message_offsets(data) if m[2] == "D"]
    offset = messages[len(messages) // 2][0]
    struct.pack_into("<H", data, offset, size)
    broken = tmp_path / "broken.ulg"
    broken.write_bytes(bytes(data))
    log, full = read_log(broken), read_log(path)
    assert log.source.partial, "half the flight dropped must not read as a complete log"
    reason = log.source.partial_reason
    assert ("framing" in reason or "corrupt" in reason) and "recovered" in reason and "busiest topic" in reason
    assert _total_messages(log) < _total_messages(full)


@pytest.mark.testdata("px4-ulog")
@pytest.mark.parametrize("path", ULOGS, ids=lambda p: p.name)
def test_a_log_cut_inside_a_message_at_any_of_several_offsets_is_partial(tmp_path, path):
    data = path.read_bytes()
    messages = [m for m in _message_offsets(data) if m[2] == "D"]
    full = _total_messages(read_log(path))
    for fraction in (0.1, 0.35, 0.6, 0.85, 0.999):
        offset, size, _ = messages[int(fraction * (len(messages) - 1))]
        for cut_at in {offset + 1, offset + 3 + size // 2}:  # in the header, in the payload
            cut = tmp_path / "cut.ulg"
            cut.write_bytes(data[:cut_at])
            log = read_log(cut)
            assert log.source.partial, (path.name, cut_at)
            assert "truncated" in log.source.partial_reason and "recovered" in log.source.partial_reason
            assert _total_messages(log) <= full


# ---- round trip through pyulog's ulog2csv --------------------------------------------------------


@pytest.mark.parametrize("name", ["sample_appended_multiple.ulg", "sample_logging_tagged_and_default_params.ulg"])
def test_ulog2csv_directory_reads_to_the_same_channels_and_values(tmp_path, name):
    from pyulog.ulog2csv import convert_ulog2csv

    path = ulog(name)
    out = tmp_path / "csv"
    out.mkdir()
    with contextlib.redirect_stdout(io.StringIO()):
        convert_ulog2csv(str(path), None, str(out), ",", None, None)
    from_ulog = read_log(path)
    from_csv = read_csv_dir(out, None)
    assert set(from_csv.source.topics) == set(from_ulog.source.topics)
    assert set(from_csv.channels) == set(from_ulog.channels)
    assert from_csv.source.time_unit == "us"
    for name_, channel in from_ulog.channels.items():
        other = from_csv.channels[name_]
        np.testing.assert_array_equal(other.t, channel.t, err_msg=name_)
        # ulog2csv prints float32 values with str(): equal once both are float32
        np.testing.assert_allclose(
            other.values.astype(np.float32),
            channel.values.astype(np.float32),
            rtol=1e-6,
            atol=0,
            equal_nan=True,
            err_msg=name_,
        )


@pytest.mark.testdata("px4-ulog")
def test_the_fields_of_a_read_topic_left_out_are_named_for_a_misspelt_profile_channel():
    """A profile naming one field of a topic reads only it; the others stay known by name
    (`SourceInfo.unread`), so a misspelt field is matched against them too."""
    from logscan.profiles.problems import suggest_channel

    path = need_testdata("px4-ulog/sample_log_small.ulg")
    log = read_log(path, topics={"/vehicle_attitude_0/q[1]"})
    assert list(log.channels) == ["/vehicle_attitude_0/q[1]"]
    assert "/vehicle_attitude_0/q[0]" in log.source.unread and "/vehicle_attitude_0/q[1]" not in log.source.unread
    assert "'/vehicle_attitude_0/q[0]'" in suggest_channel("/vehicle_attitude_0/qq[0]", log.source.unread)
