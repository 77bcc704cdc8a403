"""KGN's trained operating envelope (detectors/kgn_operating.py, docs/algorithms.md section 3): the
window features, the box, the hold after an excursion, the flight-level rule, the operating-point
range and the gain's memory of an excursion beyond it, against brute force."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.detectors.kgn_operating import (
    envelope_gate,
    fit_envelope,
    fit_ranges,
    held_inside,
    inside,
    memory_gate,
    operating_features,
    outside_ranges,
)


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


def test_the_range_is_the_trained_windows_from_zero_for_a_magnitude():
    blocks = [
        {"speed": np.array([0.5, 2.0]), "thrust": np.array([9.0, np.nan])},
        {"speed": np.array([1.0]), "thrust": np.array([11.0])},
    ]
    ranges = fit_ranges(blocks)
    assert ranges == {"speed": [0.0, 2.0], "thrust": [9.0, 11.0]}
    quantities = {"speed": np.array([0.1, 2.1, 1.0, np.nan]), "thrust": np.array([10.0, 10.0, 8.9, 10.0])}
    # slower than any training window is not outside (a magnitude); less thrust is; NaN is not
    assert outside_ranges(quantities, ranges, 4).tolist() == [False, True, True, False]


def test_the_gains_memory_takes_the_steady_stretch_after_a_manoeuvre_beyond_the_range():
    steady = np.array([0, 0, 1, 1, 1, 0, 0, 1, 1, 1, 0, 1, 1], dtype=bool)
    outside = np.zeros(steady.size, dtype=bool)
    outside[5] = True  # in the manoeuvre before the stretch 7-9: all of it
    outside[12] = True  # in a steady stretch: the envelope's business, not the memory's
    assert np.flatnonzero(memory_gate(outside, steady)).tolist() == [7, 8, 9]
    outside[0] = True  # before the first stretch too
    assert np.flatnonzero(memory_gate(outside, steady)).tolist() == [2, 3, 4, 7, 8, 9]
    assert not memory_gate(np.zeros(steady.size, dtype=bool), steady).any()
    assert not memory_gate(outside, np.ones(steady.size, dtype=bool)).any()  # no manoeuvre: nothing
