"""The shared alarm logic: exceedance, persistence, hold-off, minimum duration, warm-up, validity."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.alarms import AlarmInterval, alarm_intervals, merge_close
from logscan.errors import InternalError

DT = 0.1
T = np.arange(20) * DT


def series(*hot, n=20, value=2.0):
    x = np.zeros(n)
    x[list(hot)] = value
    return x


def spans(alarms):
    return [(round(a.start, 9), round(a.end, 9)) for a in alarms]


def test_single_exceedances_each_raise_with_n_persist_1():
    alarms = alarm_intervals(T, series(3, 4, 9), 1.0)
    assert spans(alarms) == [(0.3, 0.4), (0.9, 0.9)]
    assert alarms[0].n_exceed == 2 and alarms[1].duration == 0.0


def test_persistence_starts_at_nth_consecutive_exceedance():
    alarms = alarm_intervals(T, series(3, 4, 5, 6, 9, 10), 1.0, n_persist=3)
    assert spans(alarms) == [(0.5, 0.6)]
    assert alarms[0].first_exceed == pytest.approx(0.3)
    assert alarms[0].n_exceed == 4  # counted from the first exceedance


def test_exceedance_is_strict():
    x = series(5, value=1.0)
    assert alarm_intervals(T, x, 1.0) == []
    assert alarm_intervals(T, x, 0.999)[0].start == pytest.approx(0.5)


def test_lower_threshold_and_band():
    x = np.zeros(20)
    x[4], x[12] = -3.0, 3.0
    alarms = alarm_intervals(T, x, upper=2.0, lower=-2.0)
    assert [a.bound for a in alarms] == ["lower", "upper"]
    assert spans(alarms) == [(0.4, 0.4), (1.2, 1.2)]
    only_lower = alarm_intervals(T, x, lower=-2.0)
    assert spans(only_lower) == [(0.4, 0.4)]


def test_threshold_series_is_followed_sample_by_sample():
    upper = np.where(T < 1.0, 0.5, 5.0)
    alarms = alarm_intervals(T, np.ones(20), upper)
    assert spans(alarms) == [(0.0, 0.9)]


def test_hold_off_bridges_short_gaps_only():
    x = series(2, 3, 5, 9)
    assert spans(alarm_intervals(T, x, 1.0, hold_off_s=0.2)) == [(0.2, 0.5), (0.9, 0.9)]
    assert spans(alarm_intervals(T, x, 1.0, hold_off_s=0.4)) == [(0.2, 0.9)]
    assert spans(alarm_intervals(T, x, 1.0, hold_off_s=0.0)) == [(0.2, 0.3), (0.5, 0.5), (0.9, 0.9)]


def test_hold_off_keeps_alarm_on_through_short_runs_but_they_cannot_start_one():
    x = series(2, 3, 4, 6, 12)
    alarms = alarm_intervals(T, x, 1.0, n_persist=3, hold_off_s=0.2)
    assert spans(alarms) == [(0.4, 0.6)]  # sample 6 extends, sample 12 alone does not raise


def test_short_run_before_a_persistent_one_in_same_chain_gives_first_exceed_of_that_run():
    x = series(2, 4, 5, 6)
    alarms = alarm_intervals(T, x, 1.0, n_persist=3, hold_off_s=0.2)
    assert spans(alarms) == [(0.6, 0.6)]
    assert alarms[0].first_exceed == pytest.approx(0.4)


def test_min_duration_drops_short_alarms():
    x = series(2, 3, 4, 5, 10)
    alarms = alarm_intervals(T, x, 1.0, min_duration_s=0.2)
    assert spans(alarms) == [(0.2, 0.5)]
    assert alarm_intervals(T, x, 1.0, min_duration_s=0.31) == []


def test_warmup_in_samples_seconds_and_mask():
    x = series(0, 1, 2, 3, 8)
    assert spans(alarm_intervals(T, x, 1.0, warmup=2)) == [(0.2, 0.3), (0.8, 0.8)]
    assert spans(alarm_intervals(T, x, 1.0, warmup_s=0.25)) == [(0.3, 0.3), (0.8, 0.8)]
    mask = np.zeros(20, bool)
    mask[8] = True
    assert spans(alarm_intervals(T, x, 1.0, warmup=mask)) == [(0.0, 0.3)]


def test_warmup_breaks_persistence_runs_and_hold_off():
    x = series(3, 4, 5, 6, 7)
    mask = np.zeros(20, bool)
    mask[5] = True
    assert spans(alarm_intervals(T, x, 1.0, n_persist=3, warmup=mask)) == []
    assert spans(alarm_intervals(T, x, 1.0, hold_off_s=1.0, warmup=mask)) == [(0.3, 0.4), (0.6, 0.7)]


def test_invalid_samples_are_skipped_without_breaking_persistence():
    x = series(2, 4, 6)
    valid = np.zeros(20, bool)
    valid[::2] = True  # a group updating every other step
    alarms = alarm_intervals(T, x, 1.0, n_persist=3, valid=valid)
    assert spans(alarms) == [(0.6, 0.6)]
    assert alarms[0].first_exceed == pytest.approx(0.2)
    x[5] = 10.0  # not judged: no effect
    assert spans(alarm_intervals(T, x, 1.0, n_persist=3, valid=valid)) == [(0.6, 0.6)]


def test_nonfinite_statistic_is_an_exceedance_where_valid():
    x = np.zeros(20)
    x[5], x[7] = np.nan, np.inf
    alarms = alarm_intervals(T, x, 1.0)
    assert spans(alarms) == [(0.5, 0.5), (0.7, 0.7)]
    assert alarms[0].bound == "nonfinite" and alarms[0].peak_ratio is None
    valid = np.ones(20, bool)
    valid[5] = False
    assert spans(alarm_intervals(T, x, 1.0, valid=valid)) == [(0.7, 0.7)]


def test_nonfinite_threshold_never_raises_by_itself():
    upper = np.full(20, np.nan)
    upper[10:] = 1.0
    alarms = alarm_intervals(T, np.full(20, 5.0), upper)
    assert spans(alarms) == [(1.0, 1.9)]


def test_peak_is_the_largest_excess_with_ratio():
    x = series(3, 4, 5)
    x[4] = 7.0
    alarm = alarm_intervals(T, x, 2.0, signal="accel", detector="nis")[0]
    assert alarm.peak_time == pytest.approx(0.4)
    assert (alarm.peak_value, alarm.peak_threshold, alarm.peak_ratio) == (7.0, 2.0, 3.5)
    assert (alarm.signal, alarm.detector) == ("accel", "nis")


def test_to_dict_is_strict_json():
    x = np.zeros(20)
    x[3] = np.nan
    data = alarm_intervals(T, x, 1.0)[0].to_dict()
    text = json.dumps(data, allow_nan=False)
    assert json.loads(text)["peak_value"] is None  # one JSON policy: NaN -> null
    assert data["duration"] == 0.0


def test_no_samples_and_no_exceedances_give_no_alarms():
    assert alarm_intervals(np.array([]), np.array([]), 1.0) == []
    assert alarm_intervals(T, np.zeros(20), 1.0) == []


@pytest.mark.parametrize(
    "kwargs",
    [
        {"upper": None},
        {"upper": np.ones(3)},
        {"upper": 1.0, "n_persist": 0},
        {"upper": 1.0, "valid": np.ones(3, bool)},
        {"upper": 1.0, "warmup": np.ones(3, bool)},
    ],
)
def test_bad_arguments_raise_internal_error(kwargs):
    with pytest.raises(InternalError, match="alarm_intervals"):
        alarm_intervals(T, np.zeros(20), **kwargs)


def make(start, end, signal="s", detector="d", ratio=2.0):
    return AlarmInterval(start, end, start, start, ratio, 1.0, ratio, "upper", 1, signal, detector)


def test_merge_close_merges_within_gap_per_signal():
    merged = merge_close([make(0, 1), make(1.5, 2, ratio=5.0), make(4, 5), make(1.2, 1.3, "other")], 0.5)
    assert [(m.signal, m.start, m.end) for m in merged] == [("s", 0, 2), ("other", 1.2, 1.3), ("s", 4, 5)]
    assert merged[0].peak_ratio == 5.0 and merged[0].n_exceed == 2


def test_merge_close_across_signals_joins_names():
    merged = merge_close([make(0, 1, "a"), make(1.2, 2, "b")], 0.5, by_signal=False)
    assert len(merged) == 1 and merged[0].signal == "a,b" and merged[0].end == 2


# --- properties -------------------------------------------------------------------------------

hot_masks = st.lists(st.booleans(), min_size=1, max_size=60)


def _x(hot):
    return np.where(np.array(hot), 2.0, 0.0)


@settings(max_examples=150, deadline=None)
@given(hot=hot_masks, n=st.integers(1, 5), hold=st.sampled_from([0.0, 0.1, 0.25, 0.5]))
def test_more_persistence_never_adds_alarm_time(hot, n, hold):
    t = np.arange(len(hot)) * DT
    fewer = alarm_intervals(t, _x(hot), 1.0, n_persist=n, hold_off_s=hold)
    more = alarm_intervals(t, _x(hot), 1.0, n_persist=n + 1, hold_off_s=hold)
    assert len(more) <= len(fewer)
    # every alarm of the stricter setting lies inside an alarm of the looser one
    for a in more:
        assert any(b.start <= a.start and a.end <= b.end for b in fewer)


@settings(max_examples=150, deadline=None)
@given(hot=hot_masks, warm=st.integers(0, 60), n=st.integers(1, 4), hold=st.sampled_from([0.0, 0.3]))
def test_alarms_never_contain_warmup_samples(hot, warm, n, hold):
    t = np.arange(len(hot)) * DT
    for a in alarm_intervals(t, _x(hot), 1.0, n_persist=n, hold_off_s=hold, warmup=warm):
        assert a.first_exceed >= t[min(warm, len(hot) - 1)] - 1e-12
        assert warm < len(hot)


@settings(max_examples=150, deadline=None)
@given(hot=hot_masks, n=st.integers(1, 4), hold=st.sampled_from([0.0, 0.1, 0.3]))
def test_alarms_are_ordered_disjoint_and_start_on_exceedances(hot, n, hold):
    t = np.arange(len(hot)) * DT
    x = _x(hot)
    alarms = alarm_intervals(t, x, 1.0, n_persist=n, hold_off_s=hold)
    for a in alarms:
        i0, i1 = int(round(a.start / DT)), int(round(a.end / DT))
        assert x[i0] > 1.0 and x[i1] > 1.0
        assert i0 - int(round(a.first_exceed / DT)) + 1 >= n
        assert np.all(x[int(round(a.first_exceed / DT)) : i0 + 1] > 1.0)
    for a, b in zip(alarms, alarms[1:]):
        assert b.start - a.end > hold


@settings(max_examples=100, deadline=None)
@given(hot=hot_masks)
def test_n_persist_1_without_hold_off_reproduces_the_runs(hot):
    t = np.arange(len(hot)) * DT
    alarms = alarm_intervals(t, _x(hot), 1.0)
    covered = np.zeros(len(hot), bool)
    for a in alarms:
        covered[int(round(a.start / DT)) : int(round(a.end / DT)) + 1] = True
    assert np.array_equal(covered, np.array(hot))


@settings(max_examples=150, deadline=None)
@given(
    values=st.lists(st.floats(-5, 5, allow_nan=False), min_size=1, max_size=60),
    n=st.integers(1, 3),
    hold=st.sampled_from([0.0, 0.2]),
)
def test_peak_is_the_largest_excess_inside_each_alarm(values, n, hold):
    x = np.array(values)
    t = np.arange(x.size) * DT
    for a in alarm_intervals(t, x, upper=1.0, lower=-2.0, n_persist=n, hold_off_s=hold):
        i0, i1 = int(round(a.start / DT)), int(round(a.end / DT))
        span = x[i0 : i1 + 1]
        excess = np.maximum(span - 1.0, -2.0 - span)
        k = i0 + int(np.argmax(excess))
        assert a.peak_time == pytest.approx(t[k])
        assert a.peak_value == x[k]
        assert a.bound == ("upper" if x[k] > 1.0 else "lower")
        assert a.peak_threshold == (1.0 if x[k] > 1.0 else -2.0)


@settings(max_examples=150, deadline=None)
@given(
    values=st.lists(st.floats(-5, 5, allow_nan=False), min_size=1, max_size=60),
    n=st.integers(1, 4),
    hold=st.sampled_from([0.0, 0.1, 0.3]),
    duration=st.sampled_from([0.0, 0.15]),
    cut=st.integers(0, 60),
)
def test_alarms_seen_from_a_time_are_the_whole_series_alarms_from_it(values, n, hold, duration, cut):
    """Rule 6: from ``from_t`` (a window's first step after a lead-in), the alarms are the whole
    series' that end at or after it, each from its first exceedance there, with the peak and count
    of that part: a persistence or hold-off that began before it still counts."""
    x = np.array(values)
    t = np.arange(x.size) * DT
    from_t = t[min(cut, x.size - 1)]
    options = {"upper": 1.0, "lower": -2.0, "n_persist": n, "hold_off_s": hold, "min_duration_s": duration}
    whole = alarm_intervals(t, x, **options)
    seen = alarm_intervals(t, x, **options, from_t=from_t)
    assert [a.end for a in seen] == [a.end for a in whole if a.end >= from_t]
    exceeds = (x > 1.0) | (x < -2.0)
    excess = np.maximum(x - 1.0, -2.0 - x)
    for a, b in zip(seen, [a for a in whole if a.end >= from_t]):
        # its first exceedance and count from from_t on; its start and peak the whole one's when
        # it starts from from_t, else from its first exceedance there
        first = t[np.flatnonzero(exceeds & (t >= max(b.first_exceed, from_t) - 1e-12))[0]]
        assert a.first_exceed == first
        assert a.n_exceed == np.count_nonzero(exceeds & (t >= first - 1e-12) & (t <= a.end + 1e-12))
        if b.start >= from_t:
            assert (a.start, a.peak_time, a.peak_value) == (b.start, b.peak_time, b.peak_value)
        else:
            assert a.start == first
            i0, i1 = int(round(a.start / DT)), int(round(a.end / DT))
            span = np.where(exceeds[i0 : i1 + 1], excess[i0 : i1 + 1], -np.inf)
            assert a.peak_time == t[i0 + int(np.argmax(span))]
