"""The first screen: each incident's line with the span and physical size of the check it quotes,
and the headline incident's sensor, measured vs predicted, zoomed to it.

The line is the incident's own (`logscan.results.Incident.headline_in`: the terminal and the JSON
say the same), the size of the deviation from `logscan.verdict.deviation`; here the sensor figure
of the channel that size was measured on.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from logscan.alarms import AlarmInterval, peak_rank
from logscan.report.figures import Figure
from logscan.report.plotly_json import ZOOM_MARGIN_FRACTION, ZOOM_MARGIN_S
from logscan.report.sensor_figures import sensor_figures
from logscan.report.sensor_views import PageViews
from logscan.results import Incident
from logscan.timebase.clock import Clock
from logscan.verdict.deviation import Deviation, deviation, significant
from logscan.verdict.incidents import group_of

__all__ = ["Headline", "headline_figure", "headlines", "quoted_alarm", "significant", "zoom_range"]


@dataclass
class Headline:
    """One incident as the verdict box says it, and (the first incident's) sensor figure."""

    incident: Incident
    alarm: AlarmInterval | None  # the alarm of the check the headline quotes
    group: str | None
    deviation: Deviation | None

    def line(self, clock: Clock) -> str:
        """The incident's headline (`Incident.headline_in`), with the size measured here."""
        return self.incident.headline_in(clock, self.deviation.text() if self.deviation else None)


def quoted_alarm(incident: Incident, groups: Sequence[str]) -> AlarmInterval | None:
    """The alarm an incident's headline quotes: the incident's own (`logscan.verdict.incidents`,
    rule 3); for an incident built without one (read back from a summary), its source group's (or
    signal's) alarm with the largest peak / threshold; None for an incident without alarms."""
    if incident.quoted is not None:
        return incident.quoted
    alarms = incident.alarms
    named = [a for a in alarms if group_of(a.signal, groups) == incident.source]
    named = named or [a for a in alarms if a.signal == incident.source] or alarms
    return max(named, key=peak_rank, default=None)


def headlines(incidents: Sequence[Incident], views: PageViews | None, t: np.ndarray, model: Mapping) -> list[Headline]:
    """One `Headline` per incident, in order (the groups' views from ``views``, kept there)."""
    groups = list((model.get("groups") or {}).keys()) or (views.group_names if views else [])
    out = []
    for incident in incidents:
        alarm = quoted_alarm(incident, groups)
        group = None
        if alarm is not None and views is not None:
            group = group_of(alarm.signal, views.group_names)
        if group != incident.source:  # headed by no group (a missing input, an overall check): no size
            group = None
        size = None
        if alarm is not None and group is not None and views is not None:
            view = views.view(group)
            size = None if view is None else deviation(view, views.times(group, t), alarm, model)
        out.append(Headline(incident, alarm, group, size))
    return out


def zoom_range(start: float, end: float) -> tuple[float, float]:
    """A span with the margin a click on its row zooms with (templates/report.js)."""
    margin = max(ZOOM_MARGIN_S, ZOOM_MARGIN_FRACTION * (end - start))
    return start - margin, end + margin


def headline_figure(headline: Headline, views: PageViews | None, t: np.ndarray, truth_spans: list) -> Figure | None:
    """The channel the headline names, measured vs predicted with its ±3σ band, zoomed to the
    quoted alarm; None when the headline names no sensor channel."""
    if headline.deviation is None or headline.group is None or views is None or headline.alarm is None:
        return None
    view = views.view(headline.group)
    if view is None:
        return None
    span = (float(headline.alarm.start), float(headline.alarm.end))
    spans = {"alarm": [span], "ground truth": truth_spans}
    figures = sensor_figures(view, views.times(headline.group, t), spans, [span], channels=[headline.deviation.channel])
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
