"""KGN's parts against brute force (docs/algorithms.md section 3): the operating-point bins
(detectors/kgn_bins.py), rho from the budget (detectors/kgn_budget.py) and the probe's slice from a
checkpoint (detectors/kgn_probe.py)."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from logscan.detectors.kgn_bins import bin_keys, bin_words, fit_edges, quantity_series
from logscan.detectors.kgn_budget import alarm_statistic, budget_rho
from logscan.detectors.kgn_probe import slice_run
from logscan.detectors.kgn_windows import column_norms

SAMPLES = Path(__file__).resolve().parents[1] / "sample_logs"


def test_quantities_are_the_models_speed_yaw_rate_and_thrust():
    x = np.array([[3.0, 4.0, 0.0, -0.5], [0.0, 0.0, 1.0, 0.25]])
    trace = SimpleNamespace(state_names=["vx", "vy", "vz", "r"], x_post=x)
    run = SimpleNamespace(input_names=["thrust", "tau_x"], u=np.array([[11.0, 0.1], [12.0, 0.2]]))
    q = quantity_series(run, trace)
    np.testing.assert_allclose(q["speed"], [5.0, 1.0])
    np.testing.assert_allclose(q["yaw_rate"], [0.5, 0.25])
    np.testing.assert_allclose(q["thrust"], [11.0, 12.0])
    # a model without them (dc_motor's current and speed, voltage input): speed only
    bare = quantity_series(
        SimpleNamespace(input_names=["Va"], u=np.ones((2, 1))),
        SimpleNamespace(state_names=["i_a", "w_v"], x_post=x[:, :2]),
    )
    assert set(bare) == {"speed"}


def test_edges_are_per_mode_quantiles_and_a_mode_with_few_windows_is_not_split():
    rng = np.random.default_rng(1)
    modes = np.array(["0"] * 15 + ["1"] * 200, dtype=object)
    speed = np.concatenate([rng.uniform(0, 0.1, 15), rng.uniform(0, 10, 200)])
    edges = fit_edges(modes, {"speed": speed}, op_bins=3, min_windows=10)
    assert edges["0"]["speed"] == []  # 15 windows hold one bin of 10, not two
    np.testing.assert_allclose(edges["1"]["speed"], np.quantile(speed[15:], [1 / 3, 2 / 3]))
    keys = bin_keys(modes, {"speed": speed}, edges)
    for mode, value, key in zip(modes, speed, keys):
        if mode == "0":
            assert key == "0"
        else:
            index = sum(value >= e for e in edges["1"]["speed"])
            assert key == f"1 speed{index}"
    # an unseen mode and a NaN quantity have no bin
    assert bin_keys(np.array(["7", "1"], dtype=object), {"speed": np.array([1.0, np.nan])}, edges) == [None, None]
    assert bin_words("1 speed0", edges) == f"mode 1, speed -inf to {edges['1']['speed'][0]:.3g}"


def test_the_alarm_statistic_is_the_smallest_of_n_persist_consecutive_judged_windows():
    """Windows not judged (NaN) are skipped, as the shared alarm logic skips them: 5 and 6 around a
    gap make an alarm of two windows over 4.5."""
    g = np.array([1.0, 5.0, 4.0, np.nan, 6.0, 7.0, 2.0])
    np.testing.assert_array_equal(alarm_statistic(g, 2), [1.0, 4.0, 4.0, 6.0, 2.0])
    np.testing.assert_array_equal(alarm_statistic(g, 1), [1.0, 5.0, 4.0, 6.0, 7.0, 2.0])
    assert alarm_statistic(np.array([np.nan, 3.0]), 2).size == 0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rho_from_the_budget_bounds_an_exponential_and_a_gaussian_tail(seed):
    """For exponential statistics (the tail model's own law) and half-normal ones (lighter), the
    probability beyond rho is within alpha: the margins make rho conservative, never below the
    training maximum."""
    rng = np.random.default_rng(seed)
    alpha = 1e-6
    exp = rng.exponential(1.0, 2000)
    fit = budget_rho(exp, alpha)
    assert math.exp(-fit["rho"]) <= alpha and fit["rho"] >= exp.max()
    assert fit["rho"] < -math.log(alpha) * 1.5  # the margin is not a blanket factor
    half = np.abs(rng.normal(size=2000))
    rho = budget_rho(half, alpha)["rho"]
    assert math.erfc(rho / math.sqrt(2)) <= alpha
    few = budget_rho(np.array([1.0, 2.0, 3.0]), alpha)
    assert few["rho"] == 4.0 and "maximum + 1" in few["rule"]


def test_the_probe_slice_from_an_exact_checkpoint_reproduces_the_logs_gain():
    """The slice convention (no update at the checkpoint's step, the filter started from its
    posterior): with the exact (x_post, P_post) the re-filtered gain equals the whole run's."""
    from logscan.filters.ekf import run_ekf
    from logscan.pipeline import load_profile_for, prepare

    path = SAMPLES / "quad_healthy.mcap"
    if not path.exists():
        pytest.skip(f"{path} missing (run sample_logs/make_samples.py)")
    from logscan.needs import Needs

    prepared = prepare(path, load_profile_for(path, None), lambda run: Needs.of(ekf=()))
    run, model = prepared.run, prepared.model
    full = run_ekf(model, run, full_P=True, store_S=False, store_innovations=False)
    start, stop = 4000, 4600
    part = run_ekf(model, slice_run(run, start, stop), x0=full.x_post[start], P0=full.P_post[start], store_S=False)
    np.testing.assert_allclose(column_norms(part.K)[1:], column_norms(full.K[start + 1 : stop]), rtol=1e-9)
