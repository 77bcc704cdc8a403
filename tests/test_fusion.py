"""Sensor fusion of redundant groups (logscan.redundant.fusion): every method against a reference implementation."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.redundant import fusion

# readings on a quarter grid so that touching and equal endpoints happen often
_READING = st.one_of(st.integers(-20, 20).map(lambda k: k / 4), st.just(np.nan))
_EPS = st.integers(0, 12).map(lambda k: k / 4)


@st.composite
def _intervals(draw):
    """(values (N, s), eps (N, s)) for 3 or 4 sensors, NaN readings included."""
    s = draw(st.sampled_from([3, 4]))
    N = draw(st.integers(1, 6))
    values = np.array([[draw(_READING) for _ in range(s)] for _ in range(N)])
    eps = np.array([[draw(_EPS) for _ in range(s)] for _ in range(N)])
    return values, eps


def _brute_marzullo(values, eps, f):
    """Loop over steps: the candidate points are all endpoints; keep those covered by >= n - f closed intervals."""
    N, s = values.shape
    low, high = np.full(N, np.nan), np.full(N, np.nan)
    faulty = np.zeros((N, s), dtype=bool)
    for t in range(N):
        ok = np.isfinite(values[t])
        lo_i, hi_i = values[t, ok] - eps[t, ok], values[t, ok] + eps[t, ok]
        n = int(ok.sum())
        need = max(n - ((n - 1) // 2 if f is None else f), 1)
        covered = [p for p in np.concatenate([lo_i, hi_i]) if np.sum((lo_i <= p) & (p <= hi_i)) >= need]
        if covered:
            low[t], high[t] = min(covered), max(covered)
            faulty[t, ok] = (hi_i < low[t]) | (lo_i > high[t])
    return low, high, faulty


def _coverage(values, eps, p):
    """How many closed sensor intervals of one step contain the point p."""
    ok = np.isfinite(values)
    return int(np.sum((values[ok] - eps[ok] <= p) & (p <= values[ok] + eps[ok])))


@settings(max_examples=300, deadline=None)
@given(data=_intervals(), f=st.sampled_from([None, 0, 1]))
def test_marzullo_matches_brute_force_and_is_the_smallest_interval(data, f):
    values, eps = data
    low, high, faulty = fusion.marzullo(values, eps, f)
    b_low, b_high, b_faulty = _brute_marzullo(values, eps, f)
    np.testing.assert_array_equal(low, b_low)
    np.testing.assert_array_equal(high, b_high)
    np.testing.assert_array_equal(faulty, b_faulty)
    for t in range(values.shape[0]):
        n = int(np.isfinite(values[t]).sum())
        need = max(n - ((n - 1) // 2 if f is None else f), 1)
        if np.isnan(low[t]):
            continue
        # minimal: both ends are themselves covered by >= n - f intervals, so no narrower interval holds them
        assert low[t] <= high[t]
        assert _coverage(values[t], eps[t], low[t]) >= need
        assert _coverage(values[t], eps[t], high[t]) >= need
        # complete: no endpoint outside [low, high] is covered that often
        ends = np.concatenate([values[t] - eps[t], values[t] + eps[t]])
        outside = ends[np.isfinite(ends) & ((ends < low[t]) | (ends > high[t]))]
        assert all(_coverage(values[t], eps[t], p) < need for p in outside)


@settings(max_examples=200, deadline=None)
@given(
    truth=st.floats(-5, 5),
    good=st.lists(st.tuples(st.floats(0.001, 0.999), st.floats(0.1, 2)), min_size=2, max_size=4),
    bad=st.floats(-50, 50),
)
def test_marzullo_interval_holds_the_truth_with_at_most_f_faulty(truth, good, bad):
    # n - f correct intervals contain the true value, f = 1 arbitrary: the fused interval contains it too
    values = np.array([[truth + (2 * u - 1) * e for u, e in good] + [bad]])
    eps = np.array([[e for _, e in good] + [0.5]])
    low, high, _ = fusion.marzullo(values, eps, f=1)
    assert low[0] <= truth + 1e-9 and truth - 1e-9 <= high[0]


def test_marzullo_interval_spans_a_gap_between_covered_points():
    # n = 3, f = 1: points in 2 intervals are [0.5, 1] and [2, 3]; the fused interval holds both
    low, high, faulty = fusion.marzullo(np.array([[0.5, 1.75, 2.5]]), np.array([0.5, 1.25, 0.5]))
    assert (low[0], high[0]) == (0.5, 3.0)
    assert not faulty.any()


def test_marzullo_without_a_point_in_n_minus_f_intervals_is_nan_and_flags_nothing():
    low, high, faulty = fusion.marzullo(np.array([[0.0, 10.0, 20.0], [np.nan] * 3]), np.array([1.0, 1.0, 1.0]))
    assert np.isnan(low).all() and np.isnan(high).all()
    assert not faulty.any()


def test_a_biased_sensor_is_flagged_by_marzullo_and_hybrid_and_hybrid_is_the_median():
    rng = np.random.default_rng(1)
    truth = np.linspace(0.0, 2.0, 200)
    values = truth[:, None] + rng.uniform(-0.05, 0.05, (200, 4))
    values[:, 2] += 3.0
    eps = np.array([0.1, 0.1, 0.1, 0.1])
    low, high, faulty = fusion.marzullo(values, eps)
    assert faulty[:, 2].all()
    assert not faulty[:, [0, 1, 3]].any()
    assert np.all((low <= truth + 0.1) & (truth - 0.1 <= high))
    fused, h_faulty = fusion.hybrid(values, eps)
    np.testing.assert_array_equal(h_faulty, faulty)
    np.testing.assert_array_equal(fused, np.median(values, axis=1))


def _with_nan(seed):
    rng = np.random.default_rng(seed)
    values = rng.normal(1.0, 0.5, (300, 4))
    values[rng.random(values.shape) < 0.3] = np.nan
    values[7] = np.nan
    return values


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_average_and_median_match_numpy_with_nan(seed):
    values = _with_nan(seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # the all-NaN row
        mean, med = np.nanmean(values, axis=1), np.nanmedian(values, axis=1)
    np.testing.assert_allclose(fusion.naive_average(values), mean, rtol=1e-12, equal_nan=True)
    np.testing.assert_allclose(fusion.median(values), med, rtol=1e-12, equal_nan=True)
    assert np.isnan(fusion.median(values)[7]) and np.isnan(fusion.naive_average(values)[7])


@pytest.mark.parametrize("n", [1, 3, 5])
def test_moving_average_is_the_trailing_mean_of_the_naive_average(n):
    values = _with_nan(3)
    values[20 : 20 + n] = np.nan  # a window with no reading at all
    v = fusion.naive_average(values)
    expected = np.full(len(v), np.nan)
    for t in range(len(v)):
        window = v[max(0, t - n + 1) : t + 1]
        if np.isfinite(window).any():
            expected[t] = np.nanmean(window)
    got = fusion.moving_average(values, n)
    np.testing.assert_allclose(got, expected, rtol=1e-12, equal_nan=True)
    assert np.isnan(got[20 + n - 1])


def test_infinite_readings_count_as_missing():
    values = np.array([[1.0, np.inf, 3.0], [-np.inf, 2.0, np.nan]])
    np.testing.assert_array_equal(fusion.naive_average(values), [2.0, 2.0])
    np.testing.assert_array_equal(fusion.median(values), [2.0, 2.0])


def test_iterative_filter_of_identical_sensors_returns_them():
    x = np.sin(np.linspace(0, 6, 103))
    x[10] = np.nan
    got = fusion.iterative_filter(np.column_stack([x, x, x]))
    np.testing.assert_allclose(got, x, rtol=0, atol=1e-12, equal_nan=True)


@pytest.mark.parametrize("block", [1, 25])
def test_iterative_filter_with_one_outlier_is_closer_to_the_majority_than_the_average(block):
    rng = np.random.default_rng(4)
    truth = np.linspace(0.0, 1.0, 500)
    values = truth[:, None] + rng.normal(0, 0.02, (500, 3))
    values[:, 1] += 2.0
    got = fusion.iterative_filter(values, block=block)
    majority = values[:, [0, 2]].mean(axis=1)
    assert fusion.rmse(got, majority) < 0.1 * fusion.rmse(fusion.naive_average(values), majority)
    assert fusion.rmse(got, truth) < 0.05


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), s=st.integers(2, 5), block=st.sampled_from([1, 7, 25]))
def test_iterative_filter_converges_without_nan_on_random_data(seed, s, block):
    rng = np.random.default_rng(seed)
    values = rng.normal(0, rng.uniform(0.1, 100), (60, s)) + rng.normal(0, 10, s)
    for got in (fusion.iterative_filter(values, block=block), fusion.iterative_filter(values, 300, block=block)):
        assert np.isfinite(got).all()
        # a weighted mean: never outside the readings
        assert np.all(got >= values.min(axis=1) - 1e-9) and np.all(got <= values.max(axis=1) + 1e-9)
    # every block stops at its tolerance, not at the cap: ten times the cap changes nothing
    converged = fusion.iterative_filter(values, block=block)
    np.testing.assert_array_equal(converged, fusion.iterative_filter(values, 10 * fusion.IF_ROUNDS, block=block))


def test_iterative_filter_converges_on_a_slow_block():
    # a case found by hypothesis: one block's reciprocal weights crawl, 300 rounds leave it 3e-4 from its fixed point
    rng = np.random.default_rng(340)
    values = rng.normal(0, rng.uniform(0.1, 100), (60, 4)) + rng.normal(0, 10, 4)
    fixed_point = fusion.iterative_filter(values, iterations=100_000, tol=0.0)
    assert np.abs(fusion.iterative_filter(values, iterations=300) - fixed_point).max() > 1e-4
    np.testing.assert_allclose(fusion.iterative_filter(values), fixed_point, rtol=0, atol=1e-5)


def test_fuse_all_names_every_method():
    values = np.array([[1.0, 1.1, 5.0], [1.0, 1.2, np.nan]])
    assert set(fusion.fuse_all(values)) == {"average", "moving_average", "median", "iterative"}
    fused = fusion.fuse_all(values, eps=np.array([0.2, 0.2, 0.2]), n_moving=2)
    np.testing.assert_allclose(fused["marzullo"], [1.05, 1.1])
    np.testing.assert_array_equal(fused["hybrid"], fusion.median(values))
    np.testing.assert_allclose(fused["moving_average"], [7.1 / 3, (7.1 / 3 + 1.1) / 2])


def test_rmse_over_the_steps_where_both_are_finite():
    assert fusion.rmse(np.array([1.0, 2.0, np.nan, 4.0]), np.array([0.0, 4.0, 1.0, np.inf])) == pytest.approx(
        np.sqrt(2.5)
    )
    assert np.isnan(fusion.rmse(np.array([np.nan]), np.array([1.0])))


def test_fit_poly_recovers_a_fifth_order_polynomial():
    c = [0.5, -1.0, 0.25, 2.0, -0.75, 0.1]
    x = np.linspace(-2, 3, 80)
    y = np.polynomial.polynomial.polyval(x, c)
    x[5], y[9] = np.nan, np.inf
    got = fusion.fit_poly(x, y)
    assert len(got) == 6 and all(isinstance(v, float) for v in got)
    np.testing.assert_allclose(got, c, rtol=1e-7, atol=1e-9)


@pytest.mark.parametrize(
    "call",
    [
        lambda: fusion.naive_average(np.ones(3)),
        lambda: fusion.moving_average(np.ones((3, 2)), 0),
        lambda: fusion.marzullo(np.ones((3, 2)), np.array([-1.0, 1.0])),
        lambda: fusion.marzullo(np.ones((3, 2)), np.ones(2), f=-1),
        lambda: fusion.fit_poly(np.arange(5.0), np.arange(5.0)),
    ],
)
def test_bad_arguments_raise_value_error(call):
    with pytest.raises(ValueError):
        call()
