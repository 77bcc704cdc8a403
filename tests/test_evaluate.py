"""`logscan evaluate`: scores per detector, per check and per fault kind against ground truth."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from logscan.evaluate import (
    Evaluation,
    alarm_groups,
    check_key,
    evaluate_logs,
    merge_intervals,
    score_groups,
)
from logscan.results import AlarmInterval, DetectorResult, FaultEvent

SAMPLES = Path(__file__).resolve().parents[1] / "sample_logs"
HEALTHY = SAMPLES / "quad_healthy.mcap"
BIAS = SAMPLES / "quad_imu_bias.mcap"
BITFLIP = SAMPLES / "quad_imu_bitflip.mcap"


def alarm(start, end, signal, detector):
    return AlarmInterval(start, end, start, start, 2.0, 1.0, 2.0, "upper", 1, signal, detector)


@pytest.fixture(scope="module")
def evaluation() -> Evaluation:
    for path in (HEALTHY, BIAS, BITFLIP):
        if not path.exists():
            pytest.skip(f"{path} missing (run sample_logs/make_samples.py)")
    return evaluate_logs([str(HEALTHY), str(BIAS), str(BITFLIP)])


def test_checks_are_declared_by_the_detector_not_named_by_evaluation():
    t = np.linspace(0.0, 1.0, 11)
    encoded = DetectorResult("encoded_ekf")
    encoded.add_statistic(t, "e_x", np.zeros(11), upper=1.0)
    encoded.add_statistic(t, "rejected.accel", np.zeros(11), upper=0.5, check="e_x")
    assert check_key(encoded, "rejected.accel") == "encoded_ekf:e_x"
    assert check_key(encoded, "e_x") == "encoded_ekf:e_x"
    nis = DetectorResult("nis")
    assert check_key(nis, "nis.accel") == "nis:accel" and check_key(nis, "nis.all") == "nis:all"
    assert check_key(DetectorResult("plugin"), "other.signal") == "plugin:other.signal"


def test_the_encoded_detector_scores_rejected_samples_with_its_state_check():
    from logscan.pipeline import analyze_log

    analysis = analyze_log(str(BITFLIP), detector_names=["encoded_ekf"])
    result = analysis.results[0]
    rejected = [s for s in result.series if s.startswith("rejected.")]
    assert rejected and all(result.check_of(s) == "e_x" for s in rejected)


def test_overlapping_alarms_of_one_group_count_once():
    assert merge_intervals([(5.0, 6.0), (1.0, 2.0), (1.5, 3.0), (3.0, 4.0)]) == [(1.0, 4.0), (5.0, 6.0)]


def test_checks_that_ran_without_alarms_are_scored_as_misses():
    result = DetectorResult(
        "encoded_ekf",
        series={"e_x": None, "e_v": None, "rejected.accel": None},
        alarms=[
            alarm(10.0, 10.5, "rejected.accel", "encoded_ekf"),
            alarm(10.1, 10.2, "e_x", "encoded_ekf"),
            alarm(50.0, 50.1, "e_x", "encoded_ekf"),
        ],
        checks={"rejected.accel": "e_x"},
    )
    groups = alarm_groups([result])
    assert set(groups) == {"encoded_ekf", "encoded_ekf:e_x", "encoded_ekf:e_v"}
    scores = score_groups([FaultEvent(10.0, 11.0, "bitflip")], groups, duration_s=60.0)
    e_x, e_v = scores["encoded_ekf:e_x"], scores["encoded_ekf:e_v"]
    # rejected.accel and e_x overlap around the fault: one detection, the later e_x alarm is false
    assert (e_x.tp, e_x.fn, e_x.fp) == (1, 0, 1)
    assert (e_v.tp, e_v.fn, e_v.fp) == (0, 1, 0)


def test_nis_detects_the_accelerometer_bias_and_names_the_sensor(evaluation):
    by_kind = evaluation.by_kind("nis:accel")["quadcopter/bias"]
    assert (by_kind.tp, by_kind.n_events) == (1, 1)
    assert by_kind.max_latency_s < 1.0
    assert evaluation.by_kind("nis")["quadcopter/bias"].tp == 1


def test_encoded_check_catches_the_bit_flips_and_not_the_bias(evaluation):
    e_x = evaluation.by_kind("encoded_ekf:e_x")
    assert e_x["quadcopter/bitflip"].tp == 1 and e_x["quadcopter/bitflip"].max_latency_s < 1.0
    assert e_x["quadcopter/bias"].tp == 0  # coverage limit of docs/algorithms.md section 1.9


def test_healthy_log_raises_no_false_alarm(evaluation):
    healthy = [log for log in evaluation.logs if log.healthy]
    assert [Path(log.path).name for log in healthy] == ["quad_healthy.mcap"]
    for key in evaluation.keys():
        score = evaluation.aggregate(key, healthy)
        assert score.fp == 0, key
        assert score.false_alarms_per_hour_healthy == 0.0, key
    assert evaluation.aggregate("nis").healthy_duration_s == pytest.approx(60.0, abs=0.1)


def test_pooled_counts_add_up_over_logs(evaluation):
    nis = evaluation.aggregate("nis")
    assert nis.n_logs == 3 and nis.n_events == 2
    assert nis.tp + nis.fn == 2
    per_log = sum(log.scores["nis"].tp for log in evaluation.logs)
    assert nis.tp == per_log == 2


def test_cli_prints_tables_writes_json_and_skips_logs_without_truth(tmp_path, cli):
    if not BIAS.exists():
        pytest.skip("sample logs missing")
    no_truth = tmp_path / "no_truth.csv"
    shutil.copy(SAMPLES / "quad_healthy.csv", no_truth)  # its truth sidecar is not copied
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)) * 4)
    out = tmp_path / "eval.json"
    result = cli("evaluate", BIAS, no_truth, garbage, "--json", out, "--grace", "0.5")
    assert result.exit_code == 2, result.stderr  # the corrupt log is bad input
    assert "Traceback" not in result.stderr
    errors = [line for line in result.stderr.splitlines() if line.startswith("logscan: error: ")]
    assert len(errors) == 1 and "garbage.mcap" in errors[0]
    assert "skipped 1 log(s) without ground truth: no_truth.csv" in result.stdout
    assert "nis:accel" in result.stdout and "quadcopter/bias" in result.stdout
    data = json.loads(out.read_text())
    assert data["grace_s"] == 0.5 and data["n_logs"] == 1
    assert data["scores"]["nis"]["tp"] == 1
    assert data["by_kind"]["nis:accel"]["quadcopter/bias"]["detected"] == 1
    assert data["skipped_no_truth"] == [str(no_truth)]
    assert data["errors"][0]["file"] == str(garbage)


def test_cli_exit_zero_and_detector_filter(cli):
    if not HEALTHY.exists():
        pytest.skip("sample logs missing")
    result = cli("evaluate", HEALTHY, "--detector", "nis")
    assert result.exit_code == 0, result.stderr
    assert "encoded_ekf" not in result.stdout
    assert "1 healthy log(s)" in result.stdout


def test_cli_without_any_truth_is_bad_input(tmp_path, cli):
    if not (SAMPLES / "quad_healthy.csv").exists():
        pytest.skip("sample logs missing")
    no_truth = tmp_path / "plain.csv"
    shutil.copy(SAMPLES / "quad_healthy.csv", no_truth)
    result = cli("evaluate", no_truth)
    assert result.exit_code == 2
    assert "has ground truth" in result.stderr and "Traceback" not in result.stderr
