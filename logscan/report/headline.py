"""The first screen: each incident's line with the span and physical size of the check it quotes,
and the headline incident's sensor, measured vs predicted, zoomed to it.

An incident groups every alarm that overlaps it (`logscan.verdict.incidents`): a 10 s accelerometer
bias trips the accelerometer's test and, later, the checks of the sensors the drifting estimate
then disagrees with, so the incident spans 30-60 s for a 30-40 s fault. The line a user reads first
gives the span of the check the headline quotes (its largest alarm on the source group), and how big
the deviation is in the sensor's own units: the largest half-second mean of the innovation (measured -
predicted) during that alarm, on the channel that left its band the most ("+0.92 m/s² (9.2σ) on accel
ax for 11.3 s").
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from logscan.alarms import AlarmInterval
from logscan.errors import ModelError
from logscan.models import model_class
from logscan.report.figures import Figure
from logscan.report.plotly_json import ZOOM_MARGIN_FRACTION, ZOOM_MARGIN_S
from logscan.report.sensor_figures import sensor_figures
from logscan.report.sensor_views import Innovations, SensorView
from logscan.results import Incident
from logscan.timebase.clock import Clock
from logscan.verdict.incidents import group_of

DEVIATION_WINDOW_S = 0.5  # the deviation is the largest mean innovation over this long
MIN_WINDOW_SAMPLES = 3  # updates in a window for its mean to count
UNIT_TEXT = {"^2": "²", "^3": "³", "^-1": "⁻¹", "^-2": "⁻²"}  # as a model's GroupSpec writes them


@dataclass
class Deviation:
    """The largest windowed mean innovation during an alarm, on the channel that left its band the most."""

    channel: int  # column in the group's `SensorView`
    name: str  # "accel ax": the group and the model's output name
    size: float  # mean measured - predicted, in the sensor's units
    sigmas: float  # mean normalised innovation
    unit: str
    duration: float  # of the alarm, s

    def text(self) -> str:
        """'+0.92 m/s² (9.2σ) on accel ax for 11.3 s'."""
        unit = f" {self.unit}" if self.unit else ""
        sigmas = significant(abs(self.sigmas)).lstrip("+")
        return f"{significant(self.size)}{unit} ({sigmas}σ) on {self.name} for {self.duration:.1f} s"


@dataclass
class Headline:
    """One incident as the verdict box says it, and (the first incident's) sensor figure."""

    incident: Incident
    alarm: AlarmInterval | None  # the alarm of the check the headline quotes
    group: str | None
    deviation: Deviation | None

    def line(self, clock: Clock) -> str:
        """'accelerometer inconsistent: +0.92 m/s² (9.2σ) on accel ax for 11.3 s, 30.00-41.27 s
        (nis.accel, peak 10.7x)'; the incident's own headline when it quotes no alarm in words."""
        inc = self.incident
        if not inc.what or self.alarm is None:
            return inc.headline_in(clock)
        size = f": {self.deviation.text()}," if self.deviation else ""
        return f"{inc.what}{size} {clock.span_text(float(self.alarm.start), float(self.alarm.end))} ({inc.detail})"


def significant(value: float, digits: int = 2) -> str:
    """``value`` with a sign and ``digits`` significant figures, trailing zeros kept: '+1.0', '-0.034'."""
    if not math.isfinite(value) or value == 0:
        return f"{value:+g}"
    decimals = max(digits - 1 - math.floor(math.log10(abs(value))), 0)
    return f"{value:+.{decimals}f}"


def _ratio(alarm: AlarmInterval) -> float:
    if alarm.bound == "nonfinite":
        return math.inf
    return alarm.peak_ratio if alarm.peak_ratio is not None else -math.inf


def quoted_alarm(incident: Incident, groups: Sequence[str]) -> AlarmInterval | None:
    """The alarm an incident's headline quotes: its source group's (or signal's) alarm with the
    largest peak / threshold (`logscan.verdict.incidents`, rule 3); None for an incident without
    alarms."""
    alarms = incident.alarms
    named = [a for a in alarms if group_of(a.signal, groups) == incident.source]
    named = named or [a for a in alarms if a.signal == incident.source] or alarms
    return max(named, key=_ratio, default=None)


def unit_text(unit: str) -> str:
    for plain, pretty in UNIT_TEXT.items():
        unit = unit.replace(plain, pretty)
    return unit


def group_units(model: Mapping, group: str) -> list[str]:
    """The units of a group's outputs as its model class declares them ([] when it does not: a
    model whose groups come from its parameters, or no model)."""
    try:
        groups = getattr(model_class(str(model.get("name", ""))), "groups", None)
    except ModelError:
        return []
    spec = groups.get(group) if isinstance(groups, dict) else None
    return [str(u) for u in getattr(spec, "units", ())]


def _window_means(values: np.ndarray, width: int) -> tuple[np.ndarray, np.ndarray]:
    """(means, counts) of each column's defined values over every run of ``width`` rows."""
    defined = np.isfinite(values)
    sums = np.vstack([np.zeros((1, values.shape[1])), np.cumsum(np.where(defined, values, 0.0), axis=0)])
    counts = np.vstack([np.zeros((1, values.shape[1])), np.cumsum(defined, axis=0)])
    width = min(width, values.shape[0])
    n = counts[width:] - counts[:-width]
    with np.errstate(invalid="ignore", divide="ignore"):
        return (sums[width:] - sums[:-width]) / n, n


def deviation(view: SensorView, t: np.ndarray, alarm: AlarmInterval, model: Mapping) -> Deviation | None:
    """How far the sensor left its prediction during ``alarm``: on the channel whose normalised
    innovation had the largest mean over DEVIATION_WINDOW_S (the whole alarm when shorter), that
    window's mean innovation. A window, not the whole alarm: the filter absorbs a bias bit by bit,
    so the innovation is largest when the fault begins. None: no update of the group in the alarm."""
    start, end = float(alarm.start), float(alarm.end)
    rows = np.flatnonzero((t >= start) & (t <= end))
    if rows.size == 0:
        return None
    normalised = view.normalised[rows].astype(np.float64)
    innovation = (view.measured[rows] - view.predicted[rows]).astype(np.float64)
    innovation[~np.isfinite(normalised)] = np.nan
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    width = max(int(round(DEVIATION_WINDOW_S / dt)), 1) if dt > 0 else rows.size
    sigmas, counts = _window_means(normalised, width)
    score = np.where(counts >= MIN_WINDOW_SAMPLES, np.abs(sigmas), -1.0)
    if not np.isfinite(score).any() or score.max() < 0:
        return None
    at, j = np.unravel_index(int(np.nanargmax(score)), score.shape)
    size = _window_means(innovation[:, [j]], width)[0][at, 0]
    outputs = list(((model.get("groups") or {}).get(view.group) or {}).get("outputs") or [])
    output = outputs[j] if j < len(outputs) else view.channels[j]
    units = group_units(model, view.group)
    unit = unit_text(units[j]) if j < len(units) else ""
    return Deviation(int(j), f"{view.group} {output}", float(size), float(sigmas[at, j]), unit, end - start)


def headlines(
    incidents: Sequence[Incident], innovations: Innovations | None, t: np.ndarray, model: Mapping
) -> list[Headline]:
    """One `Headline` per incident, in order."""
    groups = list((model.get("groups") or {}).keys()) or (innovations.group_names if innovations else [])
    views: dict[str, SensorView | None] = {}
    out = []
    for incident in incidents:
        alarm = quoted_alarm(incident, groups)
        group = None
        if alarm is not None and innovations is not None:
            group = group_of(alarm.signal, innovations.group_names)
        size = None
        if alarm is not None and group is not None and innovations is not None:
            if group not in views:
                views[group] = innovations.view(group)
            view = views[group]
            size = None if view is None else deviation(view, t, alarm, model)
        out.append(Headline(incident, alarm, group, size))
    return out


def zoom_range(start: float, end: float) -> tuple[float, float]:
    """A span with the margin a click on its row zooms with (templates/report.js)."""
    margin = max(ZOOM_MARGIN_S, ZOOM_MARGIN_FRACTION * (end - start))
    return start - margin, end + margin


def headline_figure(
    headline: Headline, innovations: Innovations | None, t: np.ndarray, truth_spans: list
) -> Figure | None:
    """The channel the headline names, measured vs predicted with its ±3σ band, zoomed to the
    quoted alarm; None when the headline names no sensor channel."""
    if headline.deviation is None or headline.group is None or innovations is None or headline.alarm is None:
        return None
    view = innovations.view(headline.group)
    if view is None:
        return None
    span = (float(headline.alarm.start), float(headline.alarm.end))
    spans = {"alarm": [span], "ground truth": truth_spans}
    figures = sensor_figures(view, t, spans, [span], channels=[headline.deviation.channel])
    figure = figures[0]
    figure.title = f"{headline.deviation.name}: measured vs predicted, {headline.deviation.text()}"
    figure.x_range = zoom_range(*span)
    figure.y_range = _visible_range(figure.traces, figure.x_range)
    figure.caption = (
        f"The sensor the headline names, zoomed to the alarm it quotes (shaded red): {figure.caption} "
        "The same channel is in its detector's section below, over the whole log."
    )
    return figure


def _visible_range(traces: Sequence, x_range: tuple[float, float]) -> tuple[float, float] | None:
    """The y range of the traces' samples inside ``x_range``, padded by 5 %."""
    parts = [
        np.asarray(tr.y[(tr.t >= x_range[0]) & (tr.t <= x_range[1])], dtype=np.float64)
        for tr in traces
        if tr.t is not None
    ]
    values = np.concatenate(parts) if parts else np.zeros(0)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return None
    lo, hi = float(values.min()), float(values.max())
    pad = 0.05 * (hi - lo) if hi > lo else max(abs(hi), 1.0) * 0.05
    return lo - pad, hi + pad
