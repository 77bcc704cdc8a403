"""The encoded EKF's e_x statistics (docs/algorithms.md section 1.2): raw (the paper's adaptive
band), normalised (e_x over the spread the filter predicts) and window_sum (that summed over W)."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pytest
from scipy.special import ndtr

from logscan.detectors.budget import design_rate
from logscan.detectors.encoded_ekf import EncodedEkfDetector
from logscan.detectors.normalised_check import normal_bound, normalised_series, window_sum
from logscan.errors import ProfileError

SAMPLES = Path(__file__).resolve().parents[1] / "sample_logs"


@cache
def prepared(name: str, gain: bool = True):
    from logscan.needs import Needs
    from logscan.pipeline import load_profile_for, prepare

    path = SAMPLES / name
    if not path.exists():
        pytest.skip(f"{path} missing")
    return prepare(path, load_profile_for(path, None), Needs.of(ekf=("K", "S") if gain else ()))


def run(name: str, **params):
    p = prepared(name)
    return EncodedEkfDetector(**params).run(p.run, p.trace, model=p.model), p.log.truth


def test_the_bound_spends_the_design_rate_over_every_judged_step():
    rate = design_rate(0.1, 100.0)
    bound = normal_bound(rate, 100.0)
    # two-sided N(0, 1) tail per test x tests per hour = the design rate (union bound)
    assert 2.0 * ndtr(-bound) * 3600.0 * 100.0 == pytest.approx(rate, rel=1e-9)
    assert 5.0 < bound < 6.0
    assert normal_bound(rate, 10.0) < bound  # fewer tests per hour: a lower bound


def test_window_sum_is_the_trailing_sum_over_sqrt_w_and_a_nan_is_an_exceedance():
    rng = np.random.default_rng(3)
    z = rng.normal(size=40)
    valid = np.ones(40, dtype=bool)
    valid[::7] = False  # steps without a judged e_x are skipped, not summed as 0
    z[20] = np.nan  # a diverged filter
    out, warm = window_sum(z, valid, 5)
    steps = np.flatnonzero(valid)
    for i, k in enumerate(steps):
        window = steps[max(0, i - 4) : i + 1]
        expected = z[window].sum() / np.sqrt(5)
        if np.isnan(z[window]).any():
            assert out[k] == np.inf
        else:
            assert out[k] == pytest.approx(expected, rel=1e-12, abs=1e-12)
        assert warm[k] == (i >= 4)
    assert np.isnan(out[~valid]).all() and not warm[~valid].any()


def test_a_step_without_predicted_spread_is_not_judged_but_a_divergence_is():
    e_x = np.array([1.0, 0.0, np.nan, 2.0])
    defined = np.array([True, True, True, False])
    z, valid = normalised_series(e_x, defined, np.array([4.0, 0.0, np.nan, 1.0]))
    assert valid.tolist() == [True, False, True, False]
    assert z[0] == 0.5 and np.isnan(z[2])


@pytest.mark.parametrize("name", ["quad_healthy.mcap", "sbw_healthy.mcap", "jackal_healthy.mcap"])
def test_the_normalised_check_is_unit_normal_and_white_on_a_healthy_log(name):
    result, _ = run(name, ex_statistic="normalised")
    z = result.series["e_x"]
    z = z[np.isfinite(z)]
    assert 0.9 < z.std() < 1.1 and abs(z.mean()) < 0.05
    lag1 = np.corrcoef(z[:-1], z[1:])[0, 1]
    assert abs(lag1) < 0.1
    assert not [a for a in result.alarms if a.signal == "e_x"]


@pytest.mark.parametrize("statistic", ["raw", "normalised", "window_sum"])
def test_no_e_x_alarm_on_the_healthy_logs(statistic):
    for name in ("quad_healthy.mcap", "sbw_healthy.mcap"):
        result, _ = run(name, ex_statistic=statistic)
        assert not [a for a in result.alarms if a.signal == "e_x"], (name, statistic)
        assert result.info["ex_statistic"] == statistic


def test_the_window_sum_catches_the_motor_offset_the_raw_band_absorbs():
    # -10 % thrust on motor 1: a step of e_x of about 2.5 healthy spreads (docs/algorithms.md 1.10)
    raw, truth = run("quad_motor_offset.mcap", ex_statistic="raw")
    summed, _ = run("quad_motor_offset.mcap")
    event = truth["events"][0]
    inside = lambda r: [a for a in r.alarms if a.signal == "e_x" and event["start"] <= a.start <= event["end"]]  # noqa: E731
    assert not inside(raw)
    hits = inside(summed)
    assert hits and hits[0].start - event["start"] < 0.5
    assert summed.info["ex_statistic"] == "window_sum" and 5.0 < summed.info["ex_bound"] < 6.0


def test_rho_given_is_the_bound_of_the_normalised_statistics():
    result, _ = run("quad_healthy.mcap", rho=7.5)
    assert result.info["ex_bound"] == 7.5
    np.testing.assert_array_equal(result.thresholds["e_x"].upper[np.isfinite(result.series["e_x"])], 7.5)


def test_the_normalised_statistics_refuse_a_trace_without_their_predicted_variance():
    p = prepared("quad_healthy.mcap", gain=False)
    with pytest.raises(ProfileError, match="needs e_x's predicted variance"):
        EncodedEkfDetector().run(p.run, p.trace, model=p.model)
    # the raw statistic needs neither (on a log with on-board variances)
    EncodedEkfDetector(ex_statistic="raw").run(p.run, p.trace, model=p.model)


def test_the_baseline_keeps_the_raw_e_x_and_its_fixed_threshold():
    result, _ = run("quad_healthy.mcap", variant="baseline", threshold=2.0)
    assert result.info["variant"] == "baseline" and "ex_bound" not in result.info
    e_x, defined, _ = EncodedEkfDetector(variant="baseline").state_check(prepared("quad_healthy.mcap").trace)
    np.testing.assert_allclose(result.series["e_x"][defined], e_x[defined], rtol=1e-6, atol=1e-9)  # kept as float32


@pytest.mark.parametrize("params", [{"ex_statistic": "sum"}, {"proof_hours": 1.0}, {"budget_per_hour": 0.0}])
def test_bad_settings_are_refused(params):
    with pytest.raises(ProfileError):
        EncodedEkfDetector(**params).check_params()


def test_an_angle_wrapped_by_the_filter_is_no_jump_of_e_x():
    p = prepared("quad_healthy.mcap")
    trace = p.trace
    detector = EncodedEkfDetector(ex_statistic="raw")
    before, defined, _ = detector.state_check(trace, p.model)
    yaw = trace.state_names.index("yaw")
    k = int(np.flatnonzero(defined)[100])
    original = trace.x_post[k, yaw]
    try:
        trace.x_post[k, yaw] = original + 2.0 * np.pi  # the same heading, wrapped the other way
        after, _, _ = detector.state_check(trace, p.model)
    finally:
        trace.x_post[k, yaw] = original
    assert after[k] == pytest.approx(before[k], abs=1e-9)
