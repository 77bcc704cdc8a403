"""The sensor beside the statistic: figures of a measurement group an alarm names.

Per channel of the group, the measured value against the filter's prediction h(x_prior) with its
+-k sigma band of S; then one figure of every channel's normalised innovation y_i / sigma_i
(`logscan.report.sensor_views`). The legend carries the channel names from the log.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from logscan.report.decimate import decimate_indices, edge_indices, sorted_unique
from logscan.report.figures import LINE_COLOURS, Figure, Trace, judged_range, merge_spans, span_limits
from logscan.report.plotly_json import ascends, window_indices, zoom_windows
from logscan.report.sensor_views import K_SIGMA, PageViews, SensorView
from logscan.results import DetectorResult
from logscan.verdict.incidents import group_of

BAND_FILL = "rgba(255, 127, 14, 0.18)"
PREDICTED_COLOUR = "#ff7f0e"
MEASURED_COLOUR = "#1f77b4"
REDUCED_POINTS = 4_000  # per series, before the page's own decimation


def named_group_figures(
    result: DetectorResult, views: PageViews | None, t: np.ndarray, truth_spans: list, drawn: set[str]
) -> list[Figure]:
    """The sensor figures of the groups ``result``'s alarms name (in the order they first alarm)
    that are not in ``drawn`` (added to it: a group is drawn once per report; its view taken from
    ``views``), each at its group's times (`PageViews.times`: ``t``, the analysis grid, at once)."""
    if views is None:
        return []
    by_group: dict[str, list] = {}
    for alarm in sorted(result.alarms, key=lambda a: a.start):
        group = group_of(alarm.signal, views.group_names)
        if group is not None and group not in drawn:
            by_group.setdefault(group, []).append((float(alarm.start), float(alarm.end)))
    figures = []
    min_width, min_gap = span_limits(t)
    for group, alarm_spans in by_group.items():
        drawn.add(group)
        spans = {"alarm": merge_spans(alarm_spans, min_width, min_gap), "ground truth": truth_spans}
        view = views.take(group)
        figures.extend(sensor_figures(view, views.times(group, t), spans, alarm_spans) if view is not None else [])
    return figures


def _defined_steps(series: np.ndarray) -> np.ndarray | slice:
    """The steps where ``series`` is finite: an index array, or ``slice(None)`` when it is finite
    everywhere (then the series are used as they are, views, not copies of their defined steps)."""
    defined = np.isfinite(series)
    return slice(None) if bool(defined.all()) else np.flatnonzero(defined)


def _chosen(
    x: np.ndarray, series: list[np.ndarray], windows: np.ndarray, ascending: bool | None, points: int = REDUCED_POINTS
) -> np.ndarray:
    """Indices into ``series`` (defined samples at the times ``x``) drawing them, without keeping
    them all until the page is written: at most ``points`` per series (min/max per bucket)
    plus every one inside the zoom ``windows`` (the page decimates again under its point budget).
    ``ascending``: whether ``x`` ascends (None: not known)."""
    if x.size <= points:
        return np.arange(x.size)
    chosen = [decimate_indices(s, points, simplify_flat=True) for s in series]
    inside = window_indices(x, windows, ascending) if windows.size else chosen[0][:0]
    return sorted_unique(*chosen, inside)


def _reduced(t: np.ndarray, series: list[np.ndarray], windows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(times, indices): the steps drawing ``series`` (same length as ``t``): the steps where the
    first series is defined, `_chosen` among them."""
    pick = _defined_steps(series[0])
    steps = np.arange(t.size)[pick]
    steps = steps[_chosen(t[pick], [s[pick] for s in series], windows, None)]
    return t[steps], steps


def _channel_series(view: SensorView, j: int) -> tuple[np.ndarray | slice, list[np.ndarray]]:
    """(steps, series): the steps where channel ``j``'s prediction is defined (`_defined_steps`) and
    there its predicted, measured, upper and lower band and normalised innovation, as drawn."""
    pick = _defined_steps(view.predicted[:, j])
    predicted, measured, sigma, innovation = (a[pick, j] for a in (view.predicted, view.measured,
                                                                   view.sigma, view.normalised))  # fmt: skip
    half = np.float32(K_SIGMA) * sigma
    return pick, [predicted, measured, predicted + half, predicted - half, innovation]


def drawn_steps(view: SensorView, j: int, t: np.ndarray, windows: np.ndarray, points: int) -> np.ndarray:
    """The steps (indices into ``t``, the view's times) channel ``j``'s figure draws from when
    `_chosen` keeps at most ``points`` per series outside the zoom ``windows``."""
    pick, series = _channel_series(view, j)
    chosen = _chosen(t[pick], series, windows, ascends(t) if windows.size else None, points)
    return np.arange(t.size)[pick][chosen]


def sensor_figures(
    view: SensorView, t: np.ndarray, spans: dict, alarm_spans: Sequence, channels: Sequence[int] | None = None
) -> list[Figure]:
    """The figures of one group: one per channel (measured vs predicted), then the normalised
    innovations; ``spans`` shaded as on the statistic's figure, ``alarm_spans`` (the alarms
    naming the group) kept in full around them. ``channels``: only these columns (the normalised
    innovations of these alone). Each channel is drawn from the steps where its prediction is
    defined, taken before its band is computed (a 10 Hz sensor's on a 100 Hz grid: a tenth)."""
    windows = zoom_windows(list(alarm_spans), t)
    grid_ascends = ascends(t) if windows.size else None  # the times of any steps of t then ascend too
    figures, normalised = [], []
    for j, channel in enumerate(view.channels):
        if channels is not None and j not in channels:
            continue
        pick, series = _channel_series(view, j)
        chosen = _chosen(t[pick], series, windows, grid_ascends)
        x = t[pick][chosen]
        predicted, measured, upper, lower, innovation = (s[chosen] for s in series)
        keep = edge_indices(x, list(alarm_spans))
        figures.append(_channel_figure(view.group, channel, x, keep, predicted, measured, upper, lower, spans))
        normalised.append(_normalised_trace(channel, j, innovation, keep, x))
    figures.append(_normalised_figure(view.group, normalised, spans))
    return figures


def _channel_figure(group: str, channel: str, x, keep, predicted, measured, upper, lower, spans: dict) -> Figure:
    """One channel, measured vs predicted with its band, drawn at the times ``x``."""
    k = K_SIGMA
    band_style = {"line": {"width": 0, "color": BAND_FILL}, "hoverinfo": "skip"}
    traces = [
        Trace(f"predicted ± {k:g}σ", upper, keep, 0.25, {**band_style, "legendgroup": "band"}, t=x),
        Trace(
            f"predicted ± {k:g}σ (lower)", lower, keep, 0.25,
            {**band_style, "legendgroup": "band", "showlegend": False, "fill": "tonexty", "fillcolor": BAND_FILL},
            t=x,
        ),
        Trace("predicted h(x̂⁻)", predicted, keep, 0.5,
              {"line": {"color": PREDICTED_COLOUR, "width": 1.2, "dash": "dot"}}, t=x),
        Trace(channel, measured, keep, 1.0, {"line": {"color": MEASURED_COLOUR, "width": 1.2}}, t=x),
    ]  # fmt: skip
    return Figure(
        title=f"{group}: {channel} measured vs predicted",
        y_title=channel,
        traces=traces,
        spans=spans,
        caption=f"{channel} as the filter used it (blue) against the filter's prediction of it from the state "
        f"before the update (orange, dotted) with ±{k:g}σ of the innovation covariance S (shaded). Normal: "
        "blue inside the shaded band; blue leaving the band on one sensor while the others stay is that "
        "sensor's fault.",
        y_range=judged_range(measured, upper, lower, []),
    )  # fmt: skip


def _normalised_trace(channel: str, j: int, y: np.ndarray, keep: np.ndarray, x: np.ndarray) -> Trace:
    return Trace(channel, y, keep, 0.5, {"line": {"color": LINE_COLOURS[j % len(LINE_COLOURS)], "width": 1}}, t=x)


def _normalised_figure(group: str, traces: list[Trace], spans: dict) -> Figure:
    k = K_SIGMA
    return Figure(
        title=f"{group}: normalised innovation per channel",
        y_title="innovation / σ",
        traces=traces,
        spans=spans,
        caption=f"Each channel's innovation (measured − predicted) divided by its σ from S. Normal: noise "
        f"around 0, mostly within ±{k:g} (dashed); a sustained offset on one channel is a bias on that axis.",
        hlines=[(k, f"+{k:g}σ"), (-k, f"−{k:g}σ")],
    )  # fmt: skip


def normalised_figure(
    group: str, channels: Sequence[str], normalised: np.ndarray, t: np.ndarray, spans: dict
) -> Figure:
    """The last figure of `sensor_figures` alone, from the group's (N, k) normalised innovations
    (`Innovations.normalised`): each channel reduced on its own samples, not with its measured and
    predicted values, which are not drawn."""
    no_windows = np.zeros((0, 2))
    traces = []
    for j, channel in enumerate(channels):
        x, steps = _reduced(t, [normalised[:, j]], no_windows)
        traces.append(_normalised_trace(channel, j, normalised[steps, j], np.zeros(0, np.int64), x))
    return _normalised_figure(group, traces, spans)
