"""A window of an indexed MCAP file decodes only the chunks it needs (`logscan.readers.mcap.window`)
and aligns to exactly what the whole read gives the same window; a file without message indexes is
read whole. The files are a sample log rewritten by the mcap library in small chunks."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import need_testdata
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType, Writer

from logscan.align import align
from logscan.errors import LogscanError
from logscan.profiles import parse_profile
from logscan.readers import read_embedded_profile, read_log
from logscan.readers.common import MCAP_MAGIC, ReadWindow
from logscan.readers.mcap.records import OP_MESSAGE_INDEX, walk_records
from logscan.readers.mcap.scan import Scan
from logscan.readers.mcap.window import _record_times

MARGIN_S = 5.02  # what `analyze` gives a 100 Hz profile (MAX_DELAY_S + two steps)
S = 1_000_000_000  # ns


def rewrite(
    source: Path,
    target: Path,
    *,
    message_index: bool = True,
    edit=lambda topic, n, t, data: [(t, data)],
    metadata: dict | None = None,
):
    """``source`` written again by the mcap library in 16 KiB chunks (with or without Message
    Index records), its metadata kept (and ``metadata``'s records added); ``edit(topic, n,
    log_time, data)`` gives the (log_time, data) messages written for a topic's n-th message
    (none: dropped)."""
    index = IndexType.ALL if message_index else IndexType.ALL & ~IndexType.MESSAGE
    with open(source, "rb") as fin, open(target, "wb") as fout:
        reader = make_reader(fin)
        writer = Writer(fout, chunk_size=16 * 1024, compression=CompressionType.LZ4, index_types=index)
        writer.start(profile="", library="test")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        seen: dict[str, int] = {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                sid = schemas[schema.id] if schema is not None else 0
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, sid, dict(channel.metadata)
                )
            n = seen[channel.topic] = seen.get(channel.topic, -1) + 1
            for log_time, data in edit(channel.topic, n, message.log_time, message.data):
                writer.add_message(channels[channel.id], log_time, data, message.publish_time, message.sequence)
        fin.seek(0)
        for record in make_reader(fin).iter_metadata():
            writer.add_metadata(record.name, dict(record.metadata))
        for name, values in (metadata or {}).items():
            writer.add_metadata(name, values)
        writer.finish()


def mode_once(topic, n, t, data):
    """The flight mode logged once, at the start."""
    return [] if topic == "/flight_mode" and n else [(t, data)]


def late_but_first_command(ns: int):
    """Every message ``ns`` late but the first command."""
    return lambda topic, n, t, data: [(t + (0 if (topic, n) == ("/cmd", 0) else ns), data)]


@pytest.fixture(scope="module")
def chunked(tmp_path_factory) -> dict[str, Path]:
    source = Path(__file__).resolve().parent.parent / "sample_logs" / "quad_healthy.mcap"
    if not source.exists():
        pytest.skip(f"{source} missing (run sample_logs/make_samples.py)")
    folder = tmp_path_factory.mktemp("window")
    files = {name: folder / f"{name}.mcap" for name in ("indexed", "unindexed", "one_mode", "off_phase")}
    files["source"] = source
    rewrite(source, files["indexed"])
    rewrite(source, files["unindexed"], message_index=False)
    # the flight mode logged once, at the start: a window far later holds it from a chunk of its own
    rewrite(
        source, files["one_mode"], edit=lambda topic, n, t, data: [] if topic == "/flight_mode" and n else [(t, data)]
    )
    # every message 3 ms late but the first command: the grid keeps that one's phase, which no
    # sample inside a window has
    rewrite(
        source,
        files["off_phase"],
        edit=lambda topic, n, t, data: [(t + (3_000_000 if (topic, n) != ("/cmd", 0) else 0), data)],
    )
    return files


def profile_of(path: Path, mode_stale_s: str | None = None):
    text = read_embedded_profile(path)
    if mode_stale_s is not None:  # the flight mode held as long as it says
        text = text.replace('channel = "/flight_mode/mode"', f'channel = "/flight_mode/mode"\nstale_s = {mode_stale_s}')
    return parse_profile(text, source=str(path))


def decoded(log) -> int:
    return sum(len(channel) for channel in log.channels.values())


def assert_same_run(path: Path, start_s: float | None, end_s: float | None, profile=None) -> tuple:
    """The whole read and the window's read of ``path``, aligned on the window: the same run."""
    profile = profile or profile_of(path)
    whole = read_log(path, topics=profile.topics())
    window = read_log(path, topics=profile.topics(), window=ReadWindow(start_s, end_s, MARGIN_S))
    assert window.start_ns == whole.start_ns and window.end_ns == whole.end_ns
    a = align(whole, profile, start_s=start_s, end_s=end_s)
    b = align(window, profile, start_s=start_s, end_s=end_s)
    assert a.start_ns == b.start_ns
    for name in ("t", "u", "u_fresh", "mode", "ground", "onboard_state", "onboard_variance"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.groups.keys() == b.groups.keys()
    for name, group in a.groups.items():
        np.testing.assert_array_equal(group.z, b.groups[name].z, err_msg=name)
        np.testing.assert_array_equal(group.fresh, b.groups[name].fresh, err_msg=name)
    assert a.warnings == b.warnings and a.gaps == b.gaps
    return whole, window


def test_the_files_are_chunked_and_only_one_is_indexed(chunked):
    scans = {name: Scan(str(path), None) for name, path in chunked.items() if name != "source"}
    for scan in scans.values():
        scan.plan = lambda scan, u8, top: None
        scan.run()
        assert scan.chunks_read > 20  # many chunks: a window has some to skip
    with open(chunked["unindexed"], "rb") as fh:
        assert not any(index.message_index_offsets for index in make_reader(fh).get_summary().chunk_indexes)


@pytest.mark.parametrize("start_s, end_s", [(20.0, 30.0), (None, 12.0), (45.0, None), (0.0, 60.0)])
def test_a_window_aligns_as_the_whole_read_does(chunked, start_s, end_s):
    whole, window = assert_same_run(chunked["indexed"], start_s, end_s)
    if (start_s, end_s) == (20.0, 30.0):  # 10 s and the margins of 60 s: well under half decoded
        assert decoded(window) < 0.5 * decoded(whole)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(start=st.floats(0.0, 55.0), length=st.floats(0.05, 30.0))
def test_any_window_aligns_as_the_whole_read_does(chunked, start, length):
    assert_same_run(chunked["indexed"], start, start + length)


@pytest.mark.parametrize("start_s, end_s", [(20.0, 30.0), (45.0, None)])
def test_a_window_keeps_the_whole_logs_grid_phase(chunked, start_s, end_s):
    whole, window = assert_same_run(chunked["off_phase"], start_s, end_s)
    run = align(window, profile_of(chunked["off_phase"]), start_s=start_s, end_s=end_s)
    assert run.start_ns == 0 and np.allclose(run.t[0] * 100 % 1, 0)  # on the first command's lattice
    # the chunks read hold the first command (time zero is checked on it) and samples 3 ms late
    assert all(np.all(c.t[c.t > 0] % 10_000_000 == 3_000_000) for c in window.channels.values())
    assert window.whole_times and decoded(window) < 0.5 * decoded(whole)


def test_a_mode_logged_once_is_held_into_a_late_window(chunked):
    profile = profile_of(chunked["one_mode"], mode_stale_s="inf")
    assert profile.mode.stale_s == float("inf")
    whole, window = assert_same_run(chunked["one_mode"], 40.0, 50.0, profile)
    assert len(window.channels["/flight_mode/mode"]) == 1  # its one sample, from the first chunk
    run = align(window, profile, start_s=40.0, end_s=50.0)
    assert run.mode is not None and np.isfinite(run.mode).all()


def test_a_file_without_message_indexes_is_read_whole(chunked):
    profile = profile_of(chunked["unindexed"])
    whole = read_log(chunked["unindexed"], topics=profile.topics())
    window = read_log(chunked["unindexed"], topics=profile.topics(), window=ReadWindow(20.0, 30.0, MARGIN_S))
    assert decoded(window) == decoded(whole)
    assert window.whole_times == {}


def test_header_stamps_read_the_whole_file(chunked):
    profile = profile_of(chunked["indexed"])
    whole = read_log(chunked["indexed"], topics=profile.topics(), use_header_stamp=True)
    window = read_log(
        chunked["indexed"], topics=profile.topics(), use_header_stamp=True, window=ReadWindow(20.0, 30.0, MARGIN_S)
    )
    assert decoded(window) == decoded(whole)


def test_analyze_gives_a_window_the_summary_of_the_whole_read(chunked, cli, tmp_path):
    """The indexed file's window is read in part, the unindexed one's whole: the same summary."""
    summaries = {}
    for name in ("indexed", "unindexed"):
        out = tmp_path / f"{name}.json"
        result = cli("analyze", chunked[name], "--start", "20", "--end", "35", "--no-report", "--json", out)
        assert result.exit_code in (0, 1), result.stderr
        summaries[name] = out.read_text(encoding="utf-8").replace(str(chunked[name]), "LOG")
    assert summaries["indexed"] == summaries["unindexed"]
    assert json.loads(summaries["indexed"])["logs"][0]["filter"]["steps"] == 1501  # 20 .. 35 s at 100 Hz


def test_a_wanted_topic_no_decoder_takes_is_counted_whole(tmp_path):
    """Its messages are counted from the index, as the whole read counts them, not those of the
    chunks read."""
    path = tmp_path / "blob.mcap"
    with open(path, "wb") as fh:
        writer = Writer(fh, chunk_size=4096, compression=CompressionType.NONE)
        writer.start(profile="", library="test")
        json_schema = writer.register_schema("Speed", "jsonschema", b'{"type": "object"}')
        speed = writer.register_channel("/speed", "json", json_schema)
        blob = writer.register_channel("/blob", "x-unknown", 0)
        for k in range(2000):  # 20 s at 100 Hz
            t = k * 10_000_000
            writer.add_message(speed, t, json.dumps({"v": k * 0.01}).encode(), t)
            writer.add_message(blob, t, b"\x00\x01", t)
        writer.finish()
    whole = read_log(path, topics={"/speed", "/blob"})
    window = read_log(path, topics={"/speed", "/blob"}, window=ReadWindow(8.0, 9.0, 0.5))
    assert decoded(window) < 0.3 * decoded(whole)
    assert [s.to_dict() for s in window.source.skipped] == [s.to_dict() for s in whole.source.skipped]
    assert [s.count for s in whole.source.skipped if s.what == "/blob"] == [2000]
    assert window.source.warnings == whole.source.warnings
    assert window.source.topics["/blob"].message_count == 2000


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(picks=st.lists(st.tuples(st.floats(0.0, 1.0), st.integers(0, 255)), min_size=1, max_size=8))
def test_a_damaged_message_index_is_data_not_a_crash(chunked, tmp_path_factory, picks):
    """Bytes of the Message Index records overwritten at random: the window's read gives a log or
    one LogscanError, never another exception."""
    data = bytearray(chunked["indexed"].read_bytes())
    top = walk_records(np.frombuffer(bytes(data), dtype=np.uint8), len(MCAP_MAGIC), len(data))
    at = top.offsets[top.ops == OP_MESSAGE_INDEX]
    lengths = top.lengths[top.ops == OP_MESSAGE_INDEX]
    for where, value in picks:
        k = min(int(where * at.size), at.size - 1)
        data[int(at[k]) + int(where * 7919) % int(lengths[k])] = value
    path = tmp_path_factory.mktemp("damaged") / "damaged.mcap"
    path.write_bytes(bytes(data))
    profile = profile_of(chunked["indexed"])
    try:
        log = read_log(path, topics=profile.topics(), window=ReadWindow(20.0, 30.0, MARGIN_S))
    except LogscanError:
        return
    assert log.channels  # read, as its index (or the whole file) gives it


def edited(chunked, tmp_path, edit) -> Path:
    path = tmp_path / "edited.mcap"
    rewrite(chunked["source"], path, edit=edit)
    return path


def test_a_first_message_that_gives_no_sample_reads_the_file_whole(chunked, tmp_path):
    """Time zero is the first sample read: when the first message does not decode, the index's
    first time is not it, and the window is read whole."""
    first_bad = edited(
        chunked,
        tmp_path,
        lambda topic, n, t, data: [(t, b"{not json")] if (topic, n) == ("/cmd", 0) else [(t + S, data)],
    )
    whole, window = assert_same_run(first_bad, 20.0, 30.0)
    assert window.start_ns == S and window.whole_times == {}  # read whole
    assert [s.to_dict() for s in window.source.skipped] == [s.to_dict() for s in whole.source.skipped]


@pytest.mark.parametrize("last", [b'{"note": 1.0}', b'{"mode": NaN}'], ids=["field missing", "not finite"])
def test_a_mode_not_given_before_the_window_reads_the_file_whole(chunked, tmp_path, last):
    """The last mode message before the window lacks its field or holds NaN: the whole read holds
    the one before it, so the window is read whole."""

    def edit(topic, n, t, data):
        if topic != "/flight_mode":
            return [(t, data)]
        return {0: [(t, b'{"mode": 3.0}')], 100: [(t, last)], 550: [(t, b'{"mode": 4.0}')]}.get(n, [])

    path = edited(chunked, tmp_path, edit)
    whole, window = assert_same_run(path, 40.0, 50.0, profile_of(path, mode_stale_s="inf"))
    assert window.whole_times == {}
    run = align(window, profile_of(path, mode_stale_s="inf"), start_s=40.0, end_s=50.0)
    assert np.unique(run.mode).tolist() == [3.0]  # held from the start: the note at 10 s has no mode


def test_a_time_logged_twice_in_two_chunks_holds_the_later_sample(chunked, tmp_path):
    def edit(topic, n, t, data):
        if topic != "/flight_mode":
            return [(t, data)]
        return {0: [(10 * S, b'{"mode": 1.0}')], 300: [(10 * S, b'{"mode": 2.0}')]}.get(n, [])

    path = edited(chunked, tmp_path, edit)
    profile = profile_of(path, mode_stale_s="inf")
    whole, window = assert_same_run(path, 40.0, 50.0, profile)
    assert window.whole_times and np.unique(align(window, profile, start_s=40.0, end_s=50.0).mode).tolist() == [2.0]


def test_a_log_over_a_day_warns_once_as_the_whole_read_does(chunked, tmp_path):
    day = int(1.5 * 86400) * S

    def edit(topic, n, t, data):
        if topic == "/flight_mode":
            return [(t, data)] if n == 0 else []
        return [(t + day + (day // 3 if (topic, n) == ("/gps", 600) else 0), data)]

    path = edited(chunked, tmp_path, edit)
    whole, window = assert_same_run(path, 129_620.0, 129_630.0, profile_of(path, mode_stale_s="inf"))
    assert window.whole_times and window.source.warnings == whole.source.warnings
    assert sum("spans" in w for w in window.source.warnings) == 1


def test_analyze_reads_whole_a_window_whose_time_zero_is_an_outlier(chunked, cli, tmp_path):
    """Every message an hour late but the first command: alignment counts from the grid's start,
    not the index's first time, so the window is read again whole: the summary is the whole read's."""
    late = late_but_first_command(3600 * S)
    summaries = {}
    for name, index in (("indexed", True), ("unindexed", False)):
        path = tmp_path / f"{name}.mcap"
        rewrite(chunked["source"], path, message_index=index, edit=late)
        out = tmp_path / f"{name}.json"
        result = cli("analyze", path, "--start", "20", "--end", "30", "--no-report", "--json", out)
        assert result.exit_code in (0, 1), result.stderr
        summaries[name] = out.read_text(encoding="utf-8").replace(str(path), "LOG")
    assert summaries["indexed"] == summaries["unindexed"]
    assert json.loads(summaries["indexed"])["logs"][0]["filter"]["steps"] == 1001


@pytest.mark.parametrize("flags", [("--start", "1e300"), ("--end", "-1e300"), ("--start", "1e10")])
def test_a_window_beyond_any_log_is_a_usage_error(cli, sample, flags):
    """Seconds int64 nanoseconds cannot hold are refused in one line, for any log (they overflowed
    at the grid before, and the window's plan)."""
    for log in ("quad_healthy.mcap", "quad_healthy.csv"):
        result = cli("analyze", sample(log), *flags, "--no-report")
        assert result.exit_code == 2
        assert "is beyond any log" in result.stderr and "Traceback" not in result.stderr


def test_a_real_robots_string_fields_are_counted_as_the_whole_read_counts_them(tmp_path):
    """The husky's ROS 2 drive, rewritten in 16 KiB chunks: the frame ids (skipped, non-numeric)
    of every message are counted, not only those of the chunks read; its aligned run is the same."""
    source = need_testdata("ros-robots/robot_localization_test1_husky_ros2/robot_localization_test1_husky_ros2.mcap")
    path = tmp_path / "husky.mcap"
    rewrite(source, path)
    topics = {"/imu/data", "/husky_velocity_controller/odom", "/fix"}
    whole = read_log(path, topics=topics)
    window = read_log(path, topics=topics, window=ReadWindow(100.0, 130.0, MARGIN_S))
    assert window.whole_times and decoded(window) < 0.3 * decoded(whole)
    frame_ids = [s.to_dict() for s in whole.source.skipped if s.what.endswith("frame_id")]
    assert len(frame_ids) == 4 and [s.to_dict() for s in window.source.skipped] == [
        s.to_dict() for s in whole.source.skipped
    ]


def test_an_index_record_listing_no_message_reads_no_byte():
    """Its pairs end where the buffer may end (a truncated file): nothing is read from there."""
    u8 = np.full(6, 0xFF, dtype=np.uint8)  # a record head, and the buffer's end
    firsts, lasts = np.ones(2, dtype=np.uint64), np.ones(2, dtype=np.uint64)
    times = np.empty(1, dtype=np.int64)
    pairs = np.zeros(16, dtype=np.uint8)
    pairs[:8] = np.frombuffer(np.uint64(7).tobytes(), dtype=np.uint8)
    buffer = np.concatenate([pairs, u8])  # record 0: one pair at 0; record 1: none, at the end
    _record_times(buffer, np.array([0, buffer.size]), np.array([1, 0]), np.array([0, -1]), times, firsts, lasts)
    assert firsts.tolist() == [7, 0] and lasts.tolist() == [7, 0] and times.tolist() == [7]


def test_a_ulog_start_in_the_metadata_reads_the_window_whole_again(chunked, tmp_path):
    """A ULog start timestamp in the metadata 8 s after the first message is the log's time zero
    (`Log.origin_ns`), not the first message the window was cut from: the analysis reads the file
    whole again for the window, and aligns what the whole read aligns."""
    from logscan.pipeline.preparation import _read_and_align, load_profile_for

    with open(chunked["source"], "rb") as fh:
        first = make_reader(fh).get_summary().statistics.message_start_time
    path = tmp_path / "ulog_start.mcap"
    rewrite(chunked["source"], path, metadata={"ulog.log": {"start_timestamp_us": str(first // 1000 + 8_000_000)}})
    loaded = load_profile_for(path, None)
    log, run, _ = _read_and_align(str(path), loaded, frozenset(), False, None, (20.0, 40.0), None, lambda m: None)
    assert log.whole_times == {} and run.start_ns == first + 8 * S  # read whole, counted from the start
    whole = align(read_log(path, topics=loaded.profile.topics()), loaded.profile, start_s=20.0, end_s=40.0)
    np.testing.assert_array_equal(run.u, whole.u)
    assert not np.isnan(run.u).any()
