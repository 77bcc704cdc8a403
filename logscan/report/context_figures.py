"""The report's context figures: mode / set-point bands on the shared time axis, and the 2-D path
with the incidents marked on it (from `logscan.report.run_context.RunContext`, already decimated)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from logscan.report.context import message_text
from logscan.report.flight_modes import has_names, mode_name
from logscan.report.plotly_json import TIME_AXIS, plain_json, plot_text, spec_json
from logscan.report.run_context import estimated_path
from logscan.results import Incident
from logscan.timebase.clock import Clock

MAX_BAND_VALUES = 12  # a mode with more distinct values is a set-point: drawn as a line only
MAX_MARKED_INCIDENTS = 50
MODE_HEIGHT, PATH_HEIGHT = 270, 460
BAND_FILLS = [
    "rgba(31,119,180,0.14)", "rgba(255,127,14,0.16)", "rgba(44,160,44,0.14)", "rgba(148,103,189,0.14)",
    "rgba(140,86,75,0.14)", "rgba(227,119,194,0.14)", "rgba(127,127,127,0.14)", "rgba(188,189,34,0.16)",
    "rgba(23,190,207,0.14)", "rgba(57,59,121,0.14)", "rgba(99,121,57,0.14)", "rgba(214,39,40,0.12)",
]  # fmt: skip
INCIDENT_COLOUR = "#d62728"

_BASE_LAYOUT = {
    "hovermode": "closest",
    "plot_bgcolor": "white",
    "paper_bgcolor": "white",
    "template": {},
    "legend": {"orientation": "h", "y": -0.3, "yanchor": "top"},
}


def _spec(spec: dict, data: list[dict], layout: dict, clock: Clock | None = None, validated: bool = True) -> dict:
    """``spec`` with its figure JSON (its time axis in ``clock``) and what it costs in the report's
    point budget: its size in (x, y) float32 pairs as base64 (32 bytes per 3 points), so the page
    stays the same size. ``validated``: through plotly's Figure (`spec_json`), else written as it
    is (`plain_json`: no NaN outside numpy arrays)."""
    text = spec_json(data, layout, clock) if validated else plain_json(data, layout, clock)
    return {**spec, "json": text, "points": len(text) * 3 // 32}


def _band_trace(name: str, spans: list[tuple[float, float]], fill: str) -> dict:
    """Spans as a step area on the hidden overlay axis y2 (0..1 spans the plot): 2 points each."""
    x = np.asarray(spans, dtype=np.float64).reshape(-1)
    y = np.tile(np.array([1.0, 0.0]), len(spans))
    return {
        "type": "scatter", "name": plot_text(name), "x": x.astype(np.float32), "y": y.astype(np.float32),
        "yaxis": "y2", "mode": "lines", "line": {"width": 0, "shape": "hv"}, "fill": "tozeroy",
        "fillcolor": fill, "hoverinfo": "skip",
    }  # fmt: skip


def _time_row_layout(title: str, yaxis: dict, t_span: tuple[float, float] | None = None) -> dict:
    """The layout of a context figure on the shared time axis (the mode, the autopilot's messages
    and states): margins as the detector figures', so the time axes align."""
    return {
        **_BASE_LAYOUT,
        "title": {"text": title, "font": {"size": 14}},
        "height": MODE_HEIGHT,
        "margin": {"l": 70, "r": 20, "t": 40, "b": 100},
        "legend": {"orientation": "h", "y": -0.6, "yanchor": "top"},
        "xaxis": {**TIME_AXIS, **({"range": list(t_span)} if t_span else {})},
        "yaxis": yaxis,
    }


def _time_row_spec(fig_id: str, title: str, caption: str) -> dict:
    return {"id": fig_id, "title": title, "caption": caption, "timeseries": True, "height": MODE_HEIGHT}


def time_row(spec: dict, data: list[dict], layout: dict) -> dict:
    """A figure on the shared time axis before it is serialised: ``{"spec", "data", "layout"}``, drawn
    alone (`row_figure`) or as a row of the Context section's one figure (`logscan.report.context_stack`)."""
    return {"spec": spec, "data": data, "layout": layout}


def row_figure(row: dict, clock: Clock | None = None) -> dict:
    """A `time_row` as a figure of its own (serialised, its time axis in ``clock``)."""
    return _spec(row["spec"], row["data"], row["layout"], clock)


def _value_text(value: float) -> str:
    return f"{value:g}"


def _mode_yaxis(channel: str, values: list[float], named: bool) -> dict:
    """The mode figure's y axis: a row per named value (named by `_mode_notes`), else the values as
    numbers; room at the top for the message markers."""
    if named:
        return {"tickvals": list(range(len(values))), "showticklabels": False, "range": [-0.5, len(values) - 0.05],
                "gridcolor": "#eee", "zeroline": False, "fixedrange": True}  # fmt: skip
    return {"title": {"text": plot_text(channel)}, "gridcolor": "#eee", "exponentformat": "e"}


def _mode_notes(channel: str, values: list[float], labels: Mapping[float, str] | None = None) -> list[dict]:
    """Each named value's name at its row, inside the plot's left edge (tick labels would widen the
    margin, and the time axis would no longer line up with the other figures')."""
    return [
        {"text": plot_text(mode_name(channel, v, labels)), "xref": "paper", "x": 0.002, "xanchor": "left", "yref": "y",
         "y": i, "yanchor": "bottom", "showarrow": False, "font": {"size": 11, "color": "#333"}}
        for i, v in enumerate(values)
    ]  # fmt: skip


def _names_from(mode) -> str:
    """Where the mode's names come from, for its caption."""
    if mode.labels:
        return " (its values named by the profile's [mode] labels)"
    return " (PX4's flight modes named from its VehicleStatus.msg)"


def _mode_rows(value: np.ndarray, values: list[float]) -> np.ndarray:
    """Each sample's row: the index of its value in ``values`` (NaN where undefined)."""
    rows = np.full(value.shape, np.nan)
    for i, v in enumerate(values):
        rows[value == v] = i
    return rows


_MESSAGE_Y = 0.94  # the message markers' height on the overlay axis (0..1 spans the plot): along its top


def _message_marks(messages) -> list[dict]:
    """Every message the autopilot logged as a marker along the plot's top (on the overlay axis),
    coloured by level, its level and text on hover."""
    if not messages:
        return []
    colours = [_LEVEL_COLOURS.get(m.level, "#1f77b4") for m in messages]
    return [{
        "type": "scatter", "name": "logged messages", "x": np.array([m.t for m in messages], dtype=np.float32),
        "y": np.full(len(messages), _MESSAGE_Y, dtype=np.float32), "yaxis": "y2", "mode": "markers",
        "marker": {"symbol": "triangle-down", "size": 9, "color": colours, "line": {"color": "white", "width": 1}},
        "text": [plot_text(f"{m.level.lower()}: {message_text(m.text[:200])}") for m in messages],
        "hovertemplate": "%{text}<extra></extra>",
    }]  # fmt: skip


def mode_figure(mode, clock: Clock | None = None, messages=(), t_span: tuple[float, float] | None = None) -> dict:
    """`mode_row` as a figure of its own."""
    return row_figure(mode_row(mode, messages, t_span), clock)


IN_WINDOW = " in the --start/--end window"  # what a window's context shows, as its coverage lines say


def mode_row(mode, messages=(), t_span: tuple[float, float] | None = None, where: str = "") -> dict:
    """The mode channel as a step line, shaded by value when it takes few values (each value named,
    one row each, when it has a name: `logscan.report.flight_modes`), and the autopilot's logged
    ``messages`` (`logscan.log.LoggedMessage`, any level) as markers along its top; its time axis
    spans ``t_span`` (the analysis grid's) when given, as the other context figures'. ``where``:
    `IN_WINDOW` when the messages are a window's."""
    name = plot_text(mode.channel)
    values = sorted({v for _, _, v in mode.intervals})
    banded = bool(mode.intervals) and len(values) <= MAX_BAND_VALUES
    named = banded and has_names(mode.channel, mode.labels)
    data = []
    if banded:
        for i, value in enumerate(values):
            spans = [(a, b) for a, b, v in mode.intervals if v == value]
            label = mode_name(mode.channel, value, mode.labels) if named else f"{mode.channel} = {_value_text(value)}"
            data.append(_band_trace(label, spans, BAND_FILLS[i % len(BAND_FILLS)]))
    y = _mode_rows(mode.value, values) if named else mode.value
    line = {
        "type": "scatter", "name": name, "x": mode.t.astype(np.float32), "y": y.astype(np.float32),
        "mode": "lines", "line": {"shape": "hv", "color": "#333", "width": 1.5},
        "hovertemplate": "%{y:.6g} from %{x:.3f} s",
    }  # fmt: skip
    if named:  # the mode's name on hover
        line["text"] = [plot_text(mode_name(mode.channel, float(v), mode.labels)) for v in mode.value]
        line["hovertemplate"] = "%{text} from %{x:.3f} s"
    data.append(line)
    data += _message_marks(messages)
    layout = _time_row_layout(f"mode: {name}", _mode_yaxis(mode.channel, values, named), t_span)
    if named:
        layout["annotations"] = _mode_notes(mode.channel, values, mode.labels)
    layout["yaxis2"] = {"overlaying": "y", "range": [0, 1], "visible": False, "fixedrange": True}
    caption = (
        f"The profile's mode channel {mode.channel} on the shared time axis"
        + (", shaded by value" if banded else f" ({mode.n_changes} changes: drawn as a line)")
        + (_names_from(mode) if named else "")
        + (
            f"; triangles along the top: the {len(messages)} message(s) the autopilot logged{where} "
            "(hover for the text)"
            if messages
            else ""
        )
        + ". Read an alarm against the mode it happened in."
    )
    return time_row(_time_row_spec("ctx-mode", f"mode: {mode.channel}", caption), data, layout)


def _incident_traces(path, incidents: Sequence[Incident], clock: Clock) -> list[dict]:
    """The path during each incident (red) and a marker where each began, numbered as in the table;
    each marker's customdata: the incident's span on the time axis (in ``clock``), to zoom to."""
    segments_x, segments_y, marks = [], [], []
    for number, incident in enumerate(incidents[:MAX_MARKED_INCIDENTS], 1):
        start, end = float(incident.start), float(incident.end)
        inside = (path.t > start) & (path.t < end)
        t_seg = np.concatenate([[start], path.t[inside], [end]])
        segments_x.append(np.append(np.interp(t_seg, path.t, path.x), np.nan))
        segments_y.append(np.append(np.interp(t_seg, path.t, path.y), np.nan))
        x0, y0 = np.interp(start, path.t, path.x), np.interp(start, path.t, path.y)
        hover = f"incident {number}: {plot_text(incident.headline_in(clock))}<br>click: zoom the time axis to it"
        marks.append((float(x0), float(y0), str(number), hover, [clock.axis_value(start), clock.axis_value(end)]))
    if not marks:
        return []
    x, y, label, hover, spans = (list(column) for column in zip(*marks))
    return [
        {"type": "scatter", "name": "during an incident", "x": np.concatenate(segments_x).astype(np.float32),
         "y": np.concatenate(segments_y).astype(np.float32), "mode": "lines",
         "line": {"color": INCIDENT_COLOUR, "width": 2.5}, "opacity": 0.75, "hoverinfo": "skip"},
        {"type": "scatter", "name": "incident start", "x": x, "y": y, "mode": "markers+text", "text": label,
         "textposition": "top right", "hovertext": hover, "hoverinfo": "text", "customdata": spans,
         "textfont": {"color": INCIDENT_COLOUR, "size": 14}, "cliponaxis": False,
         "marker": {"symbol": "x", "size": 14, "color": INCIDENT_COLOUR, "line": {"color": "white", "width": 1}}},
    ]  # fmt: skip


def _hover_times(clock: Clock, t: np.ndarray) -> np.ndarray:
    """The times a path's hover shows (to 0.1 s): float32 on a seconds clock (half float64's bytes,
    steps under 0.01 s up to 18 hours), float64 epoch milliseconds on a UTC clock."""
    values = clock.axis_values(t)
    return values if clock.utc else values.astype(np.float32)


def _fixes_trace(fixes, when: str, clock: Clock) -> dict:
    """The measured fixes as small dots under the filter's estimate."""
    return {
        "type": "scatter", "name": "fixes (measured)", "x": fixes.x.astype(np.float32), "y": fixes.y.astype(np.float32),
        "customdata": _hover_times(clock, fixes.t), "mode": "markers", "opacity": 0.6,
        "marker": {"size": 3, "color": "#9a9a9a"},
        "hovertemplate": f"fix (%{{x:.2f}}, %{{y:.2f}}) at {when}<extra></extra>",
    }  # fmt: skip


def path_figure(path, incidents: Sequence[Incident], clock: Clock | None = None, estimate=None) -> dict:
    """The 2-D path (equal axes), its start and end, and the incidents on it; times in ``clock``.
    With the filter's ``estimate`` of it (`logscan.report.run_context.estimated_path`) the estimate
    is the line and the measured fixes are dots beneath."""
    clock = clock or Clock()
    fixes, path = (path, estimate) if estimate is not None else (None, path)
    x_name, y_name = plot_text(path.channels[0]), plot_text(path.channels[1])
    # the hover's time: clock seconds, or the UTC time of day (customdata in epoch ms on a UTC clock)
    when = "%{customdata|%H:%M:%S.%L} UTC" if clock.utc else "%{customdata:.1f} s"
    data = [
        *([_fixes_trace(fixes, when, clock)] if fixes is not None else []),
        {"type": "scatter", "name": "the filter's estimate" if fixes is not None else "path",
         "x": path.x.astype(np.float32), "y": path.y.astype(np.float32),
         "customdata": _hover_times(clock, path.t), "mode": "lines",
         "line": {"color": "#1f77b4" if fixes is not None else "#7f7f7f", "width": 1.5 if fixes is not None else 1},
         "hovertemplate": f"(%{{x:.2f}}, %{{y:.2f}}) at {when}<extra></extra>"},
        {"type": "scatter", "name": "start / end", "x": [float(path.x[0]), float(path.x[-1])],
         "y": [float(path.y[0]), float(path.y[-1])], "mode": "markers", "hoverinfo": "text",
         "hovertext": ["start", "end"],
         "marker": {"symbol": ["circle", "square"], "size": 10, "color": ["#2ca02c", "#222"]}},
        *_incident_traces(path, incidents, clock),
    ]  # fmt: skip
    layout = {
        **_BASE_LAYOUT,
        "title": {"text": f"path: {plot_text(path.group)}", "font": {"size": 14}},
        "height": PATH_HEIGHT,
        "margin": {"l": 70, "r": 20, "t": 40, "b": 80},
        "xaxis": {"title": {"text": x_name}, "gridcolor": "#eee", "zeroline": False},
        "yaxis": {"title": {"text": y_name}, "gridcolor": "#eee", "zeroline": False, "scaleanchor": "x"},
    }
    caption = (
        f"Where the vehicle was: {path.channels[0]} against {path.channels[1]} (equal scales). "
        + (
            "Blue: the filter's estimate (its prediction at each update), grey dots: the measured fixes. "
            if fixes is not None
            else ""
        )
        + "Red: the path during an incident, x where it began (numbered as in the incident table; "
        "click one to zoom the time axis to it)."
    )
    spec = {"id": "ctx-path", "title": f"path: {path.group}", "caption": caption, "timeseries": False,
            "height": PATH_HEIGHT}  # fmt: skip
    # not plotly's validation (10 ms of a 1-hour log's page), nor its escaped "/" in every array's base64
    return _spec(spec, data, layout, validated=False)


_LEVEL_ROWS = {"WARNING": 0, "ERROR": 1, "CRITICAL": 2, "ALERT": 3, "EMERGENCY": 4}
_LEVEL_COLOURS = {"WARNING": "#e6a100", "ERROR": "#d62728", "CRITICAL": "#8c1c13", "ALERT": "#8c1c13",
                  "EMERGENCY": "#000000"}  # fmt: skip


def messages_figure(messages, t_span: tuple[float, float] | None = None, clock: Clock | None = None) -> dict:
    """`messages_row` as a figure of its own."""
    return row_figure(messages_row(messages, t_span), clock)


def messages_row(messages, t_span: tuple[float, float] | None = None, where: str = "") -> dict:
    """The autopilot's own warnings and errors as markers on the shared time axis, one row per
    level, the text on hover; ``where`` as `mode_row`'s."""
    data = []
    for level, row in _LEVEL_ROWS.items():
        chosen = [m for m in messages if m.level == level]
        if not chosen:
            continue
        data.append({
            "type": "scatter", "name": level.lower(), "x": np.array([m.t for m in chosen], dtype=np.float32),
            "y": np.full(len(chosen), row, dtype=np.float32), "mode": "markers",
            "marker": {"symbol": "diamond", "size": 9, "color": _LEVEL_COLOURS[level]},
            "text": [plot_text(m.text[:200]) for m in chosen], "hovertemplate": "%{x:.3f} s: %{text}",
        })  # fmt: skip
    rows = sorted({_LEVEL_ROWS[m.level] for m in messages})
    yaxis = {"tickvals": rows, "ticktext": [k.lower() for k, v in _LEVEL_ROWS.items() if v in rows],
             "range": [-0.5, max(rows) + 0.5], "fixedrange": True}  # fmt: skip
    layout = _time_row_layout("the autopilot's logged warnings and errors", yaxis, t_span)
    caption = (
        f"{len(messages)} message(s) of level warning and above the autopilot logged{where}, at their time "
        "on the shared axis (hover for the text). Read an alarm against what the autopilot itself said."
    )
    return time_row(_time_row_spec("ctx-messages", "autopilot messages", caption), data, layout)


_STATE_FILLS = {"armed": "rgba(44, 160, 44, 0.25)", "failsafe": "rgba(214, 39, 40, 0.35)"}


def states_figure(states: dict, t_span: tuple[float, float] | None = None, clock: Clock | None = None) -> dict:
    """`states_row` as a figure of its own."""
    return row_figure(states_row(states, t_span), clock)


def states_row(states: dict, t_span: tuple[float, float] | None = None) -> dict:
    """The autopilot's armed and failsafe intervals as bands on the shared time axis, one row each."""
    data = []
    names = list(states)
    for row, name in enumerate(names):
        spans = states[name]
        x, y = [], []
        for a, b in spans:  # a filled rectangle per interval on the state's row
            x += [a, a, b, b, None]
            y += [row - 0.4, row + 0.4, row + 0.4, row - 0.4, None]
        data.append({
            "type": "scatter", "name": name, "x": x, "y": y, "mode": "lines", "fill": "toself",
            "fillcolor": _STATE_FILLS.get(name, "rgba(127, 127, 127, 0.3)"), "line": {"width": 0},
            "hoverinfo": "name",
        })  # fmt: skip
    yaxis = {"tickvals": list(range(len(names))), "ticktext": names, "range": [-0.6, len(names) - 0.4],
             "fixedrange": True}  # fmt: skip
    layout = _time_row_layout("the autopilot's state", yaxis, t_span)
    summary = "; ".join(f"{name}: {len(spans)} interval(s)" for name, spans in states.items())
    caption = f"When the vehicle was armed and in failsafe, as its autopilot logged ({summary})."
    return time_row(_time_row_spec("ctx-states", "autopilot state", caption), data, layout)


def context_rows(context) -> list[dict]:
    """The run's `time_row`s: the mode when the profile has a mode channel, the autopilot's state and
    its warnings and errors when logged; [] for None."""
    if context is None:
        return []
    t_span = getattr(context, "t_span", None)
    where = IN_WINDOW if getattr(context, "window", None) is not None else ""
    rows = []
    if context.mode is not None:
        rows.append(mode_row(context.mode, getattr(context, "log_messages", ()), t_span, where))
    if getattr(context, "states", None):
        rows.append(states_row(context.states, t_span))
    if getattr(context, "messages", None):
        rows.append(messages_row(context.messages, t_span, where))
    return rows


def path_figures(
    context, incidents: Sequence[Incident], clock: Clock | None = None, innovations=None, t: np.ndarray | None = None
) -> list[dict]:
    """The path when a group measures position (the filter's estimate of it from ``innovations`` on
    the grid ``t``, when given), serialised (`_spec`); [] for None or no path."""
    if context is None or context.path is None:
        return []
    estimate = estimated_path(context.path, innovations, t) if t is not None else None
    return [path_figure(context.path, incidents, clock, estimate)]
