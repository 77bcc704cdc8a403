"""Decimation for the zoom: a click on an incident or alarm row shows that window drawn densely, on a
1-hour log, without growing the report; no focus when alarms are everywhere. The figures' data made
without copies of a whole log where none is needed."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_report import GRID_N, array, figures, make_report

from logscan.report import render_html
from logscan.report.figures import RANGE_SAMPLE, Figure, Trace, grid_step, judged_range
from logscan.report.plotly_json import (
    MAX_FOCUS_FRACTION,
    MIN_POINTS_FLOOR,
    POINT_BUDGET,
    _defined_samples,
    allocate_points,
    focus_windows,
    in_windows,
    typed_array,
    window_indices,
)
from logscan.report.stacked import is_flat


@pytest.fixture(scope="module")
def hour():
    report = make_report(GRID_N, hostile=False)
    return report, figures(render_html(report))


def zoom_window(start: float, end: float) -> tuple[float, float]:
    margin = max(2.0, 0.5 * (end - start))  # as templates/report.js
    return start - margin, end + margin


def lines(specs: list[dict]):
    """(figure id, trace name, x) of every drawn line (not the shaded spans)."""
    for spec in specs:
        for trace in spec["figure"]["data"]:
            if trace.get("yaxis") != "y2" and isinstance(trace["x"], dict):
                yield spec["id"], trace["name"], array(trace["x"])


def test_every_decimated_line_is_dense_where_an_alarm_row_zooms(hour):
    report, specs = hour
    for alarm in (a for result in report.results for a in result.alarms):
        lo, hi = zoom_window(alarm.start, alarm.end)
        for fig_id, name, x in lines(specs):
            if x.size >= 1_000:  # decimated (a short flat threshold is two points)
                inside = np.count_nonzero((x >= lo) & (x <= hi))
                # >= 40: the narrowest window is 4 s, where a 10 Hz statistic has 40 samples, all drawn
                # (the overview alone leaves about 10 points there)
                assert inside >= 40, (alarm.signal, fig_id, name, inside)


def test_the_focus_is_paid_from_the_point_budget(hour):
    _, specs = hour
    assert sum(x.size for _, _, x in lines(specs)) <= POINT_BUDGET * 1.05


def test_focus_windows_cover_the_alarms_with_the_zoom_margin():
    t = np.arange(360_000) * 0.01
    fig = Figure("f", "y", [], {"alarm": [(100.0, 100.5), (2000.0, 2030.0), (2030.5, 2031.0)]})
    windows = focus_windows([fig], t)
    assert np.allclose(windows, [[98.0, 102.5], [1984.5, 2046.5]])  # 2000-2031 is one incident


def test_no_focus_when_alarms_cover_much_of_the_log():
    t = np.arange(60_000) * 0.01  # 600 s
    spans = [(s, s + 1.0) for s in np.arange(0.0, 600.0, 600.0 * MAX_FOCUS_FRACTION / 5 / 2)]
    fig = Figure("f", "y", [Trace("y", np.zeros(t.size), np.zeros(0, int), 1.0, {})], {"alarm": spans})
    assert focus_windows([fig], t).shape == (0, 2)


# --- the figures' data, made cheaply ---------------------------------------------------------------


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_typed_arrays_are_written_as_plotly_writes_them(dtype):
    from _plotly_utils.utils import to_typed_array_spec

    values = np.array([1.5, np.nan, -2.25e-7, 3.4e38, 0.0], dtype=dtype)
    for array_like in (values, values[::2]):  # a strided view too
        assert typed_array(array_like) == to_typed_array_spec(array_like)
    assert typed_array(np.array([3, 4], dtype=np.int64)) == to_typed_array_spec(np.array([3, 4], dtype=np.int64))


_DTYPES = ["int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "float32", "float64"]
_DTYPES += ["bool", ">f8"]  # no typed array, and one plotly writes with its bytes as they are


@settings(max_examples=150, deadline=None)
@given(
    dtype=st.sampled_from(_DTYPES),
    shape=st.sampled_from([(0,), (1,), (7,), (3, 4)]),
    scale=st.sampled_from([1, 100, 40_000, 3_000_000_000, 2**62]),
    seed=st.integers(0, 2**16),
    strided=st.booleans(),
)
def test_every_array_is_written_as_plotly_writes_it(dtype, shape, scale, seed, strided):
    """Our typed arrays (without importing plotly's validators) equal plotly's for every dtype and
    shape, 64-bit integers narrowed where they fit and left as arrays where they do not."""
    from _plotly_utils.utils import to_typed_array_spec

    rng = np.random.default_rng(seed)
    kind = np.dtype(dtype).kind
    raw = rng.integers(0 if kind in "ub" else -scale, scale, size=shape, endpoint=True)
    values = (raw % 2 == 0) if kind == "b" else raw.astype(dtype) if kind in "iu" else (raw * 0.37).astype(dtype)
    if strided and values.ndim == 1:
        values = values[::2]
    ours, theirs = typed_array(values), to_typed_array_spec(values)
    if isinstance(theirs, np.ndarray):  # no typed array: the array itself, written as a list
        assert isinstance(ours, np.ndarray) and ours.tolist() == theirs.tolist()
    else:
        assert ours == theirs


def test_a_statistic_defined_after_its_warm_up_is_drawn_from_there_with_its_kept_samples():
    t = np.arange(1_000) * 0.01
    y = np.sin(t).astype(np.float32)
    y[:100] = np.nan  # the warm-up
    y[990:] = np.nan
    tc, yc, kept = _defined_samples(t, y, np.array([0, 150, 995]))
    assert np.shares_memory(tc, t) and np.shares_memory(yc, y)  # views, not copies
    np.testing.assert_array_equal(tc, t[100:990])
    np.testing.assert_array_equal(kept, [0, 50, 889])  # as the grid steps map onto the drawn samples
    y[500] = np.nan  # a missing step inside: the samples either side are joined (within 3 steps)
    tc, yc, _ = _defined_samples(t, y, np.zeros(0, np.int64))
    assert tc.size == 889 and not np.isnan(yc).any()


def test_the_grid_step_is_the_median_step():
    assert grid_step(np.array([0.0, 0.5, 1.0, 1.6])) == 0.5
    assert grid_step(np.arange(1_000_001) * 0.01) == pytest.approx(0.01, rel=1e-9)  # from 10,000 of its steps
    assert grid_step(np.zeros(1)) is None


@pytest.mark.parametrize(
    ("values", "flat"),
    [([np.nan, 1.0, 1.0, np.inf], True), ([1.0, 2.0], False), ([np.nan], True), ([0.0, -0.0], True)],
)
def test_a_row_is_flat_when_its_finite_values_are_one_value(values, flat):
    trace = Trace("s", np.array(values, dtype=np.float32), np.zeros(0, np.int64), 1.0, {})
    assert is_flat(Figure("det: s", "s", [trace], {})) is flat


@settings(max_examples=300, deadline=None)
@given(
    x=st.lists(st.integers(0, 20), max_size=40).map(lambda v: np.sort(np.asarray(v, dtype=float))),
    edges=st.lists(st.integers(-2, 22), max_size=6).map(lambda v: np.sort(np.asarray(v, dtype=float))),
    shuffle=st.booleans(),
)
def test_window_indices_are_the_samples_in_windows_sorted_or_not(x, edges, shuffle):
    windows = edges[: edges.size // 2 * 2].reshape(-1, 2)  # sorted and disjoint, or touching
    if shuffle:
        x = x[::-1].copy()  # unsorted: the per-sample search
    np.testing.assert_array_equal(window_indices(x, windows), np.flatnonzero(in_windows(x, windows)))


def test_the_floor_is_paid_from_the_budget():
    y = np.zeros(10)
    context = [Trace(f"c{i}", y, np.zeros(0, np.int64), 0.25, {}) for i in range(80)]
    statistics = [Trace(f"s{i}", y, np.zeros(0, np.int64), 1.0, {}) for i in range(10)]
    points = allocate_points([Figure("f", "y", context + statistics, {})], 10_000)
    # a 0.25 share of 10,000 points among a weight of 30 is 83: the context traces get the floor
    assert all(points[id(tr)] == MIN_POINTS_FLOOR for tr in context)
    # ... out of the budget: the statistics share what is left (a third of 10,000 each on top of it)
    assert all(points[id(tr)] == (10_000 - 80 * MIN_POINTS_FLOOR) // 10 for tr in statistics)
    assert sum(points.values()) <= 10_000


def _masked_range(values, upper, lower, peaks):
    """`judged_range` as first written: masks and copies of every array (the reference)."""
    defined = [band for band in (upper, lower) if band is not None]
    if not defined:
        return None
    judged = np.logical_or.reduce([np.isfinite(band) for band in defined])
    everything = values[np.isfinite(values)]
    parts = [part[judged][np.isfinite(part[judged])] for part in (values, *defined)]
    n_parts = sum(part.size for part in parts)
    if n_parts == 0 or everything.size == 0:
        return None
    step = max(n_parts // RANGE_SAMPLE, 1)
    lo, hi = np.percentile(np.concatenate([part[::step] for part in parts]), [0.1, 99.9])
    lo, hi = float(min([lo, *peaks])), float(max([hi, *peaks]))
    span = hi - lo
    with np.errstate(invalid="ignore"):
        full_lo = min(float(everything.min()), *(float(np.fmin.reduce(b)) for b in defined))
        full_hi = max(float(everything.max()), *(float(np.fmax.reduce(b)) for b in defined))
    if full_lo >= lo - span and full_hi <= hi + span:
        return None
    pad = 0.05 * span if span > 0 else max(abs(hi), 1.0) * 0.05
    return (lo - pad, hi + pad)


special = st.sampled_from([np.nan, np.inf, -np.inf, 1e6, -1e6])


@settings(max_examples=300, deadline=None)
@given(
    values=st.lists(st.floats(-10, 10) | special, min_size=1, max_size=60),
    upper=st.none() | st.lists(st.floats(0, 20) | special, min_size=60, max_size=60),
    lower=st.none() | st.lists(st.floats(-20, 0) | special, min_size=60, max_size=60),
    peaks=st.lists(st.floats(-100, 100), max_size=2),
)
def test_the_judged_range_is_that_of_the_finite_values_where_a_threshold_is_defined(values, upper, lower, peaks):
    values = np.asarray(values, dtype=np.float32)
    n = values.size
    bands = [None if band is None else np.asarray(band[:n], dtype=np.float32) for band in (upper, lower)]
    assert judged_range(values, *bands, peaks) == _masked_range(values, *bands, peaks)


def test_an_alarms_peak_is_drawn_beside_a_larger_sample():
    from logscan.report.figures import detector_figures
    from logscan.report.plotly_json import trace_data
    from logscan.results import DetectorResult

    t = np.arange(360_000) * 0.01
    statistic = np.zeros(t.size)
    statistic[200_000:200_020] = 5.0  # an alarm
    statistic[200_010] = 5.5  # its peak, inside it
    statistic[199_996] = 100.0  # one sample far over the threshold, too short to alarm, in the peak's bucket
    result = DetectorResult("d")
    result.add_statistic(t, "d.s", statistic, upper=1.0, n_persist=3)
    assert [alarm.peak_time for alarm in result.alarms] == [t[200_010]]
    figure = detector_figures(result, t, [], {}, [])[0]
    drawn = trace_data(figure, t, allocate_points([figure], 64), focus_windows([figure], t))
    line = next(trace for trace in drawn if trace["name"] == "d.s")
    assert np.float32(t[200_010]) in array(line["x"]) and np.float32(t[199_996]) in array(line["x"])


def test_series_with_one_pattern_of_nan_share_their_defined_steps():
    from logscan.report.plotly_json import DefinedSteps

    t = np.arange(2_000) * 0.01
    rng = np.random.default_rng(5)
    position = np.where(np.arange(t.size) % 10 == 3, rng.normal(size=t.size), np.nan).astype(np.float32)
    position[1_000:1_200] = np.nan  # a gap: the line breaks there
    cusum = np.where(np.isnan(position), np.nan, 2.0 * position).astype(np.float32)
    attitude = np.where(np.arange(t.size) % 2 == 0, 1.0, np.nan).astype(np.float32)
    steps, keep = DefinedSteps(t), np.array([0, 503, 1_990])
    for y in (position, cusum, attitude):
        shared, alone = _defined_samples(t, y, keep, steps), _defined_samples(t, y, keep)
        for a, b in zip(shared, alone):
            np.testing.assert_array_equal(a, b)
    assert len(steps._found) == 2  # position's steps found once for both of its series
    assert np.isnan(_defined_samples(t, cusum, keep, steps)[1]).sum() == 1  # the gap's one break


def test_a_figure_opening_zoomed_draws_its_range_densely_whatever_the_pages_windows():
    """The headline's figure opens on one alarm of a 1-hour log whose alarms cover too much of it for
    the page's focus: three quarters of its points go to that range, not a few of the overview's."""
    import json

    from logscan.report.plotly_json import OPENED_SHARE, figure_json

    t = np.arange(360_000) * 0.01
    y = np.sin(t * 7.0)
    fig = Figure("headline", "y", [Trace("y", y, np.zeros(0, np.int64), 1.0, {})], {"alarm": [(1000.0, 1000.1)]})
    fig.x_range = (998.0, 1002.1)
    drawn = json.loads(figure_json(fig, t, {}, np.zeros((0, 2))))["data"]
    x = array(next(trace["x"] for trace in drawn if trace["name"] == "y"))
    inside = np.count_nonzero((x >= 998.0) & (x <= 1002.1))
    assert inside >= min(410, OPENED_SHARE * x.size * 0.9), (inside, x.size)
    fig.x_range = None  # the same figure not zoomed: the overview's few points there
    drawn = json.loads(figure_json(fig, t, {}, np.zeros((0, 2))))["data"]
    x = array(next(trace["x"] for trace in drawn if trace["name"] == "y"))
    assert np.count_nonzero((x >= 998.0) & (x <= 1002.1)) < 20
