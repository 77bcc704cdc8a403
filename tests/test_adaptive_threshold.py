"""The masked adaptive band: exact window statistics, exceedances kept out of the window."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.detectors.adaptive_threshold import adaptive_band, trailing_mean_var


def reference_band(e, defined, window, rho):
    """Plain-Python statement of the rule, for comparison."""
    accepted: list[float] = []
    out = []
    for k, value in enumerate(e):
        if not defined[k]:
            out.append(None)
            continue
        if len(accepted) >= window:
            last = np.array(accepted[-window:])
            mu, sd = last.mean(), last.std()
            exceed = not (abs(value - mu) <= rho * sd)
            out.append((mu, sd, exceed))
            if exceed:
                continue
        elif not np.isfinite(value):
            out.append(("warm", None, False))
            continue
        else:
            out.append(("warm", None, False))
        accepted.append(value)
    return out


@settings(max_examples=60, deadline=None)
@given(
    values=st.lists(st.one_of(st.floats(-1e3, 1e3), st.just(float("nan")), st.just(1e20)), min_size=1, max_size=300),
    window=st.integers(2, 20),
    rho=st.floats(0.5, 6.0),
    seed=st.integers(0, 2**16),
)
def test_band_matches_the_plain_statement_of_the_rule(values, window, rho, seed):
    e = np.array(values, dtype=np.float64)
    defined = np.random.default_rng(seed).random(e.size) < 0.8
    mu, s, lower, upper, exceed, warm = adaptive_band(e, defined, window, rho, np.zeros(e.size))
    expected = reference_band(e, defined, window, rho)
    for k, item in enumerate(expected):
        if item is None:
            assert not exceed[k] and np.isnan(mu[k])
        elif item[0] == "warm":
            assert not warm[k] and not exceed[k]
        else:
            ref_mu, ref_sd, ref_exceed = item
            assert warm[k]
            assert abs(mu[k] - ref_mu) <= 1e-9 * (1 + abs(ref_mu))
            assert abs(s[k] - ref_sd) <= 1e-6 * (1 + ref_sd)
            # borderline samples may flip on rounding; away from the border they must agree
            margin = abs(abs(e[k] - ref_mu) - rho * ref_sd) if np.isfinite(e[k]) else np.inf
            if margin > 1e-6 * (1 + abs(ref_mu) + ref_sd):
                assert exceed[k] == ref_exceed


def test_a_persistent_offset_does_not_widen_its_own_threshold():
    rng = np.random.default_rng(1)
    e = rng.normal(0.0, 1.0, 2000)
    e[1000:] += 20.0  # a fault that lasts
    mu, s, lower, upper, exceed, warm = adaptive_band(e, np.ones(e.size, bool), 100, 4.0, np.zeros(e.size))
    assert exceed[1000:].all()  # masked window: the band stays where the healthy data put it
    assert exceed[200:1000].sum() <= 2
    assert np.nanmax(upper[1000:]) < 5.0


def test_one_huge_sample_leaving_the_window_leaves_no_round_off_behind():
    rng = np.random.default_rng(2)
    e = rng.normal(0.0, 1e-6, 5000)
    defined = np.ones(e.size, bool)
    mean, var = trailing_mean_var(e + np.where(np.arange(e.size) == 300, 1e12, 0.0), defined, 100)
    exact = np.array([e[k - 99 : k + 1].var() for k in range(600, 5000)])
    assert np.allclose(var[600:], exact, rtol=1e-6, atol=0.0)


def test_warm_up_raises_nothing_and_nan_counts_as_an_exceedance_after_it():
    e = np.zeros(50)
    e[5] = np.nan
    e[40] = np.nan
    mu, s, lower, upper, exceed, warm = adaptive_band(e, np.ones(50, bool), 10, 3.0, np.zeros(50))
    assert not exceed[:11].any() and not warm[:10].any()
    assert exceed[40] and exceed.sum() == 1


def test_spread_floor_widens_a_band_that_noise_alone_would_make_too_tight():
    e = np.random.default_rng(3).normal(0.0, 1e-9, 400)
    e[300] = 1e-3
    floor = np.full(e.size, 1e-2)
    assert adaptive_band(e, np.ones(e.size, bool), 50, 4.0, np.zeros(e.size))[4][300]
    mu, s, lower, upper, exceed, warm = adaptive_band(e, np.ones(e.size, bool), 50, 4.0, floor)
    assert not exceed.any() and np.nanmin(s) == 1e-2
