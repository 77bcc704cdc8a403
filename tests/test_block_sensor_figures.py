"""Block mode's report keeps the sensor figures (`logscan.report.kept_views`): each block keeps the
rows of its packed innovations its figures draw, with their times; the merged report draws the
alarmed group's measured vs predicted from them, at the values the analysis at once has there."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import SAMPLES

from logscan.pipeline import analyze_log, blocks
from logscan.pipeline.blocks import analyze_blocked
from logscan.report import plotly_json
from logscan.report.headline import zoom_range
from logscan.report.page_parts import PageInput
from logscan.report.page_sections import first_screen
from logscan.report.sensor_figures import REDUCED_POINTS
from logscan.verdict.incidents import group_of

BIAS = SAMPLES / "quad_imu_bias.mcap"  # 60 s at 100 Hz, an accelerometer bias from 30 to 40 s
SERIES = 5  # a channel's figure draws predicted, measured, the band's two edges and the normalised innovation


@pytest.fixture(scope="module")
def whole():
    return analyze_log(BIAS, free_series=True, sensor_views=True)


def _at(whole, t: np.ndarray) -> np.ndarray:
    """The steps of the analysis at once at the times ``t`` (each one of its grid's)."""
    steps = np.searchsorted(whole.run.t, t - 1e-9)
    np.testing.assert_allclose(whole.run.t[steps], t, atol=1e-9)
    return steps


def _equal_to_a_float32_rounding(ours: np.ndarray, theirs: np.ndarray) -> None:
    """Equal but for a float32 rounding at each channel's magnitude: each block packs a prediction
    as float32 less its own block's median, the analysis at once less the log's."""
    assert np.array_equal(np.isfinite(ours), np.isfinite(theirs))
    finite = np.isfinite(ours)
    ours, theirs = (
        np.where(finite, ours, 0).reshape(ours.shape[0], -1),
        np.where(finite, theirs, 0).reshape(ours.shape[0], -1),
    )
    for j in range(ours.shape[1]):
        rounding = 2 * np.spacing(np.max(np.abs(theirs[:, j])))
        np.testing.assert_allclose(ours[:, j], theirs[:, j], rtol=0, atol=rounding)


def test_the_headline_sensor_figure_is_drawn_from_the_kept_rows(whole):
    """The block-mode report's headline figure is the alarmed accelerometer's measured vs predicted,
    at the values of the analysis at once at the same times (float32 as packed)."""
    merged = analyze_blocked(BIAS, block_s=20.0, free_series=True, sensor_views=True)
    report = merged.report_input()
    heads, first, _ = first_screen(PageInput(report, np.asarray(report.t, dtype=np.float64), []))
    assert first is not None and heads[0].group == "accel"
    traces = {trace.name: trace for trace in first.traces}
    channel = heads[0].deviation.channel
    at_once = whole.prepared.innovations.view("accel")
    for name, field in ((at_once.channels[channel], "measured"), ("predicted h(x̂⁻)", "predicted")):
        trace = traces[name]
        assert trace.t.size > 100
        _equal_to_a_float32_rounding(trace.y, getattr(at_once, field)[_at(whole, trace.t), channel])
    kept = merged.prepared.innovations
    t = kept.times("accel", report.t)
    assert np.all(np.diff(t) > 0) and t[0] >= 0.0 and t[-1] <= 60.0  # no lead-in step twice
    for field in ("measured", "predicted", "sigma", "normalised"):
        _equal_to_a_float32_rounding(getattr(kept.view("accel"), field), getattr(at_once, field)[_at(whole, t)])


def test_each_block_keeps_at_most_its_share_and_the_alarms_in_full(whole, monkeypatch):
    """With 60 points per series over the log (20 per block) the accelerometer keeps at most that
    many rows per series and channel outside its alarms' zoom windows, and every step inside."""
    monkeypatch.setattr(blocks, "REDUCED_POINTS", 60)
    monkeypatch.setattr(plotly_json, "MAX_FOCUS_FRACTION", 1.0)  # a 20-s block keeps its alarms' windows
    merged = analyze_blocked(BIAS, block_s=20.0, free_series=True, sensor_views=True)
    kept = merged.prepared.innovations
    t = kept.times("accel", merged.run.t)
    channels = len(kept.channels["accel"])
    named = [(a.start, a.end) for a in merged.alarms if group_of(a.signal, kept.group_names) == "accel"]
    for start, end in named:  # every step of an alarm naming the group, at full rate
        grid = whole.run.t[(whole.run.t >= start) & (whole.run.t <= end)]
        assert np.isin(np.round(grid, 6), np.round(t, 6)).all()
    outside = ~plotly_json.in_windows(
        t, plotly_json.zoom_windows(named, merged.run.t)
    )  # the blocks' windows lie within
    assert 0 < np.count_nonzero(outside) <= 3 * SERIES * channels * 20
    assert t.size < 6001 and REDUCED_POINTS > 60


def test_an_alarm_from_a_border_is_drawn_in_full_from_before_it(whole, monkeypatch):
    """Blocks of 30 s: the accelerometer's alarm begins on the border. Its zoom window's steps
    before the border (the block before's, in the later block's lead-in) are kept in full from the
    later block, in place of the block before's few, once each and in time order."""
    monkeypatch.setattr(blocks, "REDUCED_POINTS", 60)
    monkeypatch.setattr(plotly_json, "MAX_FOCUS_FRACTION", 10.0)  # windows past the block: kept
    merged = analyze_blocked(BIAS, block_s=30.0, free_series=True, sensor_views=True)
    kept = merged.prepared.innovations
    t = kept.times("accel", merged.run.t)
    assert np.all(np.diff(t) > 0)
    before_border = whole.run.t[(whole.run.t >= 28.0) & (whole.run.t < 30.0)]  # within every margin (>= 2 s)
    assert np.isin(np.round(before_border, 6), np.round(t, 6)).all()
    assert np.count_nonzero(t < 20.0) <= SERIES * len(kept.channels["accel"]) * 30  # the first block's share
    _equal_to_a_float32_rounding(
        kept.view("accel").measured, whole.prepared.innovations.view("accel").measured[_at(whole, t)]
    )


def test_an_incidents_size_from_the_merged_rows_is_the_analysis_at_onces(whole):
    """The incidents found again on the merged analysis (a --suppressions file: `sizes_of`) size the
    accelerometer's deviation from the kept rows at their own times, as at once from the grid."""
    from logscan.verdict.incidents import sizes_of

    merged = analyze_blocked(BIAS, block_s=20.0, free_series=True, sensor_views=True)
    alarm = next(a for a in merged.alarms if a.signal == "nis.accel")
    text = sizes_of(merged.prepared).text("accel", alarm)
    assert text.startswith("+0.92 m/s² (9.2σ) on accel ax") and text == sizes_of(whole.prepared).text("accel", alarm)


def test_past_the_logs_focus_rows_a_block_keeps_the_extremes_inside_its_windows(whole, monkeypatch):
    """With the log's rows inside zoom windows capped at 600 (the alarm's windows hold about
    3,000 steps, over two 20-s blocks), the accelerometer keeps at most that many there, and among them
    each channel's highest and lowest measured value inside the windows at once."""
    monkeypatch.setattr(blocks, "FOCUS_ROWS", 600)
    monkeypatch.setattr(blocks, "REDUCED_POINTS", 60)
    monkeypatch.setattr(plotly_json, "MAX_FOCUS_FRACTION", 1.0)  # a 20-s block keeps its alarms' windows
    merged = analyze_blocked(BIAS, block_s=20.0, free_series=True, sensor_views=True)
    kept = merged.prepared.innovations
    assert 0 < kept.focus["accel"] <= 600
    t = kept.times("accel", merged.run.t)
    named = [(a.start, a.end) for a in merged.alarms if group_of(a.signal, kept.group_names) == "accel"]
    windows = plotly_json.zoom_windows(named, merged.run.t)
    inside_at_once = plotly_json.in_windows(whole.run.t, windows)
    assert np.count_nonzero(inside_at_once) > 2500  # the cap thins them
    channels = len(kept.channels["accel"])
    inside = plotly_json.in_windows(t, windows)
    assert np.count_nonzero(inside) <= 600 + 2 * SERIES * channels * 20  # and two blocks' own shares
    measured, at_once = kept.view("accel").measured[inside], whole.prepared.innovations.view("accel").measured
    for j in range(channels):
        theirs = at_once[inside_at_once, j]
        for extreme in (np.nanmax, np.nanmin):
            rounding = 2 * float(np.spacing(np.nanmax(np.abs(theirs))))  # each block's pack, as above
            assert float(extreme(measured[:, j])) == pytest.approx(float(extreme(theirs)), abs=rounding)


def test_thinned_rows_keep_every_series_extremes_within_the_limit():
    """`_thinned` of 5,000 rows to 600: at most the limit (plus each series' first and last), and
    every channel's series (measured, predicted, the band's edges, normalised) keeps its extremes."""
    from logscan.report.kept_views import DRAWN_SERIES, _thinned
    from logscan.report.sensor_views import SensorView

    rng = np.random.default_rng(7)
    n, channels = 5000, 3
    values = [rng.normal(size=(n, channels)).astype(np.float32) for _ in range(4)]
    values[1][::3] = np.nan  # a channel's prediction undefined on some steps
    view = SensorView("g", ["a", "b", "c"], *values)
    t = np.arange(n) * 0.01
    rows = np.arange(100, 4900)
    kept = _thinned(view, t, rows, 600)
    assert kept.size <= 600 + 2 * DRAWN_SERIES * channels and np.all(np.isin(kept, rows))
    assert np.array_equal(_thinned(view, t, rows[:500], 600), rows[:500])  # under the limit: all
    for j in range(channels):
        defined = rows[np.isfinite(view.predicted[rows, j])]
        for series in (view.measured[:, j], view.predicted[:, j], view.normalised[:, j]):
            assert np.nanmax(series[kept]) == np.nanmax(series[defined])
            assert np.nanmin(series[kept]) == np.nanmin(series[defined])


def test_where_the_alarms_cover_too_much_a_block_keeps_its_headlines_window(whole, monkeypatch):
    """Where the zoom windows of all the alarms cover more of a block than is kept in full
    (`MAX_FOCUS_FRACTION`, here almost none), each block still keeps every step inside the window of
    its first incident's quoted alarm, which the report's headline opens on: the accelerometer's
    bias from 30 s, drawn at full rate, not at the overview's share of 20 points per series, also
    past the block's end at 40 s, where the next block's first incident quotes another sensor."""
    monkeypatch.setattr(blocks, "REDUCED_POINTS", 60)
    monkeypatch.setattr(plotly_json, "MAX_FOCUS_FRACTION", 1e-6)
    merged = analyze_blocked(BIAS, block_s=20.0, free_series=True, sensor_views=True)
    kept = merged.prepared.innovations
    t = kept.times("accel", merged.run.t)
    quoted = merged.incidents[0].quoted
    assert quoted is not None and group_of(quoted.signal, kept.group_names) == "accel"
    assert quoted.start == pytest.approx(30.0, abs=0.02)
    # its block (20-40 s) keeps its part of the window, the next block, told of it, the rest
    lo, hi = zoom_range(quoted.start, quoted.end)
    grid = whole.run.t[(whole.run.t >= lo) & (whole.run.t <= hi)]
    assert grid.size > 2000 and hi > 45.0
    assert np.isin(np.round(grid, 6), np.round(t, 6)).all()
    assert np.count_nonzero(t < 20.0) <= SERIES * len(kept.channels["accel"]) * 20  # no window in the first block
