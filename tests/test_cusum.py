"""The CUSUM detector (docs/algorithms.md section 1e): its run length on white noise against the
Siegmund design target, detection of a slow ramp with the change time read back to the onset, both
sides, its resets, and an end-to-end run on a simulated quadcopter accelerometer drift."""

from __future__ import annotations

import numpy as np
import pytest

from logscan.alarms import AlarmInterval
from logscan.detectors.budget import design_rate
from logscan.detectors.cusum import CusumDetector, cusum_statistics, siegmund_arl, threshold_for_arl, uncapped_peaks

DT = 0.01


def run_kernel(u, h, *, kappa=0.25, cap=1.5, gap=1.0, reset=None, clip=4.0):
    u = np.asarray(u, dtype=np.float64)
    u = u[:, None] if u.ndim == 1 else u
    t = np.arange(u.shape[0]) * DT
    reset = np.zeros(u.shape[0], dtype=bool) if reset is None else reset
    m = u.shape[1]
    gaps, h = np.full(m, gap), np.full(m, float(h))
    return cusum_statistics(t, u, np.ones_like(u), 0, reset, gaps, h, kappa, cap, clip)[:2]


def run_uncapped(u, h, **settings):
    """The kernel's uncapped statistic (its third output) beside the capped one."""
    u = np.asarray(u, dtype=np.float64)[:, None]
    t = np.arange(u.shape[0]) * DT
    one = np.ones(1)
    g, _, free = cusum_statistics(t, u, np.ones_like(u), 0, np.zeros(u.shape[0], bool), one, one * h, 0.25, 1.5, 4.0)
    return t, g[:, 0], free[:, 0]


def alarm_starts(g: np.ndarray, h: float) -> np.ndarray:
    """(row, column) of every sample where |g| first goes over h."""
    over = np.abs(np.nan_to_num(g)) > h
    return np.argwhere(over & ~np.vstack([np.zeros((1, g.shape[1]), bool), over[:-1]]))


def test_threshold_inverts_siegmund_arl():
    arl = np.array([1e2, 1e4, 6.5e7])
    for kappa in (0.0, 0.25, 0.5):
        h = threshold_for_arl(arl, kappa)
        np.testing.assert_allclose(siegmund_arl(h, kappa), arl, rtol=1e-9)
    assert np.all(np.diff(threshold_for_arl(arl, 0.25)) > 0)


@pytest.mark.parametrize("kappa", [0.25, 0.5])
def test_run_length_on_white_noise_matches_the_design_target(kappa):
    """Two one-sided tests on N(0, 1): one alarm per ARL0 / 2 samples, within 25 %."""
    arl = 2000.0
    h = float(threshold_for_arl(arl, kappa)[0])
    u = np.random.default_rng(7).standard_normal((250_000, 8))
    g, _ = run_kernel(u, h, kappa=kappa)
    measured = u.size / len(alarm_starts(g, h))
    assert arl / 2 / 1.25 < measured < arl / 2 * 1.25


def test_a_slow_ramp_is_detected_and_its_onset_estimated():
    """A mean rising 0.5 std per second from 30 s: detected within 2 s, onset read back within 0.7 s."""
    t = np.arange(6000) * DT
    onset = 30.0
    u = np.random.default_rng(3).standard_normal(t.size) + 0.5 * np.clip(t - onset, 0.0, None)
    h = float(threshold_for_arl(6.5e7, 0.25)[0])  # the quadcopter's accelerometer tests' threshold
    g, first = run_kernel(u, h)
    starts = alarm_starts(g, h)
    assert starts.size and t[starts[0, 0]] > onset  # no alarm before the fault
    k = starts[0, 0]
    assert t[k] - onset < 2.0
    assert g[k, 0] > h  # upward shift: the upper side
    assert abs(t[first[k, 0]] - onset) < 0.7


def test_both_sides_alarm_with_the_sign_of_the_shift():
    u = np.zeros(400)
    u[100:] = -1.0
    g, first = run_kernel(u, 10.0)
    k = int(np.flatnonzero(np.abs(g[:, 0]) > 10.0)[0])
    assert g[k, 0] < -10.0 and first[k, 0] == 100
    g_up, _ = run_kernel(-u, 10.0)
    np.testing.assert_allclose(g_up, -g)


def test_the_statistic_is_capped_and_restarts_when_the_alarm_ends():
    u = np.concatenate([np.full(200, 1.25), np.full(200, -0.25)])  # shift 1 std, then back below kappa
    g, _ = run_kernel(u, 10.0, cap=1.5)
    assert np.nanmax(g) == pytest.approx(15.0)  # held at cap x h
    below = int(np.flatnonzero((np.arange(400) >= 200) & (g[:, 0] <= 10.0))[0])
    assert g[below, 0] == 0.0  # the sample the alarm ends on restarts the test
    assert np.all(g[below:, 0] == 0.0)


def test_a_saturated_alarm_reports_the_uncapped_peak_not_the_cap():
    u = np.concatenate([np.full(200, 1.25), np.full(200, -0.25)])  # as above: saturates at 1.5 h
    t, g, free = run_uncapped(u, 10.0)
    assert np.nanmax(g) == pytest.approx(15.0)
    assert np.nanmax(free) == pytest.approx(200 * (1.25 - 0.25))  # the sum the cap hid
    assert np.all(free[np.abs(g) == 0.0] == 0.0)  # restarted with the capped sides
    alarm = AlarmInterval(float(t[20]), float(t[250]), float(t[20]), float(t[30]), 15.0, 10.0, 1.5, "upper", 200)
    (peak,) = uncapped_peaks([alarm], t, free, 10.0)
    assert peak["peak_value"] == pytest.approx(200.0) and peak["peak_ratio"] == pytest.approx(20.0)
    assert peak["peak_time"] == pytest.approx(float(t[199])) and peak["peak_threshold"] == 10.0
    assert (peak["start"], peak["end"]) == (alarm.start, alarm.end) and alarm.peak_ratio == 1.5  # left as it was
    low = AlarmInterval(float(t[20]), float(t[250]), float(t[20]), float(t[30]), -15.0, -10.0, 1.5, "lower", 200)
    (peak,) = uncapped_peaks([low], t, -free, 10.0)  # the downward side: the sign kept, the ratio positive
    assert peak["peak_value"] == pytest.approx(-200.0) and peak["peak_ratio"] == pytest.approx(20.0)
    unsaturated = AlarmInterval(float(t[20]), float(t[250]), float(t[20]), float(t[199]), 200.0, 10.0, 20.0, "upper", 1)
    assert uncapped_peaks([unsaturated], t, free, 10.0) == []  # nothing hidden: nothing reported


def test_divergence_and_gaps_restart_the_test():
    u = np.full(300, 0.75)
    reset = np.zeros(300, dtype=bool)
    reset[100] = True
    g, first = run_kernel(u, 1e6, reset=reset)
    assert g[99, 0] == pytest.approx(50.0) and g[100, 0] == pytest.approx(0.5) and first[100, 0] == 100
    gapped = u.copy()
    gapped[150:260] = np.nan  # 1.1 s without an update: longer than gap_s = 1 s
    g, first = run_kernel(gapped, 1e6)
    assert np.isnan(g[200, 0]) and g[260, 0] == pytest.approx(0.5) and first[260, 0] == 260
    g_short, _ = run_kernel(gapped, 1e6, gap=2.0)
    assert g_short[260, 0] == pytest.approx(g_short[149, 0] + 0.5)


def test_thresholds_spend_the_budget_over_every_test():
    class Trace:
        t = np.arange(0, 60, DT)
        dt = DT
        group_sizes = np.array([3, 1])
        group_offsets = np.array([0, 3])
        updated = np.ones((t.size, 2), dtype=bool)
        tested = updated  # no outlier gate here: every update is a test

    Trace.updated[:, 1] = np.arange(Trace.t.size) % 10 == 0  # a 10 Hz group
    tests = 8  # 2 sides x 4 outputs
    rate = 1.0 / Trace.t[-1] * Trace.updated.sum(axis=0)
    for proof_hours, designed in ((None, 0.1), (100.0, design_rate(0.1, 100.0))):
        h, arl = CusumDetector(arl_margin=1.0, proof_hours=proof_hours).thresholds(Trace)
        np.testing.assert_allclose(arl, tests * np.repeat(rate, [3, 1]) * 3600 / designed)
        # false alarms per hour: sum over the one-sided tests of rate / ARL0 = the design rate
        spent = 2 * np.sum(np.repeat(rate, [3, 1]) / siegmund_arl(h, 0.25)) * 3600
        assert spent == pytest.approx(designed, rel=1e-6)
    assert design_rate(0.1, 100.0) == pytest.approx(0.0174, abs=1e-4)  # what a 100-hour proof allows


def test_a_single_glitch_cannot_raise_an_alarm():
    u = np.zeros(300)
    u[100] = 1e6  # a one-sample spike far beyond the noise
    g, _ = run_kernel(u, 10.0, clip=4.0)
    assert np.nanmax(g) == pytest.approx(3.75)
    g_unclipped, _ = run_kernel(u, 10.0, clip=np.inf)
    assert np.nanmax(g_unclipped) == pytest.approx(15.0)  # held at the cap


def test_signal_words():
    assert "accelerometer ax" in CusumDetector.signal_label("cusum.accel.ax")
    assert "yaw-rate sensor drifts" in CusumDetector.signal_label("cusum.yaw_rate")
    assert CusumDetector.signal_label("nis.accel") is None


def test_end_to_end_on_a_simulated_accelerometer_drift(tmp_path):
    from logscan.pipeline import analyze_log
    from logscan.simulate import parse_fault, simulate, write_simulation

    onset = 12.0
    sim = simulate("quadcopter", [parse_fault(f"imu-drift::{onset}::")], duration=25.0, seed=901)
    path = tmp_path / "drift.mcap"
    write_simulation(sim, str(path), "mcap-ros2")
    analysis = analyze_log(str(path), detector_names=["cusum"])
    (result,) = analysis.results
    alarms = [a for a in result.alarms if a.signal == "cusum.accel.ax"]
    assert alarms, [a.signal for a in result.alarms]
    first = alarms[0]
    assert onset < first.start < onset + 3.0
    assert first.change_time is not None and abs(first.change_time - onset) < 1.5
    assert first.to_dict()["change_time"] == first.change_time
    assert not [a for a in result.alarms if a.start < onset]
    assert result.info["h"]["cusum.accel.ax"] > 0 and result.thresholds["cusum.accel.ax"].lower is not None
