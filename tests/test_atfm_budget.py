"""The hybrid KF + A-TFM's budget-sized count threshold (detectors/atfm_budget.py, docs/algorithms.md
4.4): the run statistics, the compound Poisson law of the window count, and the threshold's bound on
the alarm-start rate, checked against brute force and simulation."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.detectors.atfm_budget import (
    alarm_start_tail,
    budget_count,
    compound_poisson_pmf,
    run_lengths,
    run_rate_upper,
    run_statistics,
)
from logscan.detectors.atfm_residual import segment_counts


@given(st.lists(st.booleans(), max_size=60))
def test_run_lengths_are_the_runs_of_consecutive_exceedances(flags):
    expected, current = [], 0
    for flag in flags + [False]:  # plain loop: close a run at each False
        if flag:
            current += 1
        elif current:
            expected.append(current)
            current = 0
    assert run_lengths(np.array(flags, dtype=bool)).tolist() == expected


def test_run_statistics_never_join_runs_across_segments_and_skip_nan():
    segments = [np.array([0.5, 0.5, np.nan]), np.array([0.5, 0.0, 0.5, 0.5, 0.5])]
    n, k, histogram = run_statistics(segments, 0.1)
    assert (n, k) == (7, 3)
    assert histogram.tolist() == [0, 1, 1, 1]  # a run of 2 (first segment), then runs of 1 and 3


def test_the_rate_bound_is_the_upper_end_of_the_exact_poisson_interval():
    from scipy.stats import chi2

    assert run_rate_upper(0, 1000) == float(chi2.ppf(0.975, 2)) / 2000  # 3.69 / n: no run seen
    assert run_rate_upper(50, 1000) > 50 / 1000
    assert run_rate_upper(50, 1000) == float(chi2.ppf(0.975, 102)) / 2000


def test_the_compound_poisson_law_is_a_sum_of_poisson_many_run_lengths():
    """Panjer's recursion against the law by brute force: sum over the number of runs n of
    Poisson(n) times the n-fold convolution of the run lengths."""
    from scipy.stats import poisson

    f = np.array([0.0, 0.7, 0.2, 0.1])
    g = compound_poisson_pmf(2.5, f, 30)
    brute, power = np.zeros(31), np.zeros(31)
    power[0] = 1.0
    for n in range(60):
        brute += poisson.pmf(n, 2.5) * power
        power = np.convolve(power, f)[:31]
    np.testing.assert_allclose(g, brute, atol=1e-12)


def test_the_alarm_start_bound_holds_on_simulated_runs():
    """Runs of exceedances starting as Bernoulli(nu) per update with lengths of law f: the
    fraction of updates where the window count rises above e stays within the bound at every e
    the simulation can resolve."""
    rng = np.random.default_rng(7)
    nu, f, w, n = 0.03, np.array([0.0, 0.8, 0.15, 0.05]), 100, 2_000_000
    starts = np.flatnonzero(rng.random(n) < nu)
    lengths = rng.choice(f.size, size=starts.size, p=f)
    exceed = np.zeros(n + 4, dtype=bool)
    for shift in range(1, f.size):  # a run of L covers start .. start + L - 1
        exceed[(starts + shift - 1)[lengths >= shift]] = True
    exceed = exceed[:n]
    counts = segment_counts(exceed, np.zeros(n), w)
    bound = alarm_start_tail(nu, f * 1000, w)
    for e in range(5, 12):
        rises = np.count_nonzero((counts[1:] > e) & (counts[:-1] <= e)) / n
        assert rises <= bound[e] * 1.1 + 3.0 / n, (e, rises, bound[e])
    assert bound[8] > 1e-5  # the simulation resolves the bound where it is checked


@settings(max_examples=30, deadline=None)
@given(
    st.integers(0, 300),
    st.integers(500, 20000),
    st.lists(st.integers(0, 50), min_size=4, max_size=6),
    st.floats(1e-9, 1e-3),
)
def test_a_smaller_budget_never_lowers_the_threshold(runs, updates, histogram, alpha):
    histogram = np.array([0] + histogram)
    nu = run_rate_upper(runs, updates)
    e = budget_count(nu, histogram, 100, alpha)
    assert budget_count(nu, histogram, 100, alpha / 10) >= e
    assert 0 <= e <= 100
    tail = alarm_start_tail(nu, histogram, 100)
    assert e == 100 or tail[e] <= alpha
    assert e == 0 or tail[e - 1] > alpha  # the smallest such count
