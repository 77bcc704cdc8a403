"""KGN's trained operating envelope (detectors/kgn_operating.py, docs/algorithms.md section 3): the
window features, the box, the hold after an excursion and the flight-level rule, against brute
force."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.detectors.kgn_operating import envelope_gate, fit_envelope, held_inside, inside, operating_features


def test_features_are_each_windows_input_mean_and_spread():
    rng = np.random.default_rng(3)
    u = rng.normal(size=(100, 2))
    u[5, 1] = np.nan  # a stale input: left out of its window
    run = SimpleNamespace(u=u, input_channels=["/cmd/thrust", "/cmd/tau"])
    starts = np.array([0, 10, 40])
    names, features = operating_features(run, starts, 10)
    assert names == ["mean /cmd/thrust", "mean /cmd/tau", "spread /cmd/thrust", "spread /cmd/tau"]
    for i, s in enumerate(starts):
        block = u[s : s + 10]
        np.testing.assert_allclose(features[i, :2], np.nanmean(block, axis=0))
        np.testing.assert_allclose(features[i, 2:], np.nanstd(block, axis=0), atol=1e-7)
    assert operating_features(SimpleNamespace(), starts, 10)[1].shape == (3, 0)  # no inputs: no envelope


def test_the_box_is_the_training_range_widened_and_admits_nan():
    envelope = fit_envelope(["a", "b"], [np.array([[1.0, 0.0], [3.0, 1.0]]), np.array([[2.0, np.nan]])], 0.5)
    np.testing.assert_allclose(envelope["lo"], [0.0, -0.5])
    np.testing.assert_allclose(envelope["hi"], [4.0, 1.5])
    ok = inside(np.array([[0.0, 1.5], [4.1, 0.0], [2.0, np.nan], [2.0, -0.6]]), envelope)
    assert ok.tolist() == [True, False, True, False]


@settings(max_examples=50, deadline=None)
@given(st.lists(st.booleans(), min_size=1, max_size=40), st.floats(0.0, 8.0))
def test_a_window_is_held_inside_only_when_every_window_of_the_hold_is(flags, hold_s):
    ok = np.array(flags)
    t = np.arange(ok.size, dtype=np.float64)  # one window per second
    expected = [all(ok[j] for j in range(ok.size) if i - hold_s <= t[j] <= i) for i in range(ok.size)]
    assert held_inside(ok, t, hold_s).tolist() == expected


def test_a_flight_mostly_outside_is_not_checked_at_all():
    t = np.arange(20, dtype=np.float64)
    warm, judged = t >= 2, t >= 2
    ok = np.ones(20, dtype=bool)
    ok[5:8] = False  # an excursion: those windows and 2 s after it
    lost, share = envelope_gate(ok, t, warm, judged, 2.0, 0.5)
    assert share == 3 / 18 and np.flatnonzero(lost).tolist() == [5, 6, 7, 8, 9]
    ok[5:16] = False  # 11 of the 18 windows after warm-up: the whole flight
    lost, share = envelope_gate(ok, t, warm, judged, 2.0, 0.5)
    assert share == 11 / 18 and np.array_equal(lost, judged)
