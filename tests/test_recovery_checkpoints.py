"""Consistent checkpoints across loops of different rates and the choice of k1: the detection-time +
slowest-period margin, never inside an earlier anomaly, the checkpoint period."""

from __future__ import annotations

import numpy as np
import pytest
from recovery_linear import make_loop

from logscan.recovery import Anomaly, RecoverySettings, recover
from logscan.recovery.checkpoints import consistent_checkpoints, select_checkpoint


@pytest.fixture(scope="module")
def loops():
    outer, _ = make_loop("outer", N=100, dt=0.1, seed=0)  # 10 Hz, 10 s
    inner, _ = make_loop("inner", N=1000, dt=0.01, seed=1)  # 100 Hz, 10 s
    return [outer, inner]


def test_consistent_checkpoints_are_the_slow_loops_instants_in_every_loop(loops):
    cp = consistent_checkpoints(loops, 0.0, None)
    assert cp.t.size == 100
    np.testing.assert_array_equal(cp.steps[:, 1], 10 * cp.steps[:, 0])
    assert np.max(np.abs(loops[1].run.t[cp.steps[:, 1]] - cp.t)) < 1e-9


def test_loops_whose_instants_differ_beyond_the_tolerance_share_no_checkpoint(loops):
    outer, inner = loops
    shifted = make_loop("inner", N=1000, dt=0.01, seed=1)[0]
    shifted.run.start_ns = 3_000_000  # the inner grid starts 3 ms later
    cp = consistent_checkpoints([outer, shifted], 0.0, None)  # default: half the fastest period
    assert cp.t.size == 100 and np.max(np.abs(shifted.run.t[cp.steps[:, 1]] + 0.003 - cp.t)) <= 0.005
    assert consistent_checkpoints([outer, shifted], 0.0, 1e-3).t.size == 0
    rec = recover([outer, shifted], [Anomaly(5.0, 6.0, None)], RecoverySettings(consistency_tol_s=1e-3))
    assert rec.anomalies[0].t_checkpoint is None and not rec.loops["outer"].recovered.any()


def test_a_diverged_step_is_no_checkpoint(loops):
    outer, inner = loops
    inner.trace.diverged[450] = True
    try:
        cp = consistent_checkpoints(loops, 0.0, None)
        assert 4.5 not in np.round(cp.t, 6) and cp.t.size == 99
    finally:
        inner.trace.diverged[450] = False


def test_k1_is_the_latest_checkpoint_beyond_detection_time_plus_the_slowest_period(loops):
    # t_detect 5.05, detection time 0.3, slowest period 0.1: k1 < 4.65
    rec = recover(loops, [Anomaly(5.05, 5.5, None)], RecoverySettings(detection_time_s=0.3))
    r = rec.anomalies[0]
    assert r.t_checkpoint == pytest.approx(4.6)
    assert r.checkpoint_steps == {"outer": 46, "inner": 460}
    assert r.rollforward_s == pytest.approx(r.t_recovered_end - 4.6)
    for name, k1 in r.checkpoint_steps.items():
        lr = rec.loops[name]
        assert not lr.recovered[k1 - 1] and lr.recovered[k1]
        np.testing.assert_array_equal(lr.x_recovered[k1], loops[0 if name == "outer" else 1].trace.x_post[k1])


def test_the_checkpoint_period_thins_the_checkpoints(loops):
    cp = consistent_checkpoints(loops, 1.0, None)
    np.testing.assert_allclose(cp.t, np.arange(10.0), atol=1e-9)
    r = recover(loops, [Anomaly(5.05, 5.5, None)], RecoverySettings(detection_time_s=0.3, checkpoint_period_s=1.0))
    assert r.anomalies[0].t_checkpoint == pytest.approx(4.0)


def test_no_checkpoint_inside_an_earlier_anomaly(loops):
    # A: detected 2.05, alarm to 3.0, every sensor agrees at once after it (healthy loops): its span
    # ends at 3.0; margin 0.1 blocks [1.95, 3.0]. B at 3.05 (not inside A's span, so not merged)
    # must roll forward from before A
    anomalies = [Anomaly(2.05, 3.0, None), Anomaly(3.05, 4.0, None)]
    rec = recover(loops, anomalies, RecoverySettings(hold_s=0.5))
    a, b = rec.anomalies
    assert a.t_recovered_end == pytest.approx(3.0) and a.t_checkpoint == pytest.approx(1.9)
    assert b.t_checkpoint == pytest.approx(1.9)
    # select_checkpoint on its own: the blocked interval is skipped
    cp = consistent_checkpoints(loops, 0.0, None)
    assert cp.t[select_checkpoint(cp, 3.05, 0.1, [(1.95, 3.0)])] == pytest.approx(1.9)
    assert cp.t[select_checkpoint(cp, 3.05, 0.1, [])] == pytest.approx(2.9)


def test_only_the_flagged_loop_is_recovered_by_a_specific_anomaly(loops):
    rec = recover(loops, [Anomaly(5.05, 5.5, {"inner": ("gps",)})], RecoverySettings(hold_s=0.2))
    assert rec.anomalies[0].loops == ("inner",)
    assert rec.loops["inner"].recovered.any() and not rec.loops["outer"].recovered.any()
    # the checkpoint is still consistent: an instant of the slow loop
    assert rec.anomalies[0].checkpoint_steps["outer"] * 10 == rec.anomalies[0].checkpoint_steps["inner"]
