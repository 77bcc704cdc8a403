"""CSV reader: wide files (time column, unit inference, NaNs, text, order) and ulog2csv directories."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from logscan.errors import InputError, LogscanError
from logscan.log import Channel, Log, SourceInfo
from logscan.readers import read_log
from logscan.readers.csv_reader import csv_log_name, infer_time_unit, read_csv, read_csv_dir, time_column_unit


def write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def rows(times, *columns) -> str:
    return "\n".join(",".join(str(v) for v in row) for row in zip(times, *columns)) + "\n"


def test_wide_file_channels_are_slash_column_and_values_are_exact(tmp_path):
    f = write(tmp_path / "run.csv", "time,ax,/already/slashed\n0.0,1.5,7\n0.01,2.5,8\n0.02,3.5,9\n")
    log = read_csv(f, None)
    assert set(log.channels) == {"/ax", "/already/slashed"}
    np.testing.assert_array_equal(log.channel("/ax").t, [0, 10_000_000, 20_000_000])
    np.testing.assert_array_equal(log.channel("/ax").values, [1.5, 2.5, 3.5])
    np.testing.assert_array_equal(log.channel("/already/slashed").values, [7, 8, 9])
    assert log.source.format == "csv" and log.source.time_unit == "s"
    assert log.source.topics["run"].message_count == 3
    assert log.source.topics["run"].fields == ["ax", "/already/slashed"]


def test_written_nans_are_kept_in_values_and_counted_in_a_warning(tmp_path):
    f = write(tmp_path / "n.csv", "time,a,b\n0,1,nan\n0.1,nan,2\n0.2,3,NaN\n0.3,4,5\n")
    log = read_csv(f, None)
    np.testing.assert_array_equal(np.isnan(log.channel("/a").values), [False, True, False, False])
    np.testing.assert_array_equal(np.isnan(log.channel("/b").values), [True, False, True, False])
    nan_warnings = [w for w in log.source.warnings if "NaN" in w]
    assert len(nan_warnings) == 1 and "3 NaN value(s)" in nan_warnings[0]
    assert "/a: 1" in nan_warnings[0] and "/b: 2" in nan_warnings[0]
    assert not log.source.skipped  # a written nan is a value, not a cell that failed to parse


def test_empty_cells_of_a_multi_rate_wide_csv_are_no_samples_and_no_warning(tmp_path):
    rows = "".join(f"{k * 0.01:.2f},{k},{'' if k % 10 else k / 10},{'NA' if k % 5 else 7}\n" for k in range(100))
    f = write(tmp_path / "multi.csv", "time_s,fast,slow,mid\n" + rows)
    log = read_csv(f, None)
    assert len(log.channel("/fast")) == 100
    slow, mid = log.channel("/slow"), log.channel("/mid")
    np.testing.assert_array_equal(slow.t, np.arange(0, 100, 10) * 10_000_000)  # its own 10 Hz samples
    np.testing.assert_array_equal(slow.values, np.arange(10.0))
    assert len(mid) == 20 and np.isfinite(mid.values).all()
    assert log.source.warnings == [] and log.source.skipped == []


def test_unsorted_and_duplicate_times_are_kept_in_file_order_with_a_warning(tmp_path):
    f = write(tmp_path / "u.csv", "t,x\n0.2,1\n0.1,2\n0.1,3\n0.3,4\n")
    log = read_csv(f, None)
    np.testing.assert_array_equal(log.channel("/x").t, [200_000_000, 100_000_000, 100_000_000, 300_000_000])
    np.testing.assert_array_equal(log.channel("/x").values, [1, 2, 3, 4])
    order = [w for w in log.source.warnings if "not strictly increasing" in w]
    assert order and "1 step(s) backwards" in order[0] and "1 duplicate(s)" in order[0]


def test_text_column_is_skipped_and_counted_and_mixed_column_reads_garbage_as_nan(tmp_path):
    f = write(tmp_path / "m.csv", "time,mode,speed\n0,idle,1.0\n1,go,2.0\n2,go,oops\n3,stop,4.0\n4,go,5.0\n")
    log = read_csv(f, None)
    assert set(log.channels) == {"/speed"}
    np.testing.assert_array_equal(np.isnan(log.channel("/speed").values), [False, False, True, False, False])
    skipped = {s.what: (s.why, s.count) for s in log.source.skipped}
    assert skipped["text column 'mode' of m.csv"] == ("not numeric", 1)
    assert skipped["cells of column 'speed' of m.csv"] == ("not a number, read as NaN", 1)


def test_rows_without_a_time_are_dropped_and_counted(tmp_path):
    f = write(tmp_path / "r.csv", "time,x\n0,1\n,2\n0.2,3\n")
    log = read_csv(f, None)
    np.testing.assert_array_equal(log.channel("/x").values, [1, 3])
    assert log.source.skipped[0].count == 1 and "time is empty" in log.source.skipped[0].why


@pytest.mark.parametrize(
    "content, message",
    [
        ("", "empty"),
        ("   \n", "empty"),
        ("time,x\n", "header (2 column(s)) but no data rows"),
        ("foo,bar\n1,2\n", "no time column among 'foo', 'bar'"),
        ("time,x\n1,2,3,4\n5\n", "malformed CSV"),
        ("time,x\nabc,1\ndef,2\n", "time column 'time' holds no numbers or dates"),
    ],
)
def test_bad_csv_raises_one_line_input_error(tmp_path, content, message):
    f = tmp_path / "bad.csv"
    f.write_text(content, encoding="utf-8")
    with pytest.raises(InputError) as info:
        read_csv(f, None)
    line = info.value.one_line()
    assert message in line and str(f) in line and "\n" not in line


def test_no_time_column_message_lists_accepted_names(tmp_path):
    f = write(tmp_path / "nt.csv", "a,b\n1,2\n")
    with pytest.raises(InputError) as info:
        read_csv(f, None)
    assert "name it time, timestamp, t or stamp" in info.value.one_line()


def test_non_utf8_bytes_after_the_first_block_give_input_error(tmp_path):
    f = tmp_path / "latin.csv"
    f.write_bytes(b"time,x\n" + b"0,1\n" * 3000 + b"1,\xe9\xff\n")
    with pytest.raises(InputError, match="UTF-8"):
        read_log(f)


@pytest.mark.parametrize(
    "header, unit",
    [
        ("time", None),
        ("Timestamp", None),
        ("t", None),
        ("stamp", None),
        ("time_s", "s"),
        ("timestamp_us", "us"),
        ("time [ms]", "ms"),
        ("stamp(ns)", "ns"),
        ("time_usec", "us"),
        ("%time", None),
        ("TIME_MS", "ms"),
    ],
)
def test_time_column_names_and_stated_units(header, unit):
    assert time_column_unit(header) == (True, unit)


@pytest.mark.parametrize("header", ["timestamp_sample", "times", "x_time", "tt", "time_total"])
def test_other_columns_are_not_time(header):
    assert time_column_unit(header)[0] is False


@pytest.mark.parametrize(
    "values, unit, origin",
    [
        (np.arange(1000) * 0.01, "s", "relative"),  # 100 Hz, fractional seconds
        (np.arange(1000) * 10.0, "ms", "relative"),  # 100 Hz integer milliseconds
        (20_000_000 + np.arange(1000) * 4000.0, "us", "relative"),  # PX4: us since boot, 250 Hz
        (1_194_000_000 + np.arange(100) * 20_000.0, "us", "relative"),  # us since boot ~ 1.2e9
        (np.arange(1000) * 1e7, "ns", "relative"),  # 100 Hz nanoseconds
        (1.7e9 + np.arange(100) * 0.02, "s", "epoch"),  # epoch seconds with fractions
        (1_700_000_000_000 + np.arange(100) * 20.0, "ms", "epoch"),
        (1_700_000_000_000_000 + np.arange(100) * 5000.0, "us", "epoch"),
        (1_700_000_000_000_000_000 + np.arange(100) * 1e7, "ns", "epoch"),
    ],
)
def test_unit_inference_from_step_and_magnitude(values, unit, origin):
    inferred = infer_time_unit(np.asarray(values, dtype=np.float64))
    assert (inferred.unit, inferred.origin) == (unit, origin), inferred.reason


@pytest.mark.parametrize(
    "header, times, expected_ns",
    [
        ("time", ["0.0", "0.01", "0.02"], [0, 10_000_000, 20_000_000]),
        ("time", ["0", "10", "20"], [0, 10_000_000, 20_000_000]),  # inferred ms
        (
            "timestamp",
            ["20000000", "20004000", "20008000"],
            [20_000_000_000, 20_004_000_000, 20_008_000_000],
        ),  # inferred us
        ("time_ms", ["0", "1", "2"], [0, 1_000_000, 2_000_000]),  # stated, not inferred
        (
            "stamp",
            ["1700000000000000000", "1700000000010000000", "1700000000020000000"],
            [1_700_000_000_000_000_000, 1_700_000_000_010_000_000, 1_700_000_000_020_000_000],
        ),
    ],
)
def test_time_is_converted_to_int64_ns_and_the_unit_is_reported(tmp_path, header, times, expected_ns):
    f = write(tmp_path / "u.csv", f"{header},x\n" + "".join(f"{t},1\n" for t in times))
    log = read_csv(f, None)
    np.testing.assert_array_equal(log.channel("/x").t, expected_ns)
    assert log.channel("/x").t.dtype == np.int64
    inferred = [w for w in log.source.warnings if "inferred from" in w]
    assert bool(inferred) == ("_" not in header)
    assert log.source.metadata["csv.time_units"]["u.csv"] == log.source.time_unit


def test_iso_datetime_time_column_is_epoch_ns(tmp_path):
    f = write(tmp_path / "d.csv", "timestamp,x\n2024-03-18 14:49:10.000,1\n2024-03-18T14:49:10.250Z,2\n")
    log = read_csv(f, None)
    np.testing.assert_array_equal(log.channel("/x").t, [1_710_773_350_000_000_000, 1_710_773_350_250_000_000])
    assert log.source.time_unit == "ns" and "ISO 8601" in log.source.metadata["csv.time_columns"]["d.csv"]


def test_semicolon_and_tab_delimiters_are_detected(tmp_path):
    for sep, name in ((";", "semi.csv"), ("\t", "tab.csv")):
        f = write(tmp_path / name, f"time{sep}x\n0{sep}1\n0.5{sep}2\n")
        assert read_csv(f, None).channel("/x").values.tolist() == [1, 2]


def test_wanted_channels_limit_what_is_kept(tmp_path):
    f = write(tmp_path / "w.csv", "time,a,b\n0,1,2\n1,3,4\n")
    assert set(read_csv(f, {"/b"}).channels) == {"/b"}


def test_truth_and_profile_sidecars_are_read(tmp_path):
    f = write(tmp_path / "flight.csv", "time,a\n0,1\n1,2\n")
    write(tmp_path / "flight.truth.json", '{"events": [{"start": 1, "end": 2, "kind": "bias"}]}')
    assert read_csv(f, None).truth["events"][0]["kind"] == "bias"
    assert read_csv(f, None).profile_text is None
    write(tmp_path / "flight.profile.toml", '[vehicle]\nmodel = "quadcopter"\n')
    assert 'model = "quadcopter"' in read_csv(f, None).profile_text
    write(tmp_path / "flight.truth.json", "{broken")
    with pytest.raises(InputError, match="not valid JSON"):
        read_csv(f, None)


def test_million_row_csv_reads_every_row(tmp_path):
    """Every row read, the values as written; its speed is measured by bench/bench_timed_checks.py."""
    n = 1_000_000
    t = np.arange(n) * 0.001
    data = np.column_stack([t, np.sin(t), np.cos(t), t * 2.0])
    f = tmp_path / "big.csv"
    np.savetxt(f, data, delimiter=",", header="time,a,b,c", comments="", fmt="%.6f")
    log = read_csv(f, None)
    assert len(log.channel("/c")) == n
    assert np.allclose(log.channel("/c").values[[0, n // 2, -1]], data[[0, n // 2, -1], 3], atol=1e-6)


# ---- directories in PX4 ulog2csv layout ---------------------------------------------------------


def make_ulog2csv_dir(root: Path, log_name: str = "flight") -> Path:
    d = root / "csvs"
    d.mkdir()
    write(
        d / f"{log_name}_vehicle_imu_0.csv",
        "timestamp,accel[0],accel[1],temp_name\n0,9,9,x\n1000,0.1,0.2,a\n2000,0.3,0.4,b\n3000,0.5,0.6,c\n",
    )
    write(d / f"{log_name}_vehicle_imu_1.csv", "timestamp,accel[0]\n1500,1.0\n2500,2.0\n")
    write(d / f"{log_name}_battery_status_0.csv", "timestamp,voltage_v\n1000000,12.1\n2000000,12.0\n")
    write(d / "notes.csv", "time_s,wind\n0,3\n1,4\n")
    return d


def test_directory_in_ulog2csv_layout_names_topics_like_the_ulog_reader(tmp_path):
    d = make_ulog2csv_dir(tmp_path)
    log = read_csv_dir(d, None)
    assert log.source.format == "csv-dir"
    assert set(log.source.topics) == {"vehicle_imu_0", "vehicle_imu_1", "battery_status_0", "notes"}
    assert "/vehicle_imu_0/accel[0]" in log.channels and "/battery_status_0/voltage_v" in log.channels
    imu = log.channel("/vehicle_imu_0/accel[1]")
    # timestamp 0 is PX4's "never set": dropped like the ULog reader drops it, and counted
    np.testing.assert_array_equal(imu.t, [1_000_000, 2_000_000, 3_000_000])
    np.testing.assert_array_equal(imu.values, [0.2, 0.4, 0.6])
    info = log.source.topics["vehicle_imu_0"]
    assert info.message_count == 3 and info.schema == "ulog2csv"
    assert info.rate_hz == pytest.approx(1000.0)
    assert info.fields == ["accel[0]", "accel[1]"]
    assert any(s.what == "text column 'temp_name' of vehicle_imu_0" for s in log.source.skipped)
    assert any("timestamp 0" in s.why and s.count == 1 for s in log.source.skipped)
    # a file outside the layout is a wide CSV with topic = its stem
    np.testing.assert_array_equal(log.channel("/notes/wind").t, [0, 1_000_000_000])
    assert log.source.time_unit == "mixed: s,us"


def test_directory_topics_are_filtered_by_wanted(tmp_path):
    d = make_ulog2csv_dir(tmp_path)
    log = read_csv_dir(d, {"/vehicle_imu_1/accel[0]"})
    assert list(log.channels) == ["/vehicle_imu_1/accel[0]"]
    assert set(log.source.topics) == {"vehicle_imu_1"}


def test_log_prefix_from_the_directory_name_when_topics_share_a_first_word(tmp_path):
    d = tmp_path / "flight"
    d.mkdir()
    write(d / "flight_vehicle_imu_0.csv", "timestamp,x\n1,2\n")
    write(d / "flight_vehicle_gps_position_0.csv", "timestamp,lat\n1,2\n")
    assert set(read_csv_dir(d, None).source.topics) == {"vehicle_imu_0", "vehicle_gps_position_0"}


def test_read_log_dispatches_directories_and_rejects_one_without_csvs(tmp_path):
    d = make_ulog2csv_dir(tmp_path)
    assert read_log(d).source.format == "csv-dir"
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(LogscanError, match="no .csv files"):
        read_log(empty)


def test_a_directory_of_separate_wide_csvs_is_not_read_as_one_log(tmp_path):
    flights = tmp_path / "flights"
    flights.mkdir()
    write(flights / "monday.csv", "timestamp,speed\n1704067200,1\n1704067201,2\n")
    write(flights / "april.csv", "timestamp,speed\n1712000000,1\n1712000001,2\n")
    assert csv_log_name(flights) == ""
    with pytest.raises(InputError) as info:
        read_log(flights)
    line = info.value.one_line()
    assert "separate logs" in line and "april.csv, monday.csv" in line and "pass one file" in line
    assert "\n" not in line


def test_a_directory_of_ulog2csv_pieces_is_one_log_named_after_them(tmp_path):
    d = make_ulog2csv_dir(tmp_path)
    assert csv_log_name(d) == "flight"
    single = tmp_path / "single"
    single.mkdir()
    write(single / "flight_vehicle_imu_0.csv", "timestamp,x\n1,2\n")
    assert csv_log_name(single) == ""  # one piece: its log name cannot be told from its topic


# ---- spans over a day ------------------------------------------------------------------------------


def test_a_span_over_one_day_is_a_warning_naming_the_channels_at_both_ends(tmp_path):
    f = write(tmp_path / "days.csv", "time_s,a,b\n0,1,\n1,2,\n200000,,3\n")
    log = read_csv(f, None)
    (warning,) = [w for w in log.source.warnings if "days" in w]
    assert "spans 2.3 days (from /a to /b)" in warning and "more than a day" in warning
    short = read_csv(write(tmp_path / "hours.csv", "time_s,a\n0,1\n86400,2\n"), None)
    assert not any("days" in w for w in short.source.warnings)


def test_the_span_warning_is_added_once_whoever_builds_the_log():
    source = SourceInfo(path="x.mcap", format="mcap")
    channels = {"/a": Channel("/a", np.array([0, 3 * 86_400 * 10**9]), np.zeros(2))}
    log = Log(channels=channels, source=source)
    Log(channels=channels, source=source)  # a second Log over the same source adds nothing
    assert [w for w in source.warnings if "3.0 days" in w] == [log.span_warning()]


@pytest.mark.parametrize("name", ["flight.mcap", "flight.ULG", "drive.bag", "drive.db3"])
def test_text_named_like_a_binary_log_is_refused_not_read_as_csv(tmp_path, name):
    path = tmp_path / name
    path.write_text("time,speed\n0,1\n1,2\n")  # a CSV would read: the name says it is something else
    with pytest.raises(LogscanError) as caught:
        read_log(path)
    line = caught.value.one_line()
    assert f"named {path.suffix} but not" in line and "time column" not in line, line


def test_a_csv_named_csv_still_reads(tmp_path):
    path = tmp_path / "flight.csv"
    path.write_text("time,speed\n0,1\n1,2\n")
    assert read_log(path).source.format == "csv"


def test_iso_date_times_under_a_name_stating_a_unit_are_read_as_the_date_times(tmp_path):
    # a date-time states its own unit: the name's unit neither applies to it nor drops its rows
    f = write(tmp_path / "d.csv", "timestamp_ns,x\n2024-03-18T14:49:10.000Z,1\n2024-03-18T14:49:10.250Z,2\n")
    log = read_csv(f, None)
    np.testing.assert_array_equal(log.channel("/x").t, [1_710_773_350_000_000_000, 1_710_773_350_250_000_000])
    assert log.source.warnings == [] and log.source.skipped == []


def test_iso_date_times_get_no_advice_to_state_a_unit_only_the_utc_they_are_read_in(tmp_path):
    naive = read_csv(write(tmp_path / "n.csv", "time,x\n2024-03-18 14:49:10,1\n2024-03-18 14:49:11,2\n"), None)
    assert not any("name it" in w or "_ns" in w for w in naive.source.warnings)
    assert [w for w in naive.source.warnings if "without a UTC offset" in w and "read as UTC" in w]
    stated = read_csv(write(tmp_path / "z.csv", "time,x\n2024-03-18 14:49:10+01:00,1\n2024-03-18 14:49:11Z,2\n"), None)
    assert stated.source.warnings == []


def test_a_time_column_stating_a_unit_over_text_is_an_error_saying_so(tmp_path):
    f = write(tmp_path / "t.csv", "time_s,x\nstart,1\nlater,2\n")
    with pytest.raises(InputError) as caught:
        read_csv(f, None)
    assert "time column 'time_s' holds no numbers or dates" in caught.value.message


@pytest.mark.parametrize(
    "text",
    [
        "time;x;y\n1432235498,025;0,25;1\n1432235498,125;-0,5;2\n1432235498,225;1,5e-3;3\n",
        "time_ms;x\n0;0,25\n10;-0,5\n20;1,75\n",  # the time reads; a value column does not
    ],
    ids=["time-column", "value-column"],
)
def test_numbers_with_a_decimal_comma_are_an_error_saying_so_and_what_to_do(tmp_path, text):
    with pytest.raises(InputError) as caught:
        read_csv(write(tmp_path / "comma.csv", text), None)
    assert "decimal comma" in caught.value.message and "'.'" in caught.value.hint


def test_a_folder_of_per_topic_csvs_not_in_ulog2csv_layout_says_what_a_folder_log_needs(tmp_path):
    topics = tmp_path / "husky_topics"
    topics.mkdir()
    write(topics / "husky_imu.csv", "time,gyro.z\n1432235498.00,0.1\n1432235498.03,0.2\n")
    write(topics / "husky_odom.csv", "time,speed\n1432235498.01,1\n1432235498.11,2\n")
    with pytest.raises(InputError) as info:
        read_log(topics)
    line = info.value.one_line()
    # what a folder read as one log must be, and both ways to get one from these files
    assert "ulog2csv layout" in line and "<log>_<topic>_<n>.csv" in line and "'timestamp' in microseconds" in line
    assert "join them into one wide CSV" in line and "pass one file" in line
