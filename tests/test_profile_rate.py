"""A built-in profile's rates (`logscan.profiles.built.rate_hz`): 1 / the median step between a
channel's distinct times, its steps counted a megasample at a time so that a 24-hour IMU is not
differenced and sorted whole; the same figure as the median of all its steps at once."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.profiles import built


def _median_at_once(t: np.ndarray) -> float:
    """The rate as the steps of all the times at once give it (the earlier code)."""
    steps = np.diff(t)
    if not bool((steps > 0).all()):
        t = np.unique(t)
        steps = np.diff(t)
    return 0.0 if t.size < 2 else float(1e9 / np.median(steps))


@given(
    steps=st.lists(st.integers(-3, 6), max_size=80) | st.lists(st.integers(1, 10**9), max_size=80),
    scale=st.sampled_from([1, 1000, 4_000_000]),
    chunk=st.integers(1, 9),
)
@settings(max_examples=300, deadline=None)
def test_the_rate_from_counted_steps_is_the_median_of_all_the_steps(steps, scale, chunk):
    t = 10**12 + np.cumsum(np.array(steps, dtype=np.int64) * scale).astype(np.int64)
    old = built._STEP_CHUNK
    built._STEP_CHUNK = chunk  # chunk borders, and merges of the distinct steps, everywhere
    try:
        assert built.rate_hz(t) == _median_at_once(t)
    finally:
        built._STEP_CHUNK = old


def test_a_250_hz_imu_with_a_gap_is_250_hz():
    t = np.arange(0, 10**9, 4_000_000, dtype=np.int64)
    t[100:] += 300_000_000  # a 0.3 s dropout
    assert built.rate_hz(t) == 250.0
