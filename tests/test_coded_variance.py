"""The encoded check's predicted variance computed inside the EKF (`logscan.filters.coding`): the
same CV K S K^T CV^T the detector computes from a stored K and S, without either being kept."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pytest

from logscan.detectors.encoded_ekf import EncodedEkfDetector, coding_vectors
from logscan.detectors.normalised_check import predicted_variance
from logscan.errors import InternalError
from logscan.filters.ekf import run_ekf
from logscan.needs import CodedVariance, Needs
from logscan.pipeline import analyze_log, load_profile_for, prepare
from logscan.pipeline.refilter import run_ekf_parts

SAMPLES = Path(__file__).resolve().parents[1] / "sample_logs"


@cache
def prepared(name: str):
    path = SAMPLES / name
    if not path.exists():
        pytest.skip(f"{path} missing")
    return prepare(path, load_profile_for(path, None), Needs.of(ekf=()))


@pytest.mark.parametrize(
    ("name", "coding"),
    [
        ("quad_imu_bias.mcap", CodedVariance(1e-9, 1e6)),
        ("quad_imu_bias.mcap", CodedVariance(1e-3, 50.0)),  # the floor and the sum bound both bite
        ("ground_robot_attack.mcap", CodedVariance(1e-9, 1e6)),
    ],
)
def test_the_filter_gives_the_variance_the_detector_computes_from_k_and_s(name, coding):
    p = prepared(name)
    trace = run_ekf(p.model, p.run, store_gain=True, store_S=True, store_innovations=False, coding=coding)
    scale = p.model.state_scale()
    expected = predicted_variance(
        lambda rows: coding_vectors(trace.P_prior_diag[rows], scale, coding.sigma_floor, coding.r_max),
        trace.K,
        trace.S,
    )
    got = trace.ex_variance
    assert got is not None and got.shape == expected.shape
    updated = trace.m_k > 0
    assert updated.sum() > 100 and np.all(got[~updated] == 0.0) and np.all(expected[~updated] == 0.0)
    # the detector's coding vector is float32 arithmetic on the float32 diag(P): a 1e-6 relative scale
    np.testing.assert_allclose(got[updated], expected[updated], rtol=2e-6)
    assert np.all(got[updated] > 0.0)


def test_a_trace_without_coding_holds_no_variance_and_the_pipeline_keeps_no_gain():
    p = prepared("quad_healthy.mcap")
    assert run_ekf(p.model, p.run, store_gain=False, store_S=False).ex_variance is None
    analysis = analyze_log(SAMPLES / "quad_healthy.mcap", detector_names=["encoded_ekf"], free_series=False)
    trace = analysis.prepared.trace
    assert trace.K is None and trace.S is None and trace.ex_variance is not None
    assert analysis.results[0].info["ex_statistic"] == "window_sum"


def test_two_coding_vectors_for_one_filter_are_refused():
    p = prepared("quad_healthy.mcap")
    parts = frozenset({CodedVariance(1e-9, 1e6), CodedVariance(1e-9, 10.0)})
    with pytest.raises(InternalError, match="2 different coding vectors"):
        run_ekf_parts(p.model, p.run, parts)


def test_the_detector_judges_alike_from_the_filters_variance_and_from_k_and_s():
    p = prepared("quad_imu_bias.mcap")
    detector = EncodedEkfDetector()
    coding = CodedVariance(detector.sigma_floor, detector.r_max)
    from_filter = run_ekf(p.model, p.run, store_gain=False, store_S=False, store_innovations=False, coding=coding)
    from_gain = run_ekf(p.model, p.run, store_gain=True, store_S=True, store_innovations=False)
    a = detector.run(p.run, from_filter, model=p.model)
    b = detector.run(p.run, from_gain, model=p.model)
    np.testing.assert_allclose(a.series["e_x"], b.series["e_x"], rtol=1e-5, atol=1e-6, equal_nan=True)
    assert [(x.start, x.end) for x in a.alarms] == [(x.start, x.end) for x in b.alarms]
    assert len(a.alarms) > 0
