"""Alignment onto the analysis grid: zero-order hold within staleness, fresh masks, cleaning, gaps."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.align import align, hold
from logscan.errors import InputError, ProfileError
from logscan.log import Channel, Log, SourceInfo
from logscan.models.base import GroupSpec
from logscan.profiles import parse_profile

MS = 1_000_000  # ns per millisecond


class FakeModel:
    input_names = ("force",)
    state_names = ("pos", "vel")
    groups = {
        "speed": GroupSpec("speed", 0, ("v",), (0.1,), (-10.0,), (10.0,)),
        "pair": GroupSpec("pair", 1, ("a", "b"), (0.1, 0.1), (-1.0, -1.0), (1.0, 1.0)),
    }


BASE = """
[vehicle]
model = "fake"
rate_hz = 100

[inputs]
force = "/force"
"""

SPEED = """
[measurements.speed]
channels = ["/speed"]
rate_hz = 10
"""


def make_log(channels: dict[str, tuple]) -> Log:
    """channels: name -> (times in ms, values)."""
    chans = {
        name: Channel(name, np.asarray(t_ms, dtype=np.int64) * MS, np.asarray(v, dtype=np.float64))
        for name, (t_ms, v) in channels.items()
    }
    return Log(chans, SourceInfo("test.mcap", "mcap"))


def force_100hz(t_end_ms=1000):
    t = np.arange(0, t_end_ms + 1, 10)
    return t, t / 1000.0


def run(channels: dict, toml: str):
    return align(make_log(channels), parse_profile(BASE + toml, model=FakeModel()))


def steps(mask) -> list[int]:
    return [int(i) for i in np.flatnonzero(mask)]


# ------------------------------------------------------------------------------------------------


def test_10hz_group_on_100hz_grid_is_fresh_on_exactly_every_10th_step():
    t = np.arange(0, 1001, 100)
    r = run({"/force": force_100hz(), "/speed": (t, np.arange(11.0))}, SPEED)
    assert r.n_steps == 101 and r.dt == 0.01
    np.testing.assert_allclose(r.t, np.arange(101) * 0.01, atol=1e-12)
    g = r.groups["speed"]
    assert steps(g.fresh) == list(range(0, 101, 10))
    np.testing.assert_array_equal(g.z[:, 0], np.arange(101) // 10)
    assert r.u_fresh.all() and r.u.shape == (101, 1)
    assert r.input_names == ["force"] and r.input_channels == ["/force"]
    assert g.stale_s == pytest.approx(0.25) and g.rate_hz == 10
    assert r.gaps == [] and r.warnings == []


def test_a_delayed_sensor_is_held_delay_s_earlier():
    """delay_s: the sample stamped t + delay_s is the vehicle at t (a GNSS receiver's latency)."""
    t = np.arange(0, 1001, 100)
    plain = run({"/force": force_100hz(), "/speed": (t, np.arange(11.0))}, SPEED)
    late = run({"/force": force_100hz(), "/speed": (t, np.arange(11.0))}, SPEED + "delay_s = 0.03\n")
    assert late.n_steps == plain.n_steps  # the grid is the log's; only the group moves
    g = late.groups["speed"]
    assert steps(g.fresh) == [0] + list(range(7, 101, 10))  # the 100 ms sample is fresh at 70 ms
    np.testing.assert_array_equal(g.z[:, 0], plain.groups["speed"].z[np.minimum(np.arange(101) + 3, 100), 0])
    assert "delay_s = 0.03" in parse_profile(BASE + SPEED + "delay_s = 0.03\n", model=FakeModel()).to_toml()
    with pytest.raises(ProfileError, match="delay_s"):
        parse_profile(BASE + SPEED + "delay_s = -0.1\n", model=FakeModel())


def test_gap_beyond_stale_s_gives_nan_and_a_gap_report():
    t = np.array([0, 100, 200, 300, 800, 900, 1000])
    r = run({"/force": force_100hz(), "/speed": (t, t / 100.0)}, SPEED)
    z = r.groups["speed"].z[:, 0]
    nan_steps = steps(np.isnan(z))
    assert nan_steps == list(range(56, 80))  # 300 ms held until 550 ms (stale_s 0.25), back at 800 ms
    assert z[55] == 3.0 and z[80] == 8.0
    assert steps(r.groups["speed"].fresh) == [0, 10, 20, 30, 80, 90, 100]
    assert r.gaps == [(pytest.approx(0.3), pytest.approx(0.8), "/speed")]
    assert any("'/speed': 1 gap longer than stale_s=0.25 s" in w for w in r.warnings)


def test_a_topics_channels_with_the_same_gap_are_one_warning():
    """A receiver's fields lost together (one topic, the same gap) make one line, not one each."""
    t = np.array([0, 100, 200, 300, 800, 900, 1000])
    pair = '[measurements.pair]\nchannels = ["/gnss/a", "/gnss/b"]\nrate_hz = 10\n'
    r = run({"/force": force_100hz(), "/gnss/a": (t, t * 0.0), "/gnss/b": (t, t * 0.0)}, pair)
    (line,) = [w for w in r.warnings if "gap" in w]
    assert line.startswith("channels /gnss/{a, b}: 1 gap each longer than stale_s=0.25 s")
    assert len(r.gaps) == 2  # the gaps themselves stay per channel


def test_nonfinite_samples_are_masked_and_counted_not_held():
    t = np.arange(0, 1001, 100)
    v = np.arange(11.0)
    v[5], v[7] = np.nan, np.inf
    r = run({"/force": force_100hz(), "/speed": (t, v)}, SPEED)
    g = r.groups["speed"]
    assert np.isfinite(g.z).all()
    np.testing.assert_array_equal(g.z[50:60, 0], 4.0)  # the sample before the NaN, within stale_s
    np.testing.assert_array_equal(g.z[70:80, 0], 6.0)
    assert steps(g.fresh) == [0, 10, 20, 30, 40, 60, 80, 90, 100]
    assert g.nonfinite_count == 2
    assert r.channel_stats["/speed"]["nonfinite"] == 2
    assert "channel '/speed': 2 non-finite samples (NaN/inf) masked out, not held" in r.warnings


def test_unsorted_and_duplicate_timestamps_are_sorted_and_deduplicated_with_warnings():
    t = [0, 200, 100, 100, 300]
    v = [0.0, 2.0, 1.0, 1.5, 3.0]
    r = run({"/force": force_100hz(300), "/speed": (t, v)}, SPEED)
    z = r.groups["speed"].z[:, 0]
    np.testing.assert_array_equal(z[[0, 10, 15, 20, 30]], [0.0, 1.5, 1.5, 2.0, 3.0])
    assert steps(r.groups["speed"].fresh) == [0, 10, 20, 30]
    assert "channel '/speed': timestamps out of order (1 backward steps): sorted (stable)" in r.warnings
    assert "channel '/speed': 1 duplicate timestamps dropped (kept the last sample)" in r.warnings
    assert r.channel_stats["/speed"] == {"samples": 5, "nonfinite": 0, "duplicates": 1, "unsorted": 1}


PAIR = """
[measurements.pair]
channels = ["/a", "/b"]
rate_hz = 10
"""


def test_group_channels_arriving_in_different_grid_periods_are_never_fresh_together():
    ta = np.arange(0, 1001, 100)
    tb = np.concatenate([[0], np.arange(105, 1000, 100)])  # 5 ms after a, in the next grid period
    r = run({"/force": force_100hz(), "/a": (ta, ta / 100.0), "/b": (tb, -tb / 100.0)}, PAIR)
    g = r.groups["pair"]
    assert steps(g.channel_fresh[:, 0]) == list(range(0, 101, 10))
    assert steps(g.channel_fresh[:, 1]) == [0] + list(range(11, 100, 10))
    assert steps(g.fresh) == [0]
    assert g.z[11, 0] == 1.0 and g.z[11, 1] == -1.05  # each channel holds its own latest sample
    assert g.z[10, 1] == 0.0  # b's 5 ms sample is not there yet at 100 ms (its 0 ms one is held)
    assert any("group 'pair': its channels arrive at different times" in w for w in r.warnings)


def test_group_channels_arriving_within_one_grid_period_are_fresh_together():
    ta = np.arange(1, 1001, 100)  # 1, 101, ...
    tb = ta + 4  # 5, 105, ...: same grid period (t_{k-1}, t_k]
    r = run({"/force": force_100hz(), "/a": (ta, ta), "/b": (tb, tb)}, PAIR)
    g = r.groups["pair"]
    assert steps(g.fresh) == list(range(1, 101, 10))
    assert not any("arrive at different times" in w for w in r.warnings)


def test_inputs_hold_two_grid_periods_then_go_stale():
    t, v = force_100hz()
    keep = (t < 300) | (t > 350)  # drop 300..350 ms
    r = run({"/force": (t[keep], v[keep]), "/speed": ([0, 1000], [0.0, 1.0])}, SPEED)
    assert steps(~r.u_fresh) == [32, 33, 34, 35]  # 290 ms sample valid until 310 ms
    assert r.u[31, 0] == pytest.approx(0.29) and np.isnan(r.u[32, 0]) and r.u[36, 0] == pytest.approx(0.36)


def test_grid_spans_inputs_and_measurements_and_t_counts_from_the_log_start():
    t_force = np.arange(500, 1001, 10)
    toml = SPEED + '\n[mode]\nchannel = "/mode"\nstale_s = inf\n'
    r = run(
        {"/force": (t_force, t_force), "/speed": ([500, 1500], [1.0, 2.0]), "/mode": ([0, 700], [3.0, 4.0])},
        toml,
    )
    assert r.start_ns == 0  # the mode channel starts the log
    assert r.n_steps == 101
    assert r.t[0] == pytest.approx(0.5) and r.t[-1] == pytest.approx(1.5)
    assert steps(~r.u_fresh) == list(range(53, 101))  # input ends at 1.0 s (+ 20 ms hold)
    np.testing.assert_array_equal(r.mode[[0, 19, 20, 100]], [3.0, 3.0, 4.0, 4.0])
    assert r.mode_channel == "/mode"


def test_non_integer_grid_period_stays_uniform():
    toml = SPEED.replace("rate_hz = 10", "rate_hz = 10\nstale_s = inf")
    profile = parse_profile(BASE.replace("rate_hz = 100", "rate_hz = 300") + toml, model=FakeModel())
    log = make_log({"/force": force_100hz(), "/speed": ([0, 1000], [1.0, 2.0])})
    r = align(log, profile)
    assert r.n_steps == 301 and r.dt == pytest.approx(1 / 300)
    np.testing.assert_allclose(np.diff(r.t), 1 / 300, rtol=1e-9)
    assert steps(r.groups["speed"].fresh) == [0, 300]


def test_onboard_estimator_by_prefix_and_by_state_names():
    t = np.arange(0, 1001, 20)
    toml = SPEED + '\n[onboard]\nstate = "/ekf/state"\nvariance = "/ekf/var"\n'
    r = run(
        {
            "/force": force_100hz(),
            "/speed": (np.arange(0, 1001, 100), np.zeros(11)),
            "/ekf/state[0]": (t, t * 1.0),
            "/ekf/state[1]": (t, t * 2.0),
            "/ekf/var/pos": (t, t * 3.0),
            "/ekf/var/vel": (t, t * 4.0),
        },
        toml,
    )
    assert r.onboard_names == ["pos", "vel"]
    assert r.onboard_state_channels == ["/ekf/state[0]", "/ekf/state[1]"]
    assert r.onboard_variance_channels == ["/ekf/var/pos", "/ekf/var/vel"]
    assert r.onboard_state.shape == (101, 2)
    np.testing.assert_array_equal(r.onboard_state[3], [20.0, 40.0])  # 30 ms holds the 20 ms sample
    np.testing.assert_array_equal(r.onboard_variance[4], [120.0, 160.0])


def test_redundant_group_applies_its_polynomial_before_holding():
    t = np.arange(0, 1001, 100)
    toml = (
        SPEED
        + '\n[redundant.v]\nsensors = { enc = "/enc", gps = { channel = "/gps", poly = [1.0, 2.0] } }\nrate_hz = 10\n'
    )
    r = run({"/force": force_100hz(), "/speed": (t, t), "/enc": (t, t / 100.0), "/gps": (t, t / 100.0)}, toml)
    g = r.redundant["v"]
    assert g.channels == ["/enc", "/gps"]
    np.testing.assert_allclose(g.z[20], [2.0, 5.0])  # 1 + 2 x
    assert steps(g.fresh) == list(range(0, 101, 10))


def test_a_redundant_sensors_gap_is_the_runs_gap_and_warning():
    """The [redundant] groups are held before the run's warnings and gaps are taken: a gap in one of
    their sensors is reported like any measurement's (it was computed, then dropped)."""
    t = np.arange(0, 1001, 100)
    lost = t[(t < 300) | (t > 800)]  # the GNSS receiver silent from 0.3 to 0.8 s
    toml = SPEED + '\n[redundant.v]\nsensors = { enc = "/enc", gps = "/gps" }\nrate_hz = 10\n'
    r = run({"/force": force_100hz(), "/speed": (t, t), "/enc": (t, t / 100.0), "/gps": (lost, lost / 100.0)}, toml)
    assert [name for _, _, name in r.gaps] == ["/gps"]
    assert any("'/gps'" in w and "gap" in w for w in r.warnings)


def test_profile_noise_and_range_overrides_reach_the_group():
    toml = PAIR.replace("rate_hz = 10", "rate_hz = 10\nnoise_std = [0.2, 0.3]\nrange_lo = -5\nrange_hi = 5")
    t = np.arange(0, 1001, 100)
    r = run({"/force": force_100hz(), "/a": (t, t), "/b": (t, t)}, toml)
    g = r.groups["pair"]
    np.testing.assert_array_equal(g.noise_std, [0.2, 0.3])
    np.testing.assert_array_equal(g.range_lo, [-5.0, -5.0])
    np.testing.assert_array_equal(g.range_hi, [5.0, 5.0])


def test_missing_channel_is_a_profile_error_with_suggestions():
    with pytest.raises(ProfileError) as info:
        run({"/force": force_100hz(), "/speeds": ([0], [1.0])}, SPEED)
    assert info.value.problems == [
        "[measurements.speed] channels: no channel '/speed' in the log (did you mean '/speeds'?)"
    ]


def test_no_finite_sample_at_all_is_an_input_error():
    with pytest.raises(InputError, match="none of the profile's input and measurement channels"):
        run({"/force": ([0, 10], [np.nan, np.nan]), "/speed": ([], [])}, SPEED)


def test_a_channel_without_samples_is_all_nan_and_one_gap():
    r = run({"/force": force_100hz(), "/speed": ([], [])}, SPEED)
    assert np.isnan(r.groups["speed"].z).all() and not r.groups["speed"].fresh.any()
    assert r.gaps == [(0.0, 1.0, "/speed")]


# ------------------------------------------------------------------------------------------------
# Properties
# ------------------------------------------------------------------------------------------------


def brute_force_hold(t_ns, values, grid_ns, limit_ns):
    z = np.full(grid_ns.size, np.nan)
    fresh = np.zeros(grid_ns.size, dtype=bool)
    for k, g in enumerate(grid_ns):
        before = [i for i in range(t_ns.size) if t_ns[i] <= g]
        if before and g - t_ns[before[-1]] <= limit_ns:
            z[k] = values[before[-1]]
            fresh[k] = k == 0 or t_ns[before[-1]] > grid_ns[k - 1]
    return z, fresh


@settings(max_examples=200, deadline=None)
@given(
    times=st.lists(st.integers(0, 2000), min_size=0, max_size=40, unique=True),
    start=st.integers(-100, 500),
    step=st.integers(1, 150),
    n=st.integers(1, 40),
    limit=st.integers(0, 400),
)
def test_hold_is_the_latest_sample_within_the_limit(times, start, step, n, limit):
    t_ns = np.array(sorted(times), dtype=np.int64)
    values = np.arange(t_ns.size, dtype=np.float64) + 0.5
    grid = start + np.arange(n, dtype=np.int64) * step
    z, fresh = hold(t_ns, values, grid, limit)
    z_ref, fresh_ref = brute_force_hold(t_ns, values, grid, limit)
    np.testing.assert_array_equal(z, z_ref)
    np.testing.assert_array_equal(fresh, fresh_ref)


@settings(max_examples=100, deadline=None)
@given(
    samples=st.lists(
        st.tuples(st.integers(0, 1000), st.one_of(st.floats(-1e3, 1e3), st.just(float("nan")))),
        min_size=1,
        max_size=60,
    ),
    stale_ms=st.integers(1, 300),  # a profile's stale_s is > 0
)
def test_align_gives_the_latest_finite_sample_within_stale_s(samples, stale_ms):
    t_ms = np.array([s[0] for s in samples])
    v = np.array([s[1] for s in samples])
    toml = SPEED + f"stale_s = {stale_ms / 1000}\n"
    r = run({"/force": force_100hz(), "/speed": (t_ms, v)}, toml)
    last: dict[int, float] = {}
    for tm, val in samples:  # duplicates: the last record wins; then non-finite ones are dropped
        last[tm] = val
    kept = sorted((tm, val) for tm, val in last.items() if np.isfinite(val))
    for k in range(r.n_steps):
        g = 10 * k
        before = [(tm, val) for tm, val in kept if tm <= g]
        expected = before[-1][1] if before and g - before[-1][0] <= stale_ms else np.nan
        np.testing.assert_equal(r.groups["speed"].z[k, 0], expected)


def test_late_start_and_early_end_are_gaps_of_the_span():
    t = np.arange(400, 601, 100)
    r = run({"/force": force_100hz(), "/speed": (t, t)}, SPEED)
    assert r.gaps == [(0.0, pytest.approx(0.4), "/speed"), (pytest.approx(0.6), 1.0, "/speed")]


@settings(max_examples=200, deadline=None)
@given(
    times=st.lists(st.integers(0, 2000), min_size=0, max_size=30, unique=True),
    g0=st.integers(0, 1000),
    span=st.integers(0, 1000),
    limit=st.integers(0, 300),
)
def test_gaps_are_the_sample_free_stretches_longer_than_the_limit(times, g0, span, limit):
    from logscan.align import _gaps

    t_ns = np.array(sorted(times), dtype=np.int64)
    grid = np.array([g0, g0 + span], dtype=np.int64)
    starts, ends = _gaps(t_ns, limit, grid)
    before = [x for x in t_ns if x < g0]
    edges = [before[-1] if before else g0] + [x for x in t_ns if g0 <= x <= g0 + span] + [g0 + span]
    expected = [(a, b) for a, b in zip(edges[:-1], edges[1:]) if b - a > limit]
    assert list(zip(starts.tolist(), ends.tolist())) == expected


def test_onboard_columns_of_one_topic_are_held_at_their_own_rate():
    """Columns sharing their sample times are a HeldTable (samples at their own rate plus a row
    per grid step) that reads exactly like the dense held array; others stay dense."""
    from logscan.align import HeldTable

    t = np.arange(0, 1001, 20)
    late = np.arange(5, 1001, 20)
    toml = SPEED + '\n[onboard]\nstate = "/ekf/state"\nvariance = "/ekf/var"\nstale_s = 0.025\n'
    channels = {
        "/force": force_100hz(),
        "/speed": (np.arange(0, 1001, 100), np.zeros(11)),
        "/ekf/state[0]": (t[t < 500], t[t < 500] * 1.0),  # stops at 480 ms: stale after 505 ms
        "/ekf/state[1]": (t[t < 500], t[t < 500] * 2.0),
        "/ekf/var/pos": (t, t * 3.0),
        "/ekf/var/vel": (late, late * 4.0),  # other times: dense
    }
    r = run(channels, toml)
    table = r.onboard_state
    assert isinstance(table, HeldTable) and table.samples.shape == (25, 2) and table.shape == (101, 2)
    assert isinstance(r.onboard_variance, np.ndarray)
    dense = np.asarray(table)
    for j, name in enumerate(["/ekf/state[0]", "/ekf/state[1]"]):
        times, values = channels[name]
        expected, _ = hold(times * 1_000_000, values, np.arange(101) * 10_000_000, 25_000_000)
        np.testing.assert_array_equal(dense[:, j], expected)
    np.testing.assert_array_equal(table[10:20], dense[10:20])
    np.testing.assert_array_equal(table[7], dense[7])
    assert np.isnan(dense[60:]).all() and np.isfinite(dense[:49]).all()
