"""Out of memory and out-of-range times are bad input (exit 2 with what to do), never an internal error."""

from __future__ import annotations

import json

import pytest
from test_px4_vehicle_imu import _air_data, _sensor_combined
from ulog_writer import write_ulog

from logscan.errors import OUT_OF_MEMORY


def _no_memory(*args, **kwargs):
    raise MemoryError


def test_a_memory_error_while_analysing_one_log_is_exit_2_with_what_to_do(cli, sample, monkeypatch):
    monkeypatch.setattr("logscan.tasks.analyze_blocked", _no_memory)  # where the task looks it up
    result = cli("analyze", sample("quad_healthy.mcap"), "--no-report")
    assert result.exit_code == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert lines == [f"logscan: error: {OUT_OF_MEMORY}"]
    assert "--start/--end" in lines[0] and "internal error" not in result.stderr


def test_a_memory_error_in_one_of_several_logs_is_that_logs_exit_2(cli, sample, monkeypatch, tmp_path):
    monkeypatch.setattr("logscan.tasks.analyze_blocked", _no_memory)  # where the task looks it up
    out = tmp_path / "summary.json"
    result = cli("analyze", sample("quad_healthy.mcap"), sample("jackal_healthy.mcap"), "--no-report", "--json", out)
    assert result.exit_code == 2, result.stderr
    errors = json.loads(out.read_text())["errors"]
    assert len(errors) == 2 and all(OUT_OF_MEMORY in e["error"] and e["exit_code"] == 2 for e in errors), errors
    assert "internal error" not in result.stderr


def test_a_memory_error_inside_a_detector_is_exit_2_not_a_bug(cli, sample, monkeypatch):
    from logscan.detectors.nis import NisDetector

    monkeypatch.setattr(NisDetector, "_run", _no_memory)
    result = cli("analyze", sample("quad_healthy.mcap"), "--no-report")
    assert result.exit_code == 2, result.stdout + result.stderr
    assert OUT_OF_MEMORY in result.stdout + result.stderr
    assert "a bug in logscan" not in result.stdout + result.stderr


@pytest.mark.parametrize("start_us", [2**64 - 1, 2**64 - 5000, 2**63 + 5, 2**53])
def test_a_ulog_header_timestamp_near_2_to_the_64_is_no_internal_error(cli, tmp_path, start_us):
    path = write_ulog(
        tmp_path / "start.ulg",
        {"sensor_combined": _sensor_combined(100.0, 5.0), "vehicle_air_data": _air_data(5.0)},
        start_us=start_us,
    )
    out = tmp_path / "out.json"
    result = cli("analyze", path, "--no-report", "--json", out)
    assert result.exit_code in (0, 1, 2) and "internal error" not in result.stderr, result.stderr
    log = json.loads(out.read_text())["logs"][0]
    assert log["clock"]["offset_s"] == pytest.approx(1.0)  # time zero: the first sample, 1 s after boot
    assert any("header's start timestamp" in w for w in log["warnings"]), log["warnings"]
    assert not [f for f in log.get("failures", []) if "Overflow" in str(f)]
