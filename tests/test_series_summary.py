"""The JSON summary's view of a statistic (`logscan.results.series_summary`): its count, finite
count and extremes, exactly as the finite values' own min and max in float64 would give them
(the JSON summaries of every log depend on it, down to the sign of a zero)."""

from __future__ import annotations

import json

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from logscan.results import series_summary

SPECIAL = st.sampled_from([0.0, -0.0, 1.0, -1.0, 2.5, np.nan, np.inf, -np.inf])


def reference(values: np.ndarray) -> dict:
    """The definition: the finite values copied out in float64, their min and max."""
    finite = np.asarray(values, dtype=np.float64)
    finite = finite[np.isfinite(finite)]
    low, high = (float(finite.min()), float(finite.max())) if finite.size else (None, None)
    return {"n": int(values.size), "finite": int(finite.size), "min": low, "max": high}


@settings(max_examples=400, deadline=None)
@given(
    arrays(
        st.sampled_from([np.float32, np.float64]),
        st.integers(0, 300),
        elements=st.one_of(SPECIAL, st.floats(allow_nan=True, allow_infinity=True, width=32)),
    )
)
def test_summary_is_the_finite_values_extremes_to_the_sign_of_zero(values):
    assert json.dumps(series_summary(values)) == json.dumps(reference(values))


def test_nan_and_infinity_are_no_extremes():
    summary = series_summary(np.array([np.nan, 3.0, -np.inf, -2.0, np.inf, np.nan]))
    assert summary == {"n": 6, "finite": 2, "min": -2.0, "max": 3.0}
    assert series_summary(np.full(4, np.nan)) == {"n": 4, "finite": 0, "min": None, "max": None}
