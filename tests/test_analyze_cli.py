"""`logscan analyze` end to end through the real CLI: sample logs, exit codes, artifacts, bad input."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "sample_logs"

FAULTY = [
    "quad_imu_bias.mcap",
    "quad_imu_bitflip.mcap",
    "quad_motor_offset.mcap",
    "quad_cov_corruption.mcap",
    "sbw_yaw_rate_bitflip.mcap",
]
# jackal_healthy.mcap is left out on purpose: its speed sensors carry short healthy glitches
# (the A-TFM's transients), which the NIS test rightly flags as sensor anomalies.
HEALTHY = ["quad_healthy.mcap", "sbw_healthy.mcap", "quad_healthy.csv"]


@pytest.mark.parametrize("name", FAULTY)
def test_each_faulty_sample_log_raises_an_alarm_matching_its_fault_within_one_second(name, tmp_path, cli, sample):
    out = tmp_path / "summary.json"
    result = cli("analyze", sample(name), "--json", out, "--no-report")
    assert result.exit_code == 1, result.stderr
    summary = json.loads(out.read_text())["logs"][0]
    assert summary["truth_events"], "sample logs carry their ground truth"
    latencies = [s["mean_latency_s"] for s in summary["scores"].values() if s["tp"]]
    assert latencies and min(latencies) <= 1.0, summary["scores"]


@pytest.mark.parametrize("name", HEALTHY)
def test_each_healthy_sample_log_raises_no_alarm_and_exits_zero(name, tmp_path, cli, sample):
    result = cli("analyze", sample(name), "-o", tmp_path / "r.html")
    assert result.exit_code == 0, result.stdout + result.stderr
    assert "no alarms" in result.stdout
    assert (tmp_path / "r.html").stat().st_size > 100_000


def test_rejected_samples_are_counted_in_words_not_as_a_ratio(cli, sample):
    result = cli("analyze", sample("quad_imu_bitflip.mcap"), "--no-report")
    line = next(line for line in result.stdout.splitlines() if "rejected.accel" in line)
    assert re.search(r"\d+\.\d\d +\d+ samples outside the physical range, the filter skipped them$", line), line


def test_exit_zero_and_report_written_for_alarms(tmp_path, cli, sample):
    report = tmp_path / "bias.html"
    result = cli("analyze", sample("quad_imu_bias.mcap"), "-o", report, "--exit-zero")
    assert result.exit_code == 0, result.stderr
    assert "nis" in result.stdout and report.exists()
    html = report.read_text(encoding="utf-8")
    assert "nis.accel" in html


def test_bad_input_exits_two_with_one_line_and_keeps_an_existing_report(tmp_path, cli, sample):
    report = tmp_path / "r.html"
    report.write_text("previous report")
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 10)
    for args in (
        [tmp_path / "missing.mcap"],
        [broken],
        [sample("quad_healthy.mcap"), "--profile", tmp_path / "nope.toml"],
    ):
        result = cli("analyze", *args, "-o", report)
        assert result.exit_code == 2, (args, result.stderr)
        assert "Traceback" not in result.stderr
        assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert report.read_text() == "previous report"


def test_unknown_channel_in_a_profile_names_the_closest_channels(tmp_path, cli, sample):
    text = (SAMPLES / "quad_healthy.profile.toml").read_text().replace("/imu/accel.x", "/imu/acel.x")
    profile = tmp_path / "p.toml"
    profile.write_text(text)
    result = cli("analyze", sample("quad_healthy.mcap"), "--profile", profile, "--no-report")
    assert result.exit_code == 2
    assert "/imu/acel.x" in result.stderr and "/imu/accel.x" in result.stderr


def test_a_log_without_profile_asks_for_one(tmp_path, cli):
    from logscan.readers.mcap import TopicData, write_mcap

    t = np.arange(10, dtype=np.int64) * 10_000_000
    path = tmp_path / "bare.mcap"
    write_mcap(path, {"/x": TopicData("X", t, {"v": np.zeros(10)})}, encoding="json")
    result = cli("analyze", path, "--no-report")
    assert result.exit_code == 2 and "--profile" in result.stderr


def test_several_logs_one_bad_reports_the_rest_and_exits_two(tmp_path, cli, sample):
    out = tmp_path / "s.json"
    reports = f"{tmp_path / 'reports'}/"  # ends in "/": a directory to create
    result = cli("analyze", sample("sbw_healthy.mcap"), tmp_path / "missing.mcap", "-o", reports, "--json", out)
    assert result.exit_code == 2
    summary = json.loads(out.read_text())
    assert [Path(s["file"]).name for s in summary["logs"]] == ["sbw_healthy.mcap"]
    assert summary["errors"][0]["exit_code"] == 2
    assert (tmp_path / "reports" / "sbw_healthy.report.html").exists()


def test_script_in_topic_names_is_shown_as_text_in_the_report(tmp_path, cli, sample):
    """A hostile topic name travels through reader, profile, detectors and report as data."""
    from logscan.readers import read_log
    from logscan.readers.mcap import TopicData, write_mcap

    source = read_log(sample("sbw_healthy.mcap"))
    hostile = "/imu<script>alert(1)</script>"
    topics: dict[str, dict] = {}
    for name, channel in source.channels.items():
        topic, _, field = name.rpartition("/")
        topic = hostile if topic == "/imu" else topic
        entry = topics.setdefault(topic, {"t": channel.t, "fields": {}})
        entry["fields"][field] = channel.values
    data = {topic: TopicData("S", e["t"], e["fields"]) for topic, e in topics.items()}
    profile = source.profile_text.replace('"/imu/', f'"{hostile}/')
    assert hostile in profile
    path = tmp_path / "hostile.mcap"
    write_mcap(path, data, encoding="json", metadata={"logscan.profile": {"toml": profile}})
    report = tmp_path / "hostile.html"
    result = cli("analyze", path, "-o", report, "--exit-zero")
    assert result.exit_code == 0, result.stderr
    html = report.read_text(encoding="utf-8")
    assert "<script>alert(1)</script>" not in html
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in html


def test_json_to_stdout_is_pure_json(sample, cli_process):
    # a subprocess: only a real pipe shows that nothing else (imports, numba, warnings) writes to stdout
    result = cli_process("analyze", sample("sbw_healthy.mcap"), "--json", "-", "--no-report")
    assert result.exit_code == 0
    summary = json.loads(result.stdout)
    assert summary["exit_code"] == 0 and summary["logs"][0]["verdict"] == "no alarms"
    assert "sbw_healthy.mcap" in result.stderr  # the human summary moved to stderr
