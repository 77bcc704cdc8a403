"""The encoded EKF checks and the NIS test on real filter traces of the sample logs."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

from logscan.detectors.base import any_per_row
from logscan.detectors.encoded_ekf import EncodedEkfDetector, coding_vectors
from logscan.detectors.nis import NisDetector, chi2_threshold, window_sums
from logscan.errors import NotTrainedError

SAMPLES = Path(__file__).resolve().parents[1] / "sample_logs"


@cache
def pipeline(name: str, store_gain: bool = False):
    """(aligned run, EKF trace, model, log) of a sample log through `logscan.pipeline.preparation`."""
    from logscan.needs import Needs
    from logscan.pipeline import load_profile_for, prepare

    path = SAMPLES / name
    if not path.exists():
        pytest.skip(f"{path} missing")
    # K and S always: the default e_x statistic (window_sum) normalises e_x by CV K S K^T CV^T
    prepared = prepare(path, load_profile_for(path, None), Needs.of(ekf=("K", "S", "y") if store_gain else ("K", "S")))
    return prepared.run, prepared.trace, prepared.model, prepared.log


# --- coding vector -------------------------------------------------------------------------------


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(0.0, 1e6) | st.just(float("nan")), min_size=12, max_size=12), st.floats(1.0, 1e6))
def test_coding_vector_equalises_alpha_sigma_and_respects_the_sum_bound(variances, r_max):
    P = np.array([variances])
    scale = np.ones(12)
    cv = coding_vectors(P, scale, 1e-9, r_max)
    assert np.isfinite(cv).all() and (cv > 0).all()
    assert cv.sum() <= r_max * (1 + 1e-12)
    sigma = np.sqrt(np.where(np.isnan(P), 0.0, P))
    sigma = np.maximum(sigma, 1e-9)  # the floor, NaN mapped onto it
    product = cv * sigma
    assert np.allclose(product, product[0, 0], rtol=1e-9)


def test_state_check_is_minus_cv_k_y():
    run, trace, model, _ = pipeline("quad_healthy.mcap", True)
    detector = EncodedEkfDetector()
    e_x, defined, cv = detector.state_check(trace, model)
    K = np.nan_to_num(trace.K)
    y = np.nan_to_num(trace.y)
    # e_x = CV x_prior - CV x_post = -CV K y
    expected = -np.einsum("kn,knm,km->k", cv, K, y)
    ordinary = defined & ~trace.seeded.any(axis=1)  # seeding steps set states directly, not by K y
    assert ordinary.sum() > 0.9 * defined.sum()
    # the trace keeps y as float32: each term carries its rounding (2^-24 relative), so the bound
    # scales with the sum of the terms' magnitudes
    magnitude = np.einsum("kn,knm,km->k", np.abs(cv), np.abs(K), np.abs(y))
    error = np.abs(e_x - expected)[ordinary]
    assert np.all(error <= 1e-6 * magnitude[ordinary] + 1e-12)


# --- encoded detector on sample logs -----------------------------------------------------------


def test_bit_flips_rejected_by_the_filter_raise_an_alarm_naming_the_sensor():
    run, trace, model, log = pipeline("quad_imu_bitflip.mcap")
    result = EncodedEkfDetector().run(run, trace, model=model)
    start = log.truth["events"][0]["start"]
    signals = {a.signal for a in result.alarms if start <= a.start <= start + 1.2}
    assert "rejected.accel" in signals


@pytest.mark.parametrize("variant", ["adaptive", "baseline"])
def test_rejected_checks_false_leaves_out_the_range_check_alarms_only(variant):
    run, trace, model, log = pipeline("quad_imu_bitflip.mcap")
    params = {"variant": variant, "threshold": 1.684} if variant == "baseline" else {}
    full = EncodedEkfDetector(**params).run(run, trace, model=model)
    bare = EncodedEkfDetector(rejected_checks=False, **params).run(run, trace, model=model)
    assert any(a.signal.startswith("rejected.") for a in full.alarms)
    assert not any(s.startswith("rejected.") for s in bare.series)
    kept = [(a.signal, a.start) for a in full.alarms if not a.signal.startswith("rejected.")]
    assert [(a.signal, a.start) for a in bare.alarms] == kept
    assert bare.info["rejected_samples"] == full.info["rejected_samples"] > 0


def test_rejected_checks_must_be_a_boolean():
    from logscan.errors import ProfileError

    with pytest.raises(ProfileError):
        EncodedEkfDetector(rejected_checks="no").check_params()


def test_covariance_corruption_is_caught_by_the_onboard_variance_check():
    run, trace, model, log = pipeline("quad_cov_corruption.mcap")
    result = EncodedEkfDetector().run(run, trace, model=model)
    assert result.info["variance_check"] == "onboard"
    event = log.truth["events"][0]
    hits = [a for a in result.alarms if a.signal == "e_v" and event["start"] <= a.start <= event["end"] + 1]
    assert hits and hits[0].start - event["start"] < 0.5


def test_observed_variance_check_is_centred_on_a_healthy_log():
    run, trace, model, _ = pipeline("quad_healthy.mcap", True)
    detector = EncodedEkfDetector(variance_check="observed", ex_statistic="raw")
    result = detector.run(run, trace, model=model)
    e_v = result.series["e_v"]
    e_x = result.series["e_x"]
    # observed minus predicted variance of e_x: near zero next to the variance itself
    assert abs(np.nanmedian(e_v)) < 0.5 * np.nanvar(e_x)
    assert not [a for a in result.alarms if a.signal == "e_v"]


def test_baseline_needs_training_then_its_threshold_is_the_healthy_peak():
    run, trace, model, _ = pipeline("sbw_healthy.mcap")
    baseline = EncodedEkfDetector(variant="baseline")
    with pytest.raises(NotTrainedError):
        baseline.run(run, trace, model=model)
    baseline.fit([run], [trace], model=model)
    e_x, defined, cv = baseline.state_check(trace, model)
    assert np.allclose(cv[0], [1, 1, 1, 1])  # the paper's CV_0 for steer-by-wire
    assert baseline.threshold_ == pytest.approx(np.nanmax(np.abs(e_x[defined])))
    assert baseline.run(run, trace, model=model).alarms == []  # strict: the peak itself never exceeds
    restored = EncodedEkfDetector.from_state(baseline.to_state())
    assert restored.threshold_ == baseline.threshold_


def test_healthy_logs_raise_no_encoded_alarm():
    for name in ("quad_healthy.mcap", "sbw_healthy.mcap"):
        run, trace, model, _ = pipeline(name)
        assert EncodedEkfDetector().run(run, trace, model=model).alarms == []


# --- NIS ------------------------------------------------------------------------------------------


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(0, 100), min_size=1, max_size=60), st.integers(1, 12))
def test_window_sums_match_brute_force(values, window):
    v = np.array(values)
    counts = np.arange(v.size) % 3 + 1
    sums, dof, full = window_sums(v, counts, window)
    for i in range(v.size):
        lo = max(0, i + 1 - window)
        assert sums[i] == pytest.approx(v[lo : i + 1].sum())
        assert dof[i] == counts[lo : i + 1].sum()
        assert full[i] == (i + 1 >= window)


@pytest.mark.parametrize("width", [1, 2, 3, 4, 5, 8, 12])
def test_any_per_row_is_numpys_row_any(width):
    mask = np.random.default_rng(width).random((50, width)) < 0.2
    assert any_per_row(mask).tolist() == mask.any(axis=1).tolist()
    assert any_per_row(np.asfortranarray(mask)).tolist() == mask.any(axis=1).tolist()


def test_chi2_threshold_matches_scipy():
    dof = np.array([0, 3, 30, 3, 60])
    out = chi2_threshold(dof, 1e-6)
    assert np.isnan(out[0])
    assert np.allclose(out[1:], chi2.ppf(1 - 1e-6, dof[1:]), rtol=1e-8)


def test_nis_names_the_biased_sensor_within_a_second():
    run, trace, model, log = pipeline("quad_imu_bias.mcap")
    result = NisDetector().run(run, trace, model=model)
    start = log.truth["events"][0]["start"]
    first = min((a for a in result.alarms if a.start >= start - 1), key=lambda a: a.start)
    assert first.signal in ("nis.accel", "nis.all") and first.start - start < 1.0
    assert any(a.signal == "nis.accel" for a in result.alarms)


def test_nis_alpha_follows_the_false_alarm_budget():
    run, trace, model, _ = pipeline("quad_healthy.mcap")
    result = NisDetector(budget_per_hour=0.1, proof_hours=None).run(run, trace, model=model)
    tests = trace.updated.sum() + trace.updated.any(axis=1).sum()
    per_second = tests / (trace.t[-1] - trace.t[0])
    assert result.info["alpha"] == pytest.approx(0.1 / (3600 * per_second))
    assert result.alarms == []


def test_onboard_state_corruption_is_caught_by_the_state_comparison(tmp_path, cli):
    from logscan.pipeline import analyze_log

    path = tmp_path / "sc.mcap"
    result = cli(
        "simulate",
        "quadcopter",
        "--fault",
        "state-corruption",
        "--at",
        "20",
        "--duration",
        "40",
        "--seed",
        "11",
        "-o",
        path,
        "-q",
    )
    assert result.exit_code == 0, result.stderr
    analysis = analyze_log(path, detector_names=["encoded_ekf"])
    hits = [a for a in analysis.alarms if a.signal == "e_s"]
    assert hits and 20.0 <= hits[0].start < 20.5
    assert all(a.start >= 20.0 for a in analysis.alarms)  # nothing before the upset


def test_detector_settings_in_the_profile_docs_are_accepted():
    import re
    import tomllib

    from logscan.detectors.registry import default_registry

    text = (Path(__file__).resolve().parents[1] / "docs" / "profiles.md").read_text(encoding="utf-8")
    registry = default_registry()
    seen = 0
    for block in re.findall(r"```toml\n(.*?)```", text, re.S):
        for name, options in tomllib.loads(block).get("detectors", {}).items():
            options = {k: v for k, v in options.items() if k != "enabled"}
            registry.create(name, options).check_params()  # raises ProfileError on a bad setting
            seen += 1
    assert seen >= 3
    for name in ("encoded_ekf", "nis"):
        for key in registry.get(name).defaults:
            assert f"`{key}`" in text, f"docs/profiles.md does not describe {name}.{key}"
