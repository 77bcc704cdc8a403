"""A PX4 log whose IMU is too slow for the ins model still gets a verdict: the checks that need no
filter (health, PX4's own estimator tests) run, and the ins model is one `not checked` line (the
log is then not fully checked: exit 2, or 0/1 by its alarms with --allow-partial).

The case is a real log edited: PX4's SITL flight sample_px4_events.ulg with its IMU
(sensor_combined, 250 Hz) kept at about 9.6 Hz, as a log recorded with a low-rate logger profile.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import need_testdata
from pyulog import ULog

from logscan.pipeline import builtin_profile_for

pytestmark = pytest.mark.testdata("px4-ulog/sample_px4_events.ulg")
SOURCE = "px4-ulog/sample_px4_events.ulg"
SLOW_HZ = 9.6


@pytest.fixture(scope="module")
def slow_imu_log(tmp_path_factory):
    """The real flight with its IMU topics decimated to about SLOW_HZ (every other topic as logged)."""
    ulog = ULog(str(need_testdata(SOURCE)))
    for data in ulog.data_list:
        if data.name in ("sensor_combined", "vehicle_imu"):
            hz = 1e6 / float(np.median(np.diff(data.data["timestamp"].astype(np.float64))))
            step = max(1, round(hz / SLOW_HZ))
            data.data = {name: values[::step] for name, values in data.data.items()}
    path = tmp_path_factory.mktemp("slow_imu") / "slow_imu.ulg"
    ulog.write_ulog(str(path))
    return path


def _analyze(cli, path, tmp_path, *args):
    out = tmp_path / "summary.json"
    result = cli("analyze", path, "--no-report", "--json", out, *args)
    return result, (json.loads(out.read_text())["logs"][0] if out.exists() else None)


def test_the_unedited_flight_runs_the_ins_model():
    built = builtin_profile_for(need_testdata(SOURCE))
    assert built.model_not_run == ""
    assert "[detectors.nis]" in built.text


def test_a_slow_imu_runs_the_filter_free_checks_and_names_the_model_not_checked(cli, slow_imu_log, tmp_path):
    result, summary = _analyze(cli, slow_imu_log, tmp_path)
    assert result.exit_code == 2, result.stderr  # not fully checked
    assert "Traceback" not in result.stderr
    ran = {d["detector"]: d for d in summary["detectors"]}
    assert set(ran) == {"health", "px4_estimator"}  # nis needs the filter: not run
    assert ran["health"]["info"]["checks"], "health judged nothing"
    assert ran["px4_estimator"]["info"]["sources"], "PX4's test ratios were not read"
    model_lines = [line for line in summary["unchecked"] if line.startswith("the ins model")]
    assert len(model_lines) == 1
    assert "sensor_combined is logged at 9.6" in model_lines[0] and "50 Hz or more" in model_lines[0]
    assert "not fully checked" in summary["verdict"]
    assert "not checked: the ins model" in result.stdout


def test_allow_partial_gives_the_verdict_of_what_was_checked(cli, slow_imu_log, tmp_path):
    result, summary = _analyze(cli, slow_imu_log, tmp_path, "--allow-partial", "-d", "health")
    assert result.exit_code == (1 if summary["n_alarms"] else 0)
    assert [d["detector"] for d in summary["detectors"]] == ["health"]
    assert any(line.startswith("the ins model") for line in summary["unchecked"])


def test_asking_only_for_a_filter_detector_is_one_clear_error(cli, slow_imu_log, tmp_path):
    result, _ = _analyze(cli, slow_imu_log, tmp_path, "-d", "nis")
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and str(slow_imu_log) in lines[0]
    assert "50 Hz or more" in lines[0] and "nis needs its filter" in lines[0] and "-d health" in lines[0]


def test_the_profile_printed_for_a_slow_imu_says_why_nis_is_left_out(slow_imu_log):
    built = builtin_profile_for(slow_imu_log)
    assert "9.6" in built.model_not_run
    assert "[detectors.nis]" not in built.text and "[detectors.health]" in built.text
    assert "# The ins model is not run:" in built.text
