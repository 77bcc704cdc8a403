"""A-TFM numeric core (logscan/redundant/tfm.py) against brute-force loops and hand-built cases."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.redundant import tfm

NAN = math.nan
# a small lattice makes errors equal to grid points (err > eps is strict) and ties in the knee common
LATTICE = [0.0, 0.25, 0.5, 0.75, 1.0]
error_values = st.one_of(st.sampled_from(LATTICE + [NAN]), st.floats(0.0, 1.2))


def brute_max_window_counts(segments, eps, windows):
    """e(eps, w) by plain loops: every segment, every window start, every eps."""
    out = np.zeros((len(eps), len(windows)), dtype=np.int64)
    for a, threshold in enumerate(eps):
        for b, w in enumerate(windows):
            best = 0
            for segment in segments:
                n = len(segment)
                starts = range(n - w + 1) if n >= w else ([0] if n else [])
                for start in starts:
                    best = max(best, sum(1 for x in segment[start : start + w] if x > threshold))
            out[a, b] = best
    return out


def brute_knee(eps, e, w):
    """The knee rule point by point: ratio filter, objective, ties within 1e-12 to the larger eps."""
    eps_max = eps[-1]
    allowed = [k for k in range(len(eps)) if e[k] / w < 0.5]
    if not allowed:
        return float(eps[-1]), int(e[-1])
    objective = {k: 1.0 - eps[k] / eps_max - e[k] / w for k in allowed}
    best = max(objective.values())
    pick = None
    for k in allowed:
        if objective[k] >= best - 1e-12 and (pick is None or eps[k] > eps[pick]):
            pick = k
    return float(eps[pick]), int(e[pick])


def brute_window_counts(flags, w):
    return np.array([sum(flags[max(0, t - w + 1) : t + 1]) for t in range(len(flags))], dtype=np.int64)


# --- e(eps, w) --------------------------------------------------------------------------------------


@settings(max_examples=150, deadline=None)
@given(
    segments=st.lists(st.lists(error_values, max_size=14), min_size=1, max_size=4),
    eps=st.lists(st.one_of(st.sampled_from(LATTICE), st.floats(0.0, 1.2)), min_size=1, max_size=9),
    windows=st.lists(st.integers(1, 9), min_size=1, max_size=4),
    chunk=st.integers(1, 5),
)
def test_max_window_counts_equals_brute_force(segments, eps, windows, chunk):
    eps = np.sort(np.array(eps))
    arrays = [np.array(segment, dtype=float) for segment in segments]
    counts = tfm.max_window_counts(arrays, eps, windows, chunk=chunk)
    assert counts.dtype == np.int64
    np.testing.assert_array_equal(counts, brute_max_window_counts(segments, eps, windows))


def test_windows_never_cross_segments():
    # two exceedances at the end of one segment and two at the start of the next: 2, not 4
    segments = [np.array([0.0, 0.0, 1.0, 1.0]), np.array([1.0, 1.0, 0.0, 0.0])]
    counts = tfm.max_window_counts(segments, np.array([0.5]), [4])
    assert counts[0, 0] == 2
    assert tfm.max_window_counts([np.concatenate(segments)], np.array([0.5]), [4])[0, 0] == 4


def test_a_segment_shorter_than_the_window_counts_as_one_window():
    counts = tfm.max_window_counts([np.array([1.0, NAN, 1.0]), np.zeros(10)], np.array([0.0, 2.0]), [5])
    np.testing.assert_array_equal(counts, [[2], [0]])


# --- eps grid -----------------------------------------------------------------------------------------


def half_normal(n, sigma=0.05, seed=0):
    return np.abs(np.random.default_rng(seed).normal(0.0, sigma, n))


def test_eps_grid_runs_from_zero_to_three_times_p99():
    err = half_normal(5000)
    err[::97] = NAN
    grid = tfm.eps_grid(err)
    assert tfm.N_EPS >= 200 and grid.size == tfm.N_EPS
    assert grid[0] == 0.0
    assert np.all(np.diff(grid) > 0)
    assert grid[-1] == pytest.approx(3.0 * np.nanpercentile(err, 99), rel=1e-12)


def test_eps_grid_is_not_moved_by_one_huge_outlier():
    err = half_normal(10_000)
    with_outlier = np.append(err, 1000.0 * err.max())
    assert tfm.eps_grid(with_outlier)[-1] == pytest.approx(tfm.eps_grid(err)[-1], rel=0.01)


@pytest.mark.parametrize("errors", [np.zeros(50), np.array([]), np.full(5, NAN)])
def test_eps_grid_has_a_positive_end_without_any_scale(errors):
    grid = tfm.eps_grid(errors, n=250)
    assert grid.size == 250 and grid[0] == 0.0 and 0.0 < grid[-1] < 1e-6


def test_eps_grid_of_mostly_zero_errors_reaches_past_the_largest():
    # a quantised sensor: p99 is 0, so the grid falls back to the largest error's scale
    err = np.zeros(1000)
    err[::200] = 0.01
    assert tfm.eps_grid(err)[-1] > 0.01


# --- knee -----------------------------------------------------------------------------------------------


@settings(max_examples=200, deadline=None)
@given(
    n=st.integers(2, 30),
    eps_max=st.sampled_from([1.0, 0.3, 2.5, 1e-3]),
    w=st.integers(1, 40),
    data=st.data(),
)
def test_knee_equals_brute_force_on_monotone_curves(n, eps_max, w, data):
    eps = np.linspace(0.0, eps_max, n)
    e = np.sort(np.array(data.draw(st.lists(st.integers(0, w), min_size=n, max_size=n))))[::-1]
    assert tfm.knee(eps, e, w) == brute_knee(eps, e, w)


@pytest.mark.parametrize(
    ("eps", "e", "w", "expected"),
    [
        # every point has the same objective 0: the allowed ones (e <= 4) tie, the largest eps wins
        (np.linspace(0.0, 1.0, 11), np.arange(10, -1, -1), 10, (1.0, 0)),
        # (0.25, 1) and (0.5, 0) tie at 0.5: the larger eps
        (np.linspace(0.0, 1.0, 5), np.array([4, 1, 0, 0, 0]), 4, (0.5, 0)),
        # e/w = 0.5 is not < 0.5: the best-looking points are excluded
        (np.array([0.0, 0.5, 1.0]), np.array([6, 5, 0]), 10, (1.0, 0)),
        # a clear maximum at eps = 0 (no tie): taken even though a larger eps is close
        (np.array([0.0, 0.5, 1.0]), np.array([1, 0, 0]), 4, (0.0, 1)),
        # no point allowed: the last point
        (np.array([0.0, 0.5, 1.0]), np.array([9, 8, 5]), 10, (1.0, 5)),
    ],
)
def test_knee_lattice_ties_and_ratio_filter(eps, e, w, expected):
    assert tfm.knee(eps, e, w) == expected
    assert brute_knee(eps, e, w) == expected


def test_knee_of_noise_with_outliers_lies_between_p90_and_three_p99():
    err = half_normal(20_000, seed=3)
    err[np.random.default_rng(4).choice(err.size, 15, replace=False)] = 5.0
    training = tfm.train_sensor([err[:12_000], err[12_000:]])
    p90, p99 = np.percentile(err, [90, 99])
    assert training.windows == tfm.DEFAULT_WINDOWS
    assert training.counts.shape == (tfm.N_EPS, len(tfm.DEFAULT_WINDOWS))
    assert training.n_samples == err.size
    for k, found in enumerate(training.knees):
        assert (found.eps, found.e) == tfm.knee(training.eps, training.counts[:, k], found.w)
        assert p90 <= found.eps <= 3.0 * p99
        assert found.e < 0.5 * found.w


# --- reference errors ---------------------------------------------------------------------------------


def test_reference_errors_three_sensors_use_the_mean_of_the_other_two():
    y = np.random.default_rng(1).normal(1.0, 0.1, (50, 3))
    err = tfm.reference_errors(y)
    np.testing.assert_allclose(err[:, 0], np.abs(y[:, 0] - (y[:, 1] + y[:, 2]) / 2))
    np.testing.assert_allclose(err[:, 2], np.abs(y[:, 2] - (y[:, 0] + y[:, 1]) / 2))


def test_reference_errors_four_sensors_use_the_median_of_the_other_three():
    y = np.random.default_rng(2).normal(1.0, 0.1, (50, 4))
    err = tfm.reference_errors(y)
    for i in range(4):
        np.testing.assert_allclose(err[:, i], np.abs(y[:, i] - np.median(np.delete(y, i, axis=1), axis=1)))


def test_reference_errors_skip_missing_readings():
    y = np.array(
        [
            [1.0, NAN, 3.0],  # sensor 1 missing: sensor 0 against sensor 2 alone
            [1.0, NAN, NAN],  # no other reading for sensor 0
            [NAN, NAN, NAN],
        ]
    )
    err = tfm.reference_errors(y)
    np.testing.assert_array_equal(err[0], [2.0, NAN, 2.0])
    assert np.isnan(err[1:]).all()
    four = tfm.reference_errors(np.array([[0.0, 1.0, NAN, 3.0]]))
    np.testing.assert_allclose(four[0], [2.0, 0.5, NAN, 2.5])


@settings(max_examples=60, deadline=None)
@given(st.lists(st.lists(st.one_of(st.floats(-5, 5), st.just(NAN)), min_size=5, max_size=5), min_size=1, max_size=8))
def test_reference_errors_equal_nanmedian(rows):
    y = np.array(rows)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        expected = np.column_stack([np.abs(y[:, i] - np.nanmedian(np.delete(y, i, axis=1), axis=1)) for i in range(5)])
    np.testing.assert_allclose(tfm.reference_errors(y), expected, rtol=1e-12, atol=1e-12)


# --- lookup table -------------------------------------------------------------------------------------


def test_monotone_envelope_is_the_running_maximum():
    np.testing.assert_array_equal(tfm.monotone_envelope(np.array([0.1, 0.146, 0.138, 0.2])), [0.1, 0.146, 0.146, 0.2])
    table = np.array([[0.06, 0.3], [0.11, 0.2], [0.10, 0.4]])
    np.testing.assert_array_equal(tfm.monotone_envelope(table), [[0.06, 0.3], [0.11, 0.3], [0.11, 0.4]])


MODES = np.array([0.4, 0.7, 1.0, 1.3])


def test_select_rows_takes_the_next_higher_mode():
    commanded = np.array([0.1, 0.4, 0.5, 0.7 + 0.3, 0.1 * 10, 1.0000000001, 1.2])
    row, above = tfm.select_rows(MODES, commanded, np.full(commanded.size, NAN), 0.05)
    np.testing.assert_array_equal(row, [0, 0, 1, 2, 2, 2, 3])
    assert row.dtype == np.int64 and not above.any()


def test_select_rows_raises_the_row_while_still_fast():
    # decelerating from 1.0 to 0.4: measured 0.9 - 0.05 > 0.4 keeps the 1.0 row
    row, _ = tfm.select_rows(MODES, np.array([0.4, 0.4, 0.4]), np.array([0.9, 0.74, 0.3]), 0.05)
    np.testing.assert_array_equal(row, [2, 1, 0])


def test_select_rows_above_the_top_and_without_any_value():
    commanded = np.array([1.5, 0.4, NAN, NAN])
    measured = np.array([NAN, 1.5, 0.6, NAN])
    row, above = tfm.select_rows(MODES, commanded, measured, 0.05)
    np.testing.assert_array_equal(row, [3, 3, 1, 3])
    np.testing.assert_array_equal(above, [True, True, False, False])


# --- detection ----------------------------------------------------------------------------------------


def test_weak_inconsistency_needs_disjoint_intervals():
    y_i = np.array([0.0, 0.0, 0.0, NAN, 0.0])
    y_j = np.array([0.25, 0.2, -0.3, 1.0, NAN])
    # eps 0.1 + 0.15 = 0.25: touching intervals (0.25 apart) overlap
    np.testing.assert_array_equal(tfm.weak_inconsistency(y_i, 0.1, y_j, 0.15), [False, False, True, False, False])


@settings(max_examples=100, deadline=None)
@given(flags=st.lists(st.booleans(), max_size=40), w=st.integers(1, 12))
def test_window_counts_equals_brute_force(flags, w):
    counts = tfm.window_counts(np.array(flags, dtype=bool), w)
    assert counts.dtype == np.int64
    np.testing.assert_array_equal(counts, brute_window_counts(flags, w))


def three_sensors(n=600, eps=0.1, seed=5):
    """Three agreeing sensors: noise well inside the +-eps intervals (at most 0.4 eps apart)."""
    rng = np.random.default_rng(seed)
    return 1.0 + rng.uniform(-0.2 * eps, 0.2 * eps, (n, 3))


def si_flags(pairs):
    return {pair: count > threshold for pair, (count, threshold) in pairs.items()}


def test_a_sustained_bias_gives_si_on_both_pairs_of_the_biased_sensor():
    w, eps = 50, 0.1
    y = three_sensors(eps=eps)
    # a bias of 2 eps would only touch the other intervals (no WI); 2.5 eps minus the noise clears them
    y[200 : 200 + 3 * w, 0] += 2.5 * eps
    pairs = tfm.strong_inconsistency(y, np.full(y.shape, eps), np.full(y.shape, 2), w)
    assert set(pairs) == {(0, 1), (0, 2), (1, 2)}
    count, threshold = pairs[(0, 1)]
    assert count.dtype == np.int64 and count.max() == w and (threshold == 4).all()
    si = si_flags(pairs)
    for pair in [(0, 1), (0, 2)]:
        assert si[pair][200 + 5 : 200 + 3 * w].all()  # from the 5th WI on (count 5 > 4)
        assert not si[pair][:200].any()
    assert not si[(1, 2)].any()
    named = tfm.attribute(si, 3)
    assert named[0][200 + 5 : 200 + 3 * w].all() and not named[0][:200].any()
    assert not named[1].any() and not named[2].any()


def test_a_short_glitch_stays_below_the_transient_budget():
    w, eps = 50, 0.1
    y = three_sensors(eps=eps)
    y[300:302, 1] += 5 * eps
    pairs = tfm.strong_inconsistency(y, np.array([eps, eps, eps]), np.array([2, 2, 2]), w)
    assert pairs[(0, 1)][0].max() == 2
    assert not any(flags.any() for flags in si_flags(pairs).values())


def test_attribute_by_majority_in_groups_of_four_and_never_in_pairs():
    steps = 3
    none = np.zeros(steps, dtype=bool)
    si = {(i, j): none for i in range(4) for j in range(i + 1, 4)}
    si[(0, 1)] = np.array([True, True, False])
    si[(0, 2)] = np.array([True, False, False])
    named = tfm.attribute(si, 4)
    np.testing.assert_array_equal(named[0], [True, False, False])  # 2 of 3 others, then only 1
    assert not any(flags.any() for flags in named[1:])
    two = tfm.attribute({(0, 1): np.array([True, False])}, 2)
    assert not two[0].any() and not two[1].any()


@settings(max_examples=100, deadline=None)
@given(
    data=st.data(),
    n=st.integers(0, 30),
    w=st.integers(1, 10),
)
def test_residual_counts_equal_brute_force(data, n, w):
    residual = data.draw(st.lists(st.one_of(st.floats(-2, 2), st.just(NAN)), min_size=n, max_size=n))
    eps = data.draw(st.lists(st.sampled_from([0.0, 0.5, 1.0]), min_size=n, max_size=n))
    exceed = [abs(r) > x for r, x in zip(residual, eps)]  # NaN compares False
    counts = tfm.residual_counts(np.array(residual, dtype=float), np.array(eps, dtype=float), w)
    np.testing.assert_array_equal(counts, brute_window_counts(exceed, w))
