"""Figure specs as plotly JSON for an HTML page: one point budget, decimated traces, escaped text.

Traces are decimated (``logscan.report.decimate``: min/max per bucket, alarm edges and NaN gaps kept)
under one point budget per report, so a report stays a few hundred kilobytes plus plotly.js
whatever the log length. Every name shown in a figure (trace names, titles, axis titles) goes
through `plot_text`: plotly draws ``<a href>``, ``<b>``, ``<br>`` in them as markup, and names come
from logs and profiles. The JSON has every ``<``, ``>`` and ``&`` escaped, so it can sit inside a
``<script>`` element.

Time axes show the log's own clock (`logscan.timebase.clock`: PX4 boot time, UTC as a date axis, or time
since the log's start): figures are built in seconds since the log's time zero and `on_clock`, in
`spec_json`, moves every figure on TIME_AXIS to the clock, in one place.

Zooming to an incident or alarm (templates/report.js: its span with a margin of max(2 s, 50 %))
would show a long log's overview decimation, a few points per window; so a quarter of each
decimated trace's points is spent inside those windows (`focus_windows`), when they cover at most
a fifth of the log. A figure that opens zoomed (the headline's) spends three quarters of its points
(OPENED_SHARE) in the range it opens on instead, whatever the page's windows.
"""

from __future__ import annotations

import base64
import json

import numpy as np

from logscan.report.decimate import DEFAULT_MAX_POINTS, collapsed, decimate_indices, sorted_unique
from logscan.report.figures import Figure, grid_step, merge_spans
from logscan.timebase.clock import Clock

# plotted points per report, shared by all varying traces: a report with plotly.js shared stays under
# 300 KB (issue 29's budget). A point is two float32 as base64, 10.7 bytes: 18,000 points are 192 KB,
# and the rest of the page (tables, scripts, each trace's style) about 100 KB.
POINT_BUDGET = 18_000
MIN_POINTS_PER_TRACE = 400
MIN_POINTS_FLOOR = 100
_F4_MAX = float(np.finfo(np.float32).max)

TIME_TITLE = "time since log start (s)"  # the axis' title until `on_clock` names the log's clock
TIME_AXIS = {
    "title": {"text": TIME_TITLE},
    "gridcolor": "#eee",
    "zeroline": False,
    "exponentformat": "none",  # 20000 s, not "20k"
}
ZOOM_MARGIN_S, ZOOM_MARGIN_FRACTION = 2.0, 0.5  # as templates/report.js zooms to a row's span
INCIDENT_GAP_S = 1.0  # alarms this close form one incident (logscan.verdict.incidents.DEFAULT_GAP_S)
FOCUS_SHARE = 0.25  # of a decimated trace's points, spent inside the zoom windows
OPENED_SHARE = 0.75  # of a figure's that opens zoomed (the headline's), spent in the range it shows
MAX_FOCUS_FRACTION = 0.2  # no focus when the windows cover more of the log than this
ALARM_FILL = "rgba(214, 39, 40, 0.18)"
TRUTH_FILL = "rgba(31, 119, 180, 0.16)"
POSSIBLE_FILL = "rgba(255, 165, 0, 0.22)"  # "possible fault" warnings: orange, apart from alarms


def _defined_samples(t: np.ndarray, y: np.ndarray, keep: np.ndarray, steps: DefinedSteps | None = None) -> tuple:
    """The samples where ``y`` is defined, with one NaN where they are far apart in time.

    Statistics are NaN on steps where they are not evaluated (a 10 Hz group's NIS on a 100 Hz
    grid is NaN 9 steps in 10); drawn as is, such a line would be all gaps. So only defined
    samples are drawn, joined, except across a gap longer than 3x their typical spacing, where a
    NaN still breaks the line. ``keep`` (grid indices) is mapped onto the returned samples. The
    typical spacing is the samples' `grid_step` (the median of at most STEP_SAMPLE spacings spread
    evenly over the series: the median of all of a long log's cost more than the rest of its trace).
    Defined samples in one run (NaN only before and after it: a warm-up) are that part of the
    series, as a series defined everywhere is all of it: no step is missing inside it. ``steps``:
    the page's `DefinedSteps` on ``t`` (None: found here).
    """
    if y.size == 0 or not np.isnan(collapsed(y).min()):  # no NaN (the least value is NaN when one is): no mask
        return t, y, keep
    defined = ~np.isnan(y)
    idx, tc, breaks = steps.of(defined) if steps is not None else _steps_of(t, defined)
    if breaks is None:  # one run
        first, n_defined = int(idx[0]), idx.size
        kept = np.clip(keep, first, first + n_defined - 1) - first
        return t[first : first + n_defined], y[first : first + n_defined], sorted_unique(kept)
    yc = np.insert(y[idx], breaks, np.nan) if breaks.size else y[idx]
    kept = np.clip(np.searchsorted(tc, t[keep]), 0, max(tc.size - 1, 0)) if tc.size else keep[:0]
    return tc, yc, sorted_unique(kept)


def _steps_of(t: np.ndarray, defined: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(the steps where ``defined``, the times `_defined_samples` draws them at: a midpoint inserted
    where a gap breaks the line, where those breaks go in the steps' samples); breaks None when the
    steps are one run, no step missing between its ends."""
    idx = np.flatnonzero(defined)
    if idx.size and idx[-1] - idx[0] + 1 == idx.size:
        return idx, t[idx[0] : idx[-1] + 1], None
    tc, breaks = t[idx], np.zeros(0, dtype=np.int64)
    if tc.size >= 2:
        typical = grid_step(tc) or 0.0  # two samples or more: a float
        breaks = np.flatnonzero(np.diff(tc) > 3.0 * typical) + 1
        if breaks.size:
            tc = np.insert(tc, breaks, 0.5 * (tc[breaks - 1] + tc[breaks]))
    return idx, tc, breaks


class DefinedSteps:
    """The steps where the series drawn on one page's grid ``t`` are defined, found once per pattern
    of NaN: the statistics of one measurement group (a 10 Hz group's NIS, its CUSUMs and frozen-
    sensor checks, their thresholds) are NaN on the same steps, and finding those steps, their
    times and the gaps that break the line for each of them took a third of drawing the lines of a
    1-hour log's page."""

    def __init__(self, t: np.ndarray):
        self.t = t
        self._found: list[tuple[np.ndarray, tuple]] = []

    def of(self, defined: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """`_steps_of` ``defined`` (a mask over the grid)."""
        for mask, found in self._found:
            if np.array_equal(mask, defined):
                return found
        found = _steps_of(self.t, defined)
        self._found.append((defined, found))
        return found


def _display_values(y: np.ndarray) -> np.ndarray:
    """float32 values for the browser: inf -> NaN (a gap), finite values clipped to float32."""
    out = np.asarray(y, dtype=np.float64).copy()
    out[np.isinf(out)] = np.nan
    np.clip(out, -_F4_MAX, _F4_MAX, out=out)
    return out.astype(np.float32)


def plot_text(text: object) -> str:
    """``text`` as plotly shows it literally: ``&``, ``<`` and ``>`` as the entities plotly turns
    back into characters, never into links or formatting."""
    return str(text).replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def span_trace(name: str, spans: list, fill: str) -> dict:
    """A filled polygon per span on the hidden overlay axis y2 (0..1 covers the plot height)."""
    arr = np.asarray(spans, dtype=np.float64).reshape(-1, 2)
    x = np.column_stack([arr[:, 0], arr[:, 0], arr[:, 1], arr[:, 1], np.full(len(arr), np.nan)])
    y = np.tile(np.array([0.0, 1.0, 1.0, 0.0, np.nan]), (len(arr), 1))
    return {
        "type": "scatter",
        "name": plot_text(name),
        "legendgroup": plot_text(name),
        "x": x.ravel().astype(np.float32),
        "y": y.ravel().astype(np.float32),
        "yaxis": "y2",
        "mode": "lines",
        "line": {"width": 0},
        "fill": "toself",
        "fillcolor": fill,
        "hoverinfo": "skip",
        "showlegend": True,
    }


def allocate_points(figures: list[Figure], budget: int) -> dict[int, int]:
    """Points per varying trace (by id), proportional to weight, within [floor, DEFAULT_MAX]; the
    floor is MIN_POINTS_PER_TRACE, lowered (to MIN_POINTS_FLOOR at least) when that many traces at
    the floor would spend more than half the budget (the sensor figures of several groups); a
    trace's own ``max_points`` caps its share, floor or not. The floor's points come out of the
    budget: the traces above it share what the floored ones leave, so the page keeps to its budget
    (on top of it, the floor drew 12 % more points than the budget on a 1-hour log's incident page)."""
    varying = [tr for fig in figures for tr in fig.traces if tr.varying]
    floor = max(MIN_POINTS_FLOOR, min(MIN_POINTS_PER_TRACE, budget // max(2 * len(varying), 1)))
    floored: set[int] = set()
    while True:  # each round floors the traces whose share of what is left falls under the floor
        rest = [tr for tr in varying if id(tr) not in floored]
        left = budget - floor * len(floored)
        total_weight = sum(tr.weight for tr in rest) or 1.0
        under = [id(tr) for tr in rest if left * tr.weight / total_weight < floor]
        if not under:
            break
        floored.update(under)
    share = {id(tr): floor if id(tr) in floored else left * tr.weight / total_weight for tr in varying}
    return {id(tr): int(min(tr.max_points or DEFAULT_MAX_POINTS, share[id(tr)])) for tr in varying}


def focus_windows(figures: list[Figure], t: np.ndarray) -> np.ndarray:
    """(k, 2) sorted disjoint windows a click on an alarm or incident row zooms to: every figure's
    alarm spans and their groups, widened by the zoom margin; empty when they would cover more
    than MAX_FOCUS_FRACTION of the log (alarms everywhere: the overview is the view)."""
    return zoom_windows([span for fig in figures for span in fig.spans.get("alarm", [])], t)


def zoom_windows(spans: list, t: np.ndarray, whatever_they_cover: bool = False) -> np.ndarray:
    """`focus_windows` of these alarm spans (``whatever_they_cover``: however much of ``t`` they cover)."""
    if not spans or t.size < 2:
        return np.zeros((0, 2))
    spans += merge_spans(spans, 0.0, INCIDENT_GAP_S)
    arr = np.asarray(spans, dtype=np.float64).reshape(-1, 2)
    margin = np.maximum(ZOOM_MARGIN_S, ZOOM_MARGIN_FRACTION * (arr[:, 1] - arr[:, 0]))
    windows = np.asarray(merge_spans(np.column_stack([arr[:, 0] - margin, arr[:, 1] + margin]).tolist(), 0.0, 0.0))
    covered = float(np.sum(windows[:, 1] - windows[:, 0])) if windows.size else 0.0
    if covered > MAX_FOCUS_FRACTION * float(t[-1] - t[0]) and not whatever_they_cover:
        return np.zeros((0, 2))
    return windows.reshape(-1, 2)


def in_windows(x: np.ndarray, windows: np.ndarray) -> np.ndarray:
    """Mask of ``x`` inside any of the sorted disjoint ``windows``."""
    if windows.size == 0:
        return np.zeros(x.size, dtype=bool)
    i = np.searchsorted(windows[:, 0], x, side="right") - 1
    return (i >= 0) & (x <= windows[np.maximum(i, 0), 1])


def window_indices(x: np.ndarray, windows: np.ndarray, ascending: bool | None = None) -> np.ndarray:
    """Indices of ``x`` inside any of the sorted disjoint ``windows`` (`in_windows`' True places):
    for an ascending ``x`` (a trace's times) found from the windows' edges, a binary search per edge
    instead of one per sample (a 1-hour log's report asked 138 traces of 360,000 samples each).
    ``ascending``: whether ``x`` ascends, when the caller knows (None: checked here)."""
    if windows.size == 0:
        return np.zeros(0, dtype=np.int64)
    if ascending is None:
        ascending = ascends(x)
    if not ascending:  # unsorted, or NaN: sample by sample
        return np.flatnonzero(in_windows(x, windows))
    stop = np.searchsorted(x, windows[:, 1], side="right")
    first = np.searchsorted(x, windows[:, 0], side="left")
    first[1:] = np.maximum(first[1:], stop[:-1])  # windows that touch share no sample twice
    return np.concatenate([np.arange(a, b) for a, b in zip(first.tolist(), stop.tolist())] or [np.zeros(0, np.int64)])


def ascends(x: np.ndarray) -> bool:
    """True when every value of ``x`` is at least the one before it (no NaN among them)."""
    return x.size < 2 or bool(np.all(x[1:] >= x[:-1]))


def _decimated(
    x: np.ndarray,
    y: np.ndarray,
    keep: np.ndarray,
    max_points: int,
    windows: np.ndarray,
    ascending: bool | None,
    has_nan: bool | None,
    share: float = FOCUS_SHARE,
) -> np.ndarray:
    """Indices drawing ``y``: the whole under ``max_points``, ``share`` of them inside ``windows``
    (``ascending``: whether ``x`` ascends, ``has_nan``: whether ``y`` holds a NaN; None: not known)."""
    n_focus = int(max_points * share)
    focus = y.size > max_points and n_focus >= 16
    inside = window_indices(x, windows, ascending) if focus else np.zeros(0, dtype=np.int64)
    if inside.size <= n_focus:  # not decimated, or the windows hold few samples: drawn in full below
        overview = decimate_indices(y, max_points - inside.size, keep=keep, simplify_flat=True, has_nan=has_nan)
        return sorted_unique(overview, inside)
    overview = decimate_indices(y, max_points - n_focus, keep=keep, simplify_flat=True, has_nan=has_nan)
    in_focus = decimate_indices(y[inside], n_focus, simplify_flat=True, has_nan=False if has_nan is False else None)
    return sorted_unique(overview, inside[in_focus])


def trace_data(
    fig: Figure,
    t: np.ndarray,
    points: dict[int, int],
    windows: np.ndarray | None = None,
    steps: DefinedSteps | None = None,
    share: float = FOCUS_SHARE,
) -> list[dict]:
    """The plotly traces of one figure: shaded spans, horizontal lines, decimated lines (``steps``:
    the page's `DefinedSteps` on ``t``, None: found for each line), ``share`` of each one's points
    inside the ``windows``."""
    windows = np.zeros((0, 2)) if windows is None else windows
    data: list[dict] = []
    span_fills = {"alarm": ALARM_FILL, "ground truth": TRUTH_FILL, "possible fault": POSSIBLE_FILL}
    for name, spans in fig.spans.items():
        if spans:
            data.append(span_trace(name, spans, span_fills.get(name, ALARM_FILL)))
    t0, t1 = (float(t[0]), float(t[-1])) if t.size else (0.0, 0.0)
    for y_value, name in fig.hlines:
        data.append({
            "type": "scatter", "name": plot_text(name), "x": [t0, t1], "y": [y_value, y_value],
            "mode": "lines", "line": {"color": "#d62728", "dash": "dash", "width": 1},
        })  # fmt: skip
    # whether t ascends, checked once: a trace on the grid draws some of its times, which then ascend too
    grid_ascends = ascends(t) if windows.size and any(trace.t is None for trace in fig.traces) else None
    for trace in fig.traces:
        max_points = points.get(id(trace), DEFAULT_MAX_POINTS)
        x, y, keep = (_defined_samples(t, trace.y, trace.keep, steps) if trace.t is None else
                      _defined_samples(trace.t, trace.y, trace.keep))  # fmt: skip
        no_nan = False if y is trace.y else None  # the series itself: it was found to hold no NaN
        idx = _decimated(x, y, keep, max_points, windows, grid_ascends if trace.t is None else None, no_nan, share)
        data.append({
            "type": "scatter",
            "name": plot_text(trace.name),
            "x": x[idx].astype(np.float32),
            "y": _display_values(y[idx]),
            "mode": "lines",
            "hovertemplate": "%{y:.6g} at %{x:.3f} s",
            **trace.style,
        })  # fmt: skip
    return data


def figure_json(
    fig: Figure,
    t: np.ndarray,
    points: dict[int, int],
    windows: np.ndarray | None = None,
    clock: Clock | None = None,
    steps: DefinedSteps | None = None,
) -> str:
    """One figure as escaped plotly JSON, its traces decimated to ``points`` (trace id -> points),
    part of them inside the zoom ``windows`` (`focus_windows`), or, for a figure shown zoomed
    (``x_range``: the headline's), most inside the range it opens on, whatever the page's windows; its
    time axis in ``clock`` (``steps``: as `trace_data`'s)."""
    share = FOCUS_SHARE
    if fig.x_range is not None:  # its first view: drawn there at full rate, not at the log's decimation
        windows, share = np.asarray([fig.x_range], dtype=np.float64), OPENED_SHARE
    title = {"text": plot_text(fig.title), "font": {"size": 14}}
    if fig.subtitle:  # the statistic in plain words, a smaller line under its name
        title["subtitle"] = {"text": plot_text(fig.subtitle), "font": {"size": 12, "color": "#555"}}
    layout = {
        "title": title,
        "height": 380 if fig.subtitle else 360,
        "margin": {"l": 70, "r": 20, "t": 60 if fig.subtitle else 40, "b": 80},
        "xaxis": TIME_AXIS if fig.x_range is None else {**TIME_AXIS, "range": list(fig.x_range)},
        "yaxis": {
            "title": {"text": plot_text(fig.y_title)},
            "gridcolor": "#eee",
            "exponentformat": "e",  # 1e-04, never SI prefixes ("100µ") on ratios and statistics
            "type": "log" if fig.log_y else "linear",
            **({"range": list(fig.y_range)} if fig.y_range else {}),
        },
        "yaxis2": {"overlaying": "y", "range": [0, 1], "visible": False, "fixedrange": True},
        "legend": {"orientation": "h", "y": -0.22, "yanchor": "top"},
        "hovermode": "closest",
        "plot_bgcolor": "white",
        "paper_bgcolor": "white",
        "template": {},
    }
    return plain_json(trace_data(fig, t, points, windows, steps, share), layout, clock)  # plotly's validation: 15 ms


# hover texts of times in seconds, as the figure builders write them, and as a UTC date axis shows them
_HOVER_SECONDS, _HOVER_UTC = "%{x:.3f} s", "%{x|%H:%M:%S.%L} UTC"


def is_time_axis(layout: dict) -> bool:
    """True for a figure on the report's shared time axis (its x axis built from TIME_AXIS)."""
    return (layout.get("xaxis") or {}).get("title") == TIME_AXIS["title"]


def on_clock(data: list[dict], layout: dict, clock: Clock) -> tuple[list[dict], dict]:
    """A time-axis figure (`is_time_axis`) moved to ``clock``: every trace's x and the axis range
    as the clock plots them (`Clock.axis_values`), the axis titled with the clock's name, a date
    axis for UTC; other figures unchanged."""
    if not is_time_axis(layout) or clock.relative:
        return data, layout
    moved = []
    for trace in data:
        trace = dict(trace)
        if trace.get("x") is not None:
            trace["x"] = clock.axis_values(np.asarray(trace["x"], dtype=np.float64))
        if clock.utc and isinstance(trace.get("hovertemplate"), str):
            trace["hovertemplate"] = trace["hovertemplate"].replace(_HOVER_SECONDS, _HOVER_UTC)
        moved.append(trace)
    axis = {**layout["xaxis"], "title": {"text": plot_text(clock.axis_title())}}
    if clock.utc:
        axis |= {"type": "date", "hoverformat": "%H:%M:%S.%L"}
    if axis.get("range") is not None:
        axis["range"] = [clock.axis_value(value) for value in axis["range"]]
    return moved, {**layout, "xaxis": axis}


def spec_json(data: list[dict], layout: dict, clock: Clock | None = None) -> str:
    """Plotly traces and layout as escaped figure JSON (numpy arrays as typed arrays); a figure on
    the time axis in ``clock`` (`on_clock`)."""
    import plotly.graph_objects as go

    if clock is not None:
        data, layout = on_clock(data, layout, clock)
    figure = go.Figure(data=data, layout=layout, skip_invalid=False)
    return escape_json(figure.to_json(validate=False, remove_uids=True))


def plain_json(data: list[dict], layout: dict, clock: Clock | None = None) -> str:
    """As `spec_json`, without building plotly's validated Figure: a detector section's layout of
    many axes, legends and annotations takes plotly ~70 ms to validate, more than drawing its data.
    numpy arrays become plotly.js typed arrays, as plotly writes them."""
    if clock is not None:
        data, layout = on_clock(data, layout, clock)
    traces = [{k: typed_array(v) if isinstance(v, np.ndarray) else v for k, v in trace.items()} for trace in data]
    text = json.dumps({"data": traces, "layout": layout}, separators=(",", ":"), default=_scalar, allow_nan=False)
    return escape_json(text)


def typed_array(values: np.ndarray) -> object:
    """A numpy array as the plotly.js typed array plotly writes (`to_typed_array_spec`), for every
    numeric dtype plotly.js has, 64-bit integers narrowed as plotly narrows them: plotly's own way
    imports its validators and narwhals (0.15 s of every run) and copies each array."""
    if values.size and values.dtype.kind in "iuf" and values.dtype.isnative:
        narrowed = _narrowed(values) if values.dtype.itemsize == 8 and values.dtype.kind in "iu" else values
        short = _TYPED_ARRAY_CODES.get(narrowed.dtype.name) if narrowed is not None else None
        if narrowed is not None and short is not None:
            spec = {"dtype": short, "bdata": base64.b64encode(np.ascontiguousarray(narrowed).data).decode("ascii")}
            if narrowed.ndim > 1:
                spec["shape"] = str(narrowed.shape)[1:-1]
            return spec
    from _plotly_utils.utils import to_typed_array_spec  # what plotly.js has no typed array for

    return to_typed_array_spec(values)


# numpy's dtype names to plotly.js's typed arrays (`_plotly_utils.utils.plotlyjsShortTypes`)
_TYPED_ARRAY_CODES = {
    "int8": "i1",
    "uint8": "u1",
    "int16": "i2",
    "uint16": "u2",
    "int32": "i4",
    "uint32": "u4",
    "float32": "f4",
    "float64": "f8",
}


def _narrowed(values: np.ndarray) -> np.ndarray | None:
    """A 64-bit integer array in the narrowest integer type of its sign that holds it, as plotly
    narrows it (plotly.js has no 64-bit integers); None when none does."""
    low, high = int(values.min()), int(values.max())
    for name in ("int8", "int16", "int32") if values.dtype.kind == "i" else ("uint8", "uint16", "uint32"):
        info = np.iinfo(name)
        if info.min <= low and high <= info.max:
            return values.astype(name)
    return None


def _scalar(value: object) -> object:
    """numpy values json cannot write: scalars as numbers, arrays nested below a trace's top level
    (a marker's colours, a hover's customdata) as plotly.js typed arrays, as at the top level."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        spec = typed_array(value)  # strings and objects come back as they went in
        return value.tolist() if isinstance(spec, np.ndarray) else spec
    raise TypeError(f"not JSON: {type(value).__name__}")


def escape_json(text: str) -> str:
    """JSON safe inside an HTML <script> element: no ``<``, ``>``, ``&`` or line separators."""
    return (
        text.replace("<", "\\u003c")
        .replace(">", "\\u003e")
        .replace("&", "\\u0026")
        .replace("\u2028", "\\u2028")
        .replace("\u2029", "\\u2029")
    )
