"""Recovery end to end through `logscan analyze`: a hierarchical profile's loops are each filtered
and checked, [recovery] recovers every loop from consistent checkpoints, and the JSON summary (in
its schema) and the report carry the loops and one record per anomaly."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import jsonschema
import pytest

from logscan.pipeline import analyze_log, load_profile_for
from logscan.pipeline.loops import recover_analysis

SCHEMA = Path(__file__).resolve().parents[1] / "docs" / "schema" / "analyze-summary.schema.json"


@pytest.fixture(scope="module")
def robot(tmp_path_factory):
    """The paper's scenario (attacks on mocap and both encoders at 3.25-5 s and 8.25-10 s)."""
    from logscan.cli.main import main

    path = tmp_path_factory.mktemp("robot") / "robot.mcap"
    with pytest.raises(SystemExit) as done:
        main(["simulate", "ground_robot", "--seed", "7", "-o", str(path)])
    assert done.value.code in (0, None)
    return path


def _profile(robot: Path, tmp_path: Path, recovery: str) -> Path:
    profile = replace(load_profile_for(robot, None).profile, recovery=None)  # the log's own replaced
    text = profile.to_toml() + ("" if profile.detectors else "\n[detectors.nis]\n")  # nis alone: short log
    out = tmp_path / "robot.profile.toml"
    out.write_text(text + "\n[recovery]\n" + recovery + "\n")
    return out


def test_every_loop_is_checked_and_counts_in_the_verdict(robot):
    analysis = analyze_log(robot)
    assert set(analysis.loops) == {"left_motor", "right_motor"}
    motor = analysis.loops["left_motor"]
    assert motor.run.dt == pytest.approx(0.01) and analysis.run.dt == pytest.approx(0.1)
    assert motor.alarms, "the +-20000 encoder attacks must alarm in the motor loop"
    assert len(analysis.alarms) == sum(len(r.alarms) for r in analysis.results) + sum(
        len(loop.alarms) for loop in analysis.loops.values()
    )


def test_oracle_recovery_from_a_consistent_checkpoint_before_each_attack(robot, tmp_path):
    profile = _profile(robot, tmp_path, 'detector = "oracle"\ndetection_time_s = 0.25')
    analysis = analyze_log(robot, profile)
    records = analysis.recovery.anomalies
    assert records and all(r.t_checkpoint is not None for r in records)
    first = records[0]
    assert first.t_checkpoint < 3.25 - 0.1  # before the attack, by more than the slowest period
    assert set(first.checkpoint_steps) == {"outer", "left_motor", "right_motor"}
    steps = first.checkpoint_steps  # one instant in every loop: 10 Hz and 100 Hz steps agree
    assert steps["left_motor"] == 10 * steps["outer"] and steps["right_motor"] == steps["left_motor"]


def test_recovery_in_the_json_summary_and_the_report(cli, robot, tmp_path):
    profile = _profile(robot, tmp_path, 'detector = "oracle"')
    out = tmp_path / "s.json"
    result = cli("analyze", robot, "--profile", profile, "--json", out, "-o", tmp_path / "report.html")
    assert result.exit_code == 1, result.stderr
    assert "  loop left_motor: " in result.stdout and "  recovery (refilter): " in result.stdout
    assert "from the checkpoint at 3.10 s" in result.stdout  # the latest one > 0.1 s (slowest period) before 3.25 s
    summary = json.loads(out.read_text())
    jsonschema.validate(summary, json.loads(SCHEMA.read_text()))
    entry = summary["logs"][0]
    assert entry["recovery"]["method"] == "refilter" and entry["recovery"]["anomalies"]
    assert set(entry["loops"]) == {"left_motor", "right_motor"}
    html = (tmp_path / "report.html").read_text()
    assert 'id="recovery"' in html and "outer: x" in html and "left_motor: w" in html
    assert "dotted: the true state" in html  # the simulator's truth names each loop's true-state channels


def test_a_detector_drives_recovery_and_a_missing_truth_is_said(robot, tmp_path):
    by_nis = analyze_log(robot, _profile(robot, tmp_path, 'detector = "nis"'))
    assert by_nis.recovery.anomalies  # the nis alarms drove it, with their groups as targets
    assert any(r.targets is not None for r in by_nis.recovery.anomalies)
    oracle = analyze_log(robot, _profile(robot, tmp_path, 'detector = "oracle"'))
    oracle.prepared.log.truth = None  # a log without ground truth
    assert recover_analysis(oracle) is None
    assert any('"oracle" needs the log\'s ground truth' in w for w in oracle.warnings)
