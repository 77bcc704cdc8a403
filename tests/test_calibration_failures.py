"""A calibration that did not work is said to have failed, never written as if it had worked.

`logscan train --calibrate` whose loop does not converge, whose Q scale of a block runs to its
bound (the likelihood still falling there: the logs do not fix it) or whose noise_std runs to its
ceiling writes the tables and the report marked failed (``calibration.failures``), says so in
its summary and exits 2; `logscan analyze --tables` refuses them with a command that is valid.
"""

from __future__ import annotations

import json
import math
import shlex

import pytest
from conftest import need_testdata

import logscan.training.calibration
from logscan.pipeline import load_profile_for
from logscan.training.calibration import CAL_CEILING, calibration_failures, calibration_lines
from logscan.training.process_noise import Q_SCALE_MIN


@pytest.fixture(scope="module")
def q_far_too_large(tmp_path_factory):
    """A simulated quadcopter flight and a profile whose process noise is 10^6 times its own: the
    Q scale it needs (1e-6) lies beyond the bound (1e-4)."""
    from logscan.simulate import simulate, write_simulation

    root = tmp_path_factory.mktemp("qbound")
    log = root / "healthy.mcap"
    write_simulation(simulate("quadcopter", [], duration=20.0, seed=8301), log)
    root_factor = math.sqrt(1e6)
    params = f"params = {{ q_accel = {0.2 * root_factor:g}, q_angacc = {1.0 * root_factor:g} }}\n\n[inputs]"
    profile = root / "q_huge.toml"
    profile.write_text(load_profile_for(log, None).text.replace("[inputs]", params, 1))
    return log, profile


def _suggested(stderr: str) -> list[str]:
    words = shlex.split(stderr.split("`")[1])
    assert words[0] == "logscan"
    return words[1:]


def test_a_q_scale_at_its_bound_is_a_failed_calibration_analyze_refuses(cli, q_far_too_large, tmp_path):
    log, profile = q_far_too_large
    tables = tmp_path / "q.tables.json"
    trained = cli("train", log, "--profile", profile, "--calibrate", "-o", tables)
    assert trained.exit_code == 2
    assert "calibration failed" in trained.stderr and "ran to its bound (Q x 0.0001)" in trained.stderr
    assert len(trained.stderr.strip().splitlines()) == 1 and "Traceback" not in trained.stderr
    assert "FAILED: " in trained.stdout  # the summary
    calibration = json.loads(tables.read_text())["calibration"]
    bounded = [b for b, entry in calibration["process_noise_blocks"].items() if entry["scale"] <= Q_SCALE_MIN * 1.0001]
    assert bounded and all(any(b in f for f in calibration["failures"]) for b in bounded)
    assert 'id="calibration-failed"' in tables.with_suffix(".html").read_text()  # the training report

    refused = cli("analyze", log, "--profile", profile, "--tables", tables, "--no-report")
    assert refused.exit_code == 2 and "the tables' calibration failed" in refused.stderr
    args = _suggested(refused.stderr)  # valid: it runs and fails the same way, not as a usage error
    assert args[:2] == ["train", "HEALTHY_LOG..."] and args[args.index("--profile") + 1] == str(profile)
    again = cli(*[str(log) if a == "HEALTHY_LOG..." else a for a in args], "--no-report")
    assert again.exit_code == 2 and "calibration failed" in again.stderr and "Usage" not in again.stderr


@pytest.mark.testdata("px4-ulog/sample_px4_events.ulg")
def test_a_calibration_that_does_not_converge_is_failed_and_its_command_retrains(cli, tmp_path, monkeypatch):
    flight = need_testdata("px4-ulog/sample_px4_events.ulg")
    tables = tmp_path / "px4.tables.json"
    with monkeypatch.context() as forced:
        forced.setattr(logscan.training.calibration, "CAL_ITERATIONS", 1)
        trained = cli("train", flight, "--calibrate", "-o", tables, "--no-report")
    assert trained.exit_code == 2 and "not converged in 1 iteration(s)" in trained.stderr
    document = json.loads(tables.read_text())
    assert document["calibration"]["failures"] == ["not converged in 1 iteration(s)"]
    refused = cli("analyze", flight, "--tables", tables, "--no-report")
    assert refused.exit_code == 2 and "not converged" in refused.stderr
    args = [str(flight) if a == "HEALTHY_LOG..." else a for a in _suggested(refused.stderr)]
    assert cli(*args, "--no-report", "-q").exit_code == 0  # with its iterations, the same flight converges
    assert json.loads(tables.read_text())["calibration"]["failures"] == []
    analysed = cli("analyze", flight, "--tables", tables, "--no-report", "--allow-partial")
    assert analysed.exit_code in (0, 1), analysed.stderr


def test_a_noise_at_its_ceiling_is_a_failure_and_a_worked_calibration_has_none():
    group = {"calibrated": True, "noise_factor": math.sqrt(CAL_CEILING), "at_floor": False, "logged_noise": False}
    group |= {"noise_std": [1000.0], "profile_noise_std": [1.0], "updates": 50, "nis_at_floor": None}
    group |= {"mean_nis_per_output_before": 1e6, "mean_nis_per_output_after": 3.0}
    document = {"groups": {"baro": group}}
    failures = logscan.training.calibration._failures(document, True, 3)
    assert failures == ["the noise of baro ran to its ceiling (noise_std x 1e+03)"]
    assert calibration_lines({**document, "failures": failures})[0].startswith("  FAILED: the noise of baro")
    ok = {"groups": {"baro": {**group, "noise_factor": 2.0}}}
    assert logscan.training.calibration._failures(ok, True, 3) == [] and calibration_failures(None) == []
