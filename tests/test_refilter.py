"""The EKF's K and S filtered again block by block on read (`logscan.pipeline.refilter`) are the
whole run's, bit for bit: in order, going back, across block edges, and where the state cannot be
carried (a divergence: the whole run's, filtered in one go)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from logscan.filters.ekf import run_ekf
from logscan.needs import Needs
from logscan.pipeline import refilter
from logscan.pipeline.preparation import load_profile_for, prepare

SAMPLES = Path(__file__).resolve().parent.parent / "sample_logs"


def _prepared(name: str):
    path = str(SAMPLES / name)
    return prepare(path, load_profile_for(path, None), Needs())


def _same(a, b) -> bool:
    return np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)


@pytest.mark.parametrize("name", ["quad_imu_bias.mcap", "ins_imu_bias.mcap", "jackal_gps_bias.mcap"])
def test_blocks_give_the_whole_runs_gain_and_covariance(monkeypatch, name):
    monkeypatch.setattr(refilter, "BLOCK", 997)  # many block edges, none aligned with the reads
    prepared = _prepared(name)
    whole = run_ekf(prepared.model, prepared.run, store_gain=True, store_S=True, store_innovations=False)
    trace = refilter.run_ekf_parts(prepared.model, prepared.run, frozenset({"K", "S"}))
    assert trace.K.source.exact_blocks  # the state was carried, not the whole run re-filtered
    assert trace.K.shape == whole.K.shape and trace.S.shape == whole.S.shape
    n = trace.n_steps
    for start in range(0, n, 1500):  # in order, K then S of the same rows as the detectors read them
        assert _same(trace.K[start : start + 1500], whole.K[start : start + 1500])
        assert _same(trace.S[start : start + 1500], whole.S[start : start + 1500])
    assert _same(trace.S[10:2100], whole.S[10:2100])  # going back: from the start again
    assert _same(trace.K[n - 5 :], whole.K[n - 5 :])
    assert trace.K[7:7].shape == (0, *whole.K.shape[1:])
    assert trace.K.source.whole is None  # none of these reads held the whole run's K and S
    assert _same(trace.x_post, whole.x_post) and _same(trace.nis, whole.nis)


def test_a_divergence_filters_the_whole_run_once(monkeypatch):
    monkeypatch.setattr(refilter, "BLOCK", 997)
    prepared = _prepared("quad_imu_bias.mcap")
    u = prepared.run.u.copy()
    u[3000] = 1e300  # the prediction overflows: the filter restarts from its prior
    run = replace(prepared.run, u=u)
    whole = run_ekf(prepared.model, run, store_gain=True, store_S=True, store_innovations=False)
    assert whole.diverged.any()
    trace = refilter.run_ekf_parts(prepared.model, run, frozenset({"K"}))
    assert trace.S is None
    assert not trace.K.source.exact_blocks
    assert _same(trace.K[2000:4000], whole.K[2000:4000])
    assert _same(np.asarray(trace.K), whole.K)


def test_with_the_full_covariance_the_trace_holds_them():
    prepared = _prepared("quad_imu_bias.mcap")
    trace = refilter.run_ekf_parts(prepared.model, prepared.run, frozenset({"K", "S", "P"}))
    assert isinstance(trace.K, np.ndarray) and isinstance(trace.S, np.ndarray) and trace.P_post is not None


@pytest.mark.parametrize("name", ["quad_imu_bias.mcap", "jackal_gps_bias.mcap"])
def test_the_reports_pack_waits_for_the_blocks_that_read_the_samples(name):
    """The report's innovations are packed into the samples' own buffer once no detector still to
    run reads the samples: a K or S filtered again on read reads them, so the pack waits for it,
    and the samples stay for it (jackal: no detector declares them)."""
    from logscan.pipeline import analyze_log

    path = str(SAMPLES / name)
    plain = analyze_log(path, free_series=True)
    packed = analyze_log(path, free_series=True, sensor_views=True)
    assert packed.prepared.innovations is not None
    for a, b in zip(plain.results, packed.results, strict=True):
        assert a.to_dict() == b.to_dict(), a.detector
