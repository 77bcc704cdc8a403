"""Ground truth beside any log (`<log>.truth.json`) or given with --truth, in log seconds or UTC
(logscan.truth): the alarms of a real PX4 log and a simulated one are scored against it."""

from __future__ import annotations

import datetime as dt
import json
import shutil

import pytest
from conftest import need_testdata

from logscan.errors import InputError
from logscan.verdict.truth import in_log_time, read_truth_file


def summary_of(cli, *args, tmp_path):
    out = tmp_path / "summary.json"
    # --allow-partial: a real flight judged in part (its ground time, take-off) still gets its truth scored
    result = cli("analyze", *args, "--no-report", "--allow-partial", "--json", str(out))
    assert result.exit_code in (0, 1), result.stderr
    return json.loads(out.read_text())["logs"][0]


def test_a_truth_file_beside_a_ulog_is_scored_in_log_seconds_and_in_utc(cli, tmp_path):
    src = need_testdata("px4-ulog/sample_px4_events.ulg")
    log = tmp_path / "flight.ulg"
    shutil.copy(src, log)
    event = {"kind": "bias", "target": "gps", "start": 10.0, "end": 12.0}
    (tmp_path / "flight.truth.json").write_text(json.dumps({"events": [event]}))
    entry = summary_of(cli, str(log), tmp_path=tmp_path)
    assert [e["start"] for e in entry["truth_events"]] == [10.0]
    # the same event in UTC, given with --truth: the log's clock is absolute (its start in UTC)
    start_ns = int(entry["log"]["start_ns"])
    at = dt.datetime.fromtimestamp(start_ns / 1e9 + 10.0, tz=dt.UTC).isoformat().replace("+00:00", "Z")
    utc = tmp_path / "utc.json"
    utc.write_text(json.dumps({"events": [{"kind": "bias", "target": "gps", "start_utc": at, "end_utc": None}]}))
    entry = summary_of(cli, str(log), "--truth", str(utc), tmp_path=tmp_path)
    assert entry["truth_events"][0]["start"] == pytest.approx(10.0, abs=1e-3)
    assert entry["truth_events"][0]["end"] is None


def test_truth_given_overrides_the_logs_own(cli, sample, tmp_path):
    truth = tmp_path / "t.json"
    truth.write_text(json.dumps({"events": [{"kind": "bias", "target": "accel.x", "start": 5.0, "end": 6.0}]}))
    entry = summary_of(cli, sample("quad_imu_bias.mcap"), "--truth", str(truth), tmp_path=tmp_path)
    assert [(e["start"], e["end"]) for e in entry["truth_events"]] == [(5.0, 6.0)]


def test_bad_truth_is_one_clear_error(cli, sample, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    result = cli("analyze", sample("quad_healthy.mcap"), "--no-report", "--truth", str(bad))
    assert result.exit_code == 2 and "bad.json" in result.stderr and "not valid JSON" in result.stderr
    with pytest.raises(InputError, match="not absolute"):
        in_log_time({"events": [{"start_utc": "2024-01-01T00:00:00Z"}]}, 0)
    listless = tmp_path / "listless.json"
    listless.write_text(json.dumps({"events": 3}))
    with pytest.raises(InputError, match="list of events"):
        read_truth_file(listless)


def test_the_truth_beside_the_current_folder_is_looked_for_by_its_name(tmp_path, monkeypatch):
    """`logscan analyze .` / `evaluate .` inside a rosbag2 folder: "." names the folder (it raised
    "PosixPath('.') has an empty name", an internal error)."""
    from logscan.verdict.truth import truth_beside

    folder = tmp_path / "drive"
    folder.mkdir()
    monkeypatch.chdir(folder)
    assert truth_beside(".") is None
    (tmp_path / "drive.truth.json").write_text('{"events": []}')
    assert truth_beside(".") == tmp_path / "drive.truth.json"
