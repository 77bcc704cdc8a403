"""Verdicts a user can trust: "no alarms" only when everything was checked, incidents instead of
fragments, and a failing detector named without losing the others."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from logscan.alarms import AlarmInterval
from logscan.detectors.base import Detector
from logscan.detectors.registry import BUILTIN_DETECTORS, Registry
from logscan.results import DetectorResult
from logscan.verdict.coverage import unchecked_reasons
from logscan.verdict.incidents import find_incidents, group_of

REPO = Path(__file__).resolve().parents[1]
SAMPLES = REPO / "sample_logs"
BIAS = SAMPLES / "quad_imu_bias.mcap"


def alarm(start, end, signal, ratio=2.0, detector="nis"):
    return AlarmInterval(start, end, start, start, ratio, 1.0, ratio, "upper", 3, signal, detector)


# --- incidents -------------------------------------------------------------------------------------


def test_one_injected_bias_is_one_incident_naming_the_accelerometer(cli, tmp_path):
    out = tmp_path / "bias.json"
    result = cli("analyze", BIAS, "--no-report", "--json", out)
    assert result.exit_code == 1
    first = result.stdout.splitlines()[1]
    assert first.startswith("  incident 1: accelerometer inconsistent 30.00-")
    assert "(nis.accel, peak 10.7x)" in first
    log = json.loads(out.read_text())["logs"][0]
    assert log["n_incidents"] == 1 and log["incidents"][0]["source"] == "accel"
    # fragments of one check within a second are one alarm: nis.accel flickered 3 times before
    accel = [a for d in log["detectors"] for a in d["alarms"] if a["signal"] == "nis.accel"]
    assert len(accel) == 1 and accel[0]["start"] == 30.0 and accel[0]["end"] > 41.0
    # --json keeps every alarm, and the incident lists the checks behind it
    assert log["n_alarms"] == sum(d["n_alarms"] for d in log["detectors"]) == log["incidents"][0]["n_alarms"]
    assert list(log).index("incidents") < list(log).index("detectors")


def test_rejected_samples_point_at_their_sensor(cli):
    result = cli("analyze", SAMPLES / "sbw_yaw_rate_bitflip.mcap", "--no-report")
    assert "incident 1: yaw-rate sensor inconsistent 30.1" in result.stdout
    assert "impossible samples rejected" in result.stdout


def test_incidents_split_on_gaps_and_prefer_the_first_group_alarm():
    results = [
        DetectorResult("nis", alarms=[alarm(10.0, 12.0, "nis.all", 9.0), alarm(10.0, 11.0, "nis.accel", 3.0),
                                      alarm(10.5, 15.0, "nis.position", 50.0), alarm(40.0, 40.0, "nis.gyro")]),
    ]  # fmt: skip
    incidents = find_incidents(results, None, ["accel", "gyro", "position"], gap_s=1.0)
    assert [(i.start, i.end, i.source) for i in incidents] == [(10.0, 15.0, "accel"), (40.0, 40.0, "gyro")]
    # the headline gives the span of the check it quotes, not the incident's 10-15 s
    assert incidents[0].headline.startswith("accelerometer inconsistent 10.00-11.00 s (nis.accel, peak 3x)")
    assert group_of("rejected.yaw_rate", ["yaw_rate"]) == "yaw_rate" and group_of("e_x", ["accel"]) is None


# --- what could not be checked ---------------------------------------------------------------------


def test_a_log_cut_before_its_first_complete_chunk_is_bad_input(cli, tmp_path):
    data = (SAMPLES / "quad_healthy.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 20])
    result = cli("analyze", cut, "--no-report")
    assert result.exit_code == 2 and "no messages could be recovered" in result.stderr


@pytest.mark.parametrize("fraction", [0.2, 0.45, 0.8])
def test_a_truncated_log_is_never_healthy(cli, tmp_path, fraction):
    data = (SAMPLES / "quad_healthy.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * fraction)])
    report = tmp_path / "cut.html"
    result = cli("analyze", cut, "-o", report)
    assert result.exit_code == 2
    assert "not fully checked" in result.stdout and "read only in part" in result.stdout
    assert "no alarms  (" not in result.stdout
    assert report.exists() and "Not fully checked" in report.read_text()
    allowed = cli("analyze", cut, "--no-report", "--allow-partial")
    assert allowed.exit_code == 0 and "not fully checked" in allowed.stdout


def _csv_copy(tmp_path: Path, edit) -> Path:
    """quad_healthy.csv with its sidecars, one column group edited."""
    frame = pd.read_csv(SAMPLES / "quad_healthy.csv")
    edit(frame)
    path = tmp_path / "edited.csv"
    frame.to_csv(path, index=False)
    for suffix in (".truth.json", ".profile.toml"):
        shutil.copy(SAMPLES / f"quad_healthy{suffix}", tmp_path / f"edited{suffix}")
    return path


ACCEL = ["/imu/accel.x", "/imu/accel.y", "/imu/accel.z"]


def _all_nan(frame):
    frame[ACCEL] = np.nan


def _all_inf(frame):
    frame[ACCEL] = np.inf


def _silent_after_one_second(frame):
    late = frame["time_ns"] > frame["time_ns"].iloc[0] + 1_000_000_000
    frame.loc[late, ACCEL] = np.nan


def _gps_dead(frame):
    frame[["/gps/position.x", "/gps/position.y", "/gps/position.z"]] = np.nan


@pytest.mark.parametrize("edit, group", [(_all_nan, "accel"), (_all_inf, "accel"),
                                         (_silent_after_one_second, "accel"), (_gps_dead, "position")])  # fmt: skip
def test_a_dead_or_silent_sensor_is_never_healthy(cli, tmp_path, edit, group):
    path = _csv_copy(tmp_path, edit)
    result = cli("analyze", path, "--no-report")
    assert result.exit_code == 2, result.stdout + result.stderr
    assert f"measurement group {group!r}: the filter used" in result.stdout
    assert "no alarms  (" not in result.stdout


def test_divergence_over_most_of_the_log_and_statistics_never_computed_are_unchecked():
    episode = SimpleNamespace(n_steps=700)
    trace = SimpleNamespace(group_names=[], updated=np.zeros((1000, 0), bool), divergence_episodes=[episode],
                            n_steps=1000)  # fmt: skip
    run = SimpleNamespace(t=np.arange(1000) * 0.01, dt=0.01, n_steps=1000, groups={})
    dead = DetectorResult("probe", series={"stat": np.full(1000, np.nan)})
    prepared = SimpleNamespace(log=SimpleNamespace(source=SimpleNamespace(partial=False)), trace=trace, run=run)
    reasons = unchecked_reasons(prepared, [dead])
    assert reasons == ["the filter was diverged for 70 % of the log",
                       "probe: stat was never computed (no finite value over the log)"]  # fmt: skip


# --- a failing detector ----------------------------------------------------------------------------


class ExplodingDetector(Detector):
    """Raises in run (a detector with a bug)."""

    name = "exploding"
    requires_trace = True

    def _run(self, run, trace, **context):
        raise ZeroDivisionError("boom")


def test_a_failing_detector_is_named_and_the_others_are_kept(cli, tmp_path, monkeypatch):
    registry = Registry(builtins=BUILTIN_DETECTORS + [f"{__name__}:ExplodingDetector"], plugins=[])
    monkeypatch.setattr("logscan.detectors.registry._DEFAULT", registry)
    report, out = tmp_path / "r.html", tmp_path / "r.json"
    result = cli("analyze", BIAS, "-d", "exploding", "-d", "nis", "-o", report, "--json", out)
    assert result.exit_code == 3
    assert "detector 'exploding' (built-in) failed: ZeroDivisionError: boom (a bug in logscan;" in result.stdout
    log = json.loads(out.read_text())["logs"][0]
    assert [d["detector"] for d in log["detectors"]] == ["nis"] and log["n_alarms"] > 0
    assert log["failed_detectors"][0]["detector"] == "exploding" and log["exit_code"] == 3
    assert report.exists() and "exploding" in report.read_text()


def test_a_window_longer_than_the_log_cannot_hide_a_fault(cli, tmp_path):
    import tomllib

    from logscan.pipeline import load_profile_for
    from logscan.profiles import dumps_toml

    data = tomllib.loads(load_profile_for(BIAS, None).text)
    data.setdefault("detectors", {})["nis"] = {"window": 1_000_000}
    profile = tmp_path / "long_window.toml"
    profile.write_text(dumps_toml(data))
    result = cli("analyze", BIAS, "--profile", profile, "-d", "nis", "--no-report")
    assert result.exit_code == 2
    assert "nis: nis.accel was judged on only 0 % of its samples" in result.stdout


def test_a_window_over_most_of_the_log_is_not_fully_checked(cli, tmp_path):
    import tomllib

    from logscan.pipeline import load_profile_for
    from logscan.profiles import dumps_toml

    data = tomllib.loads(load_profile_for(BIAS, None).text)
    data.setdefault("detectors", {})["nis"] = {"window": 5000}  # 50 s of the 60 s accelerometer updates
    profile = tmp_path / "long_window.toml"
    profile.write_text(dumps_toml(data))
    result = cli("analyze", BIAS, "--profile", profile, "-d", "nis", "--no-report")
    assert result.exit_code == 2
    assert "nis: nis.accel was judged on only 17 % of its samples" in result.stdout


def test_the_report_lists_the_incident_before_the_alarms_behind_it(cli, tmp_path):
    report = tmp_path / "bias.html"
    assert cli("analyze", BIAS, "-o", report).exit_code == 1
    page = report.read_text()
    assert page.index('id="incident-table"') < page.index('id="alarm-table"')
    assert "accelerometer inconsistent: +" in page and re.search(r"Verdict: \d+ alarms in 1 incident", page)
