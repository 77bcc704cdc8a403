"""The NIS false-alarm budget (docs/algorithms.md section 1b): the design rate that a 100-hour
demonstration can show, alpha spread over every test, and the 100-hour bench's counting
(bench/false_alarm_budget.py) on one short healthy log."""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2, poisson

from logscan.detectors.budget import design_rate, proof_shortest_hours
from logscan.detectors.nis import NisDetector
from logscan.errors import ProfileError

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "bench"))
import false_alarm_budget as bench  # noqa: E402

SAMPLES = Path(__file__).resolve().parents[1] / "sample_logs"


def garwood_upper(n: int, hours: float) -> float:
    return chi2.ppf(0.975, 2 * n + 2) / (2 * hours)


def test_design_rate_of_the_100_hour_demonstration():
    # 3 alarms in 100 h still show 0.1/h (upper end 0.088), 4 do not (0.102); at 0.0174/h a
    # 100-hour run has at most 3 alarms with probability 0.9
    rate = design_rate(0.1, 100.0)
    assert garwood_upper(3, 100.0) <= 0.1 < garwood_upper(4, 100.0)
    assert rate == pytest.approx(0.01745, abs=1e-5)
    assert poisson.cdf(3, rate * 100.0) == pytest.approx(0.9, abs=1e-9)
    assert design_rate(0.1, None) == 0.1


@settings(max_examples=60, deadline=None)
@given(budget=st.floats(1e-3, 10.0), stretch=st.floats(1.0, 50.0))
def test_design_rate_passes_its_demonstration_with_probability_0_9(budget, stretch):
    hours = proof_shortest_hours(budget) * stretch
    rate = design_rate(budget, hours)
    c = max(n for n in range(int(budget * hours) + 2) if garwood_upper(n, hours) <= budget * (1 + 1e-12))
    assert 0 < rate < budget
    assert poisson.cdf(c, rate * hours) == pytest.approx(0.9, abs=1e-7)
    assert design_rate(budget, hours * 2) >= rate  # a longer demonstration allows more


def test_a_demonstration_too_short_to_show_the_budget_is_refused():
    assert proof_shortest_hours(0.1) == pytest.approx(36.89, abs=0.01)
    with pytest.raises(ProfileError, match="proof_hours"):
        NisDetector(proof_hours=10.0).check_params()
    NisDetector(proof_hours=40.0).check_params()
    NisDetector(proof_hours=None).check_params()


def test_alpha_spreads_the_design_rate_over_every_test():
    from logscan.needs import Needs
    from logscan.pipeline import load_profile_for, prepare

    path = SAMPLES / "quad_healthy.mcap"
    if not path.exists():
        pytest.skip(f"{path} missing")
    prepared = prepare(path, load_profile_for(path, None), Needs.of(ekf=()))
    trace = prepared.trace
    result = NisDetector().run(prepared.run, trace)
    tests = trace.updated.sum() + trace.updated.any(axis=1).sum()
    per_second = tests / (trace.t[-1] - trace.t[0])
    assert result.info["design_rate_per_hour"] == pytest.approx(design_rate(0.1, 100.0))
    assert result.info["alpha"] == pytest.approx(design_rate(0.1, 100.0) / (3600 * per_second))
    assert result.alarms == []


def test_exact_poisson_interval_of_the_bench():
    # the figure: 5 alarms in 36.7 h = 0.14/h, 95 % interval 0.04 - 0.32
    lower, upper = bench.poisson_interval(5, 36.7)
    assert (round(lower, 2), round(upper, 2)) == (0.04, 0.32)
    assert bench.poisson_interval(0, 100.0) == (0.0, pytest.approx(0.0369, abs=1e-4))


def test_bench_counts_false_alarms_per_detector_and_check_on_a_healthy_log():
    models = {model for model, _ in bench.SEED_BASE}
    jobs = bench.make_jobs(0.2, 90.0, dict.fromkeys(models, ("nis",)), {})
    assert {(j.model, j.aggressive) for j in jobs} == set(bench.SEED_BASE)
    # 0.2 h over the configurations in 90 s logs, rounded up so that at least 0.2 h run
    per_config = math.ceil(0.2 * 3600 / len(bench.SEED_BASE) / 90.0)
    assert len({j.seed for j in jobs}) == len(jobs) == per_config * len(bench.SEED_BASE)
    assert len(jobs) * 90.0 >= 0.2 * 3600
    run = bench.count_one(bench.Job("steer_by_wire", False, 12000, 30.0, ("nis",)))
    assert run["hours"] == pytest.approx(30.0 / 3600, rel=0.01)
    assert {"nis", "nis:all", "nis:yaw_rate"} <= set(run["counts"])
    assert sum(run["counts"].values()) == 0 and run["failures"] == []
    assert "| nis | 0 |" in bench.rate_table([run])


def test_bench_covers_every_simulated_model_and_only_the_chosen_ones():
    from logscan.simulate import SIMULATED_MODELS

    assert set(bench.MODELS) == {*SIMULATED_MODELS, "ground_robot"}
    assert {model for model, _ in bench.SEED_BASE} == set(bench.MODELS)
    jobs = bench.make_jobs(1.0, 1800.0, {"ground_robot": ("nis",), "ins": ("nis",)}, {})
    # ground_robot flies no aggressive variant: three configurations share the hour
    assert {(j.model, j.aggressive) for j in jobs} == {("ground_robot", False), ("ins", False), ("ins", True)}
    assert len(jobs) == 3 and len({j.seed for j in jobs}) == 3
