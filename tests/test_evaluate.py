"""`logscan evaluate`: scores per detector, per check and per fault kind against ground truth."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from logscan.alarms import AlarmInterval
from logscan.results import DetectorResult, FaultEvent
from logscan.tasks import evaluate_logs
from logscan.verdict.evaluation import (
    Evaluation,
    LogEvaluation,
    alarm_groups,
    check_key,
    evaluate_analysis,
    merge_intervals,
    score_groups,
)

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
    merged = merge_intervals([(5.0, 6.0), (1.0, 2.0), (1.5, 3.0), (3.0, 4.0)])
    assert [(span.start, span.end) for span in merged] == [(1.0, 4.0), (5.0, 6.0)]


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


def test_merged_spans_are_scored_with_recovery_window_and_onset_flag():
    groups = {"d": [(8.0, 9.0), (8.5, 10.2), (10.5, 11.0), (14.0, 14.2), (14.1, 14.3)]}
    score = score_groups([FaultEvent(10.0, 12.0)], groups, duration_s=60.0, recovery_s=5.0)["d"]
    # (8, 10.2) is on at the onset, (10.5, 11) detects, (14, 14.3) is one recovery span
    assert (score.tp, score.fp, score.at_onset, score.recovery_alarms, score.n_alarms) == (1, 0, 1, 1, 3)
    assert score.latencies_s == [pytest.approx(0.5)]


def test_evaluate_analysis_scores_the_truth_transients_apart():
    result = DetectorResult("nis", series={"nis.accel": None}, alarms=[alarm(30.0, 30.2, "nis.accel", "nis")])
    truth = {"events": [], "transients": [{"kind": "glitch", "target": "accel.x", "start": 30.0, "end": 30.01}]}
    analysis = SimpleNamespace(
        path="glitchy.mcap",
        duration_s=60.0,
        events=[],
        results=[result],
        log=SimpleNamespace(truth=truth),
        model=SimpleNamespace(name="quadcopter"),
    )
    log = evaluate_analysis(analysis, recovery_s=2.0)
    assert [t.kind for t in log.transients] == ["glitch"]
    for key in ("nis", "nis:accel"):
        assert (log.scores[key].transient_alarms, log.scores[key].fp, log.scores[key].healthy_fp) == (1, 0, 0)


def test_by_kind_counts_events_active_at_onset():
    event = FaultEvent(10.0, 12.0, "bias")
    scores = score_groups([event], {"d": [(9.0, 10.5)]}, duration_s=60.0)
    evaluation = Evaluation(logs=[LogEvaluation("a.mcap", "quadcopter", 60.0, [event], scores)])
    entry = evaluation.by_kind("d")["quadcopter/bias"]
    assert (entry.tp, entry.n_events, entry.at_onset) == (0, 1, 1)
    assert evaluation.to_dict()["by_kind"]["d"]["quadcopter/bias"]["at_onset"] == 1


def test_nis_detects_the_accelerometer_bias_and_names_the_sensor(evaluation):
    by_kind = evaluation.by_kind("nis:accel")["quadcopter/bias"]
    assert (by_kind.tp, by_kind.n_events) == (1, 1)
    assert by_kind.max_latency_s < 1.0
    assert evaluation.by_kind("nis")["quadcopter/bias"].tp == 1


def test_encoded_check_catches_the_bit_flips_and_the_bias_only_by_its_window_sum(evaluation):
    e_x = evaluation.by_kind("encoded_ekf:e_x")
    assert e_x["quadcopter/bitflip"].tp == 1 and e_x["quadcopter/bitflip"].max_latency_s < 1.0
    # the 1 m/s^2 bias moves e_x by a fraction of its spread per sample: the default window sum
    # accumulates it (docs/algorithms.md section 1.9), not at once but within its window of 1 s
    bias = e_x["quadcopter/bias"]
    assert bias.tp == 1 and 0.1 < bias.max_latency_s < 2.0


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
    result = cli("evaluate", BIAS, no_truth, garbage, "--json", out, "--grace", "0.5", "--recovery", "3")
    assert result.exit_code == 2, result.stderr  # the corrupt log is bad input
    assert "Traceback" not in result.stderr
    errors = [line for line in result.stderr.splitlines() if line.startswith("logscan: error: ")]
    assert len(errors) == 1 and "garbage.mcap" in errors[0]
    assert "skipped 1 log(s) without ground truth: no_truth.csv" in result.stdout
    assert "nis:accel" in result.stdout and "quadcopter/bias" in result.stdout
    assert "grace 0.5 s, recovery 3 s" in result.stdout
    header = next(line for line in result.stdout.splitlines() if line.startswith("detector / check"))
    assert "at onset" in header and "recovery" in header and "transient" in header
    data = json.loads(out.read_text())
    assert data["grace_s"] == 0.5 and data["recovery_s"] == 3.0 and data["n_logs"] == 1
    assert {"at_onset", "recovery_alarms", "transient_alarms"} <= set(data["scores"]["nis"])
    assert "active_at_onset" in data["logs"][0]["scores"]["nis"]["events"][0]
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


def test_a_truth_file_beside_a_ulog_is_evaluated_as_analyze_scores_it(tmp_path):
    """A real PX4 flight with a `<log>.truth.json` beside it: `analyze` scores against it, so
    `evaluate` evaluates it (it had skipped the log as one without ground truth)."""
    from conftest import need_testdata

    log = tmp_path / "flight.ulg"
    shutil.copy(need_testdata("px4-ulog-extra/robologs_fmu_v5_test.ulg"), log)
    truth = {"events": [{"kind": "bias", "target": "battery", "start": 1.0, "end": 3.0}]}
    (tmp_path / "flight.truth.json").write_text(json.dumps(truth))
    evaluation = evaluate_logs([str(log)])
    assert not evaluation.skipped and not evaluation.failures
    assert [len(one.events) for one in evaluation.logs] == [1]
