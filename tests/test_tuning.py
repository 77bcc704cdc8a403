"""`logscan train --tune` (logscan.training.tuning): the threshold multipliers chosen by the rule (smallest
value without false alarms on the healthy logs plus the margin, F1 on labelled logs breaking ties),
the filter run once per log, and the choice applied by `logscan analyze --tables`."""

from __future__ import annotations

import json

import pytest

from logscan.pipeline import create_detectors, load_profile_for
from logscan.training.tables import apply_tables
from logscan.training.tuning import TUNE_GRID, TUNE_MARGIN


@pytest.fixture(scope="module")
def tuned(tmp_path_factory):
    """One healthy and one labelled sample log (a -10 % motor offset at 30-40 s)."""
    from conftest import SAMPLES

    from logscan.training.train import train_logs
    from logscan.training.tuning import tuning_lines

    logs = [str(SAMPLES / "quad_healthy.mcap"), str(SAMPLES / "quad_motor_offset.mcap")]
    document = train_logs(logs, None, tune=True)
    out = tmp_path_factory.mktemp("tune") / "t.json"
    out.write_text(json.dumps(document))
    return (
        out,
        json.loads(out.read_text()),
        "threshold multipliers tuned\n" + "\n".join(tuning_lines(document["tuning"])),
    )


def test_the_command_prints_the_choice(cli, sample, tmp_path):
    out = tmp_path / "t.json"
    result = cli("train", sample("quad_healthy.mcap"), "--tune", "-o", str(out), "--no-report")
    assert result.exit_code == 0, result.stderr
    assert "encoded_ekf.rho =" in result.stdout and json.loads(out.read_text())["tuning"]["encoded_ekf"]


def test_the_rule_picks_the_smallest_false_alarm_free_value_plus_the_margin(tuned):
    _, document, stdout = tuned
    assert "threshold multipliers tuned" in stdout and "encoded_ekf.rho =" in stdout
    for param in ("rho", "rho_v", "rho_s"):
        entry = document["tuning"]["encoded_ekf"][param]
        counts, grid = entry["false_alarms"], entry["grid"]
        assert grid == list(TUNE_GRID) and len(counts) == len(grid)
        free = entry["smallest_without_false_alarms"]
        i = grid.index(free)
        assert all(c == 0 for c in counts[i:]) and (i == 0 or counts[i - 1] > 0)
        assert free + TUNE_MARGIN - 1e-9 <= entry["value"] <= free + 2 * TUNE_MARGIN + 1e-9
        assert len(entry["f1"]) == len(grid)  # the labelled log scored at every value
    assert document["tuning"]["encoded_ekf"]["rho"]["false_alarms"][0] > 0  # rho = 1 alarms on healthy


def test_analyze_with_the_tables_runs_with_the_tuned_multipliers(tuned, sample):
    path, document, _ = tuned
    loaded = load_profile_for(sample("quad_healthy.mcap"), None)
    (detector,) = apply_tables(create_detectors(loaded, ["encoded_ekf"]), str(path), loaded.profile)
    for param in ("rho", "rho_v", "rho_s"):
        assert detector.params[param] == document["tuning"]["encoded_ekf"][param]["value"]


def test_the_training_report_shows_the_tuned_multipliers(tuned):
    from logscan.report.training_page import render_training_html

    _, document, _ = tuned
    page = render_training_html(document)
    assert 'id="tuning"' in page and "encoded_ekf.rho_v" in page
    rho = document["tuning"]["encoded_ekf"]["rho"]
    assert f"<td>{rho['value']:g}</td>" in page
