"""One figure per detector section: its statistics, its sensors and its extras as rows on one time axis.

A section used to be a column of separate figures (cusum's 12 axes were 12 figures, each 360 px,
each zoomed by its own `relayout`). Here they are the rows of one plotly figure, as
``make_subplots(rows=n, shared_xaxes=True)`` lays them out but with every row on the same x axis
``x`` (plotly's shared axes are several axes linked by ``matches``; one axis lets
``hoversubplots: "axis"`` put one hover and one spike line across every row): one crosshair over
the rows, one zoom for the section, one `relayout` to follow the page's time axis.

Each row keeps what its `Figure` had: its own y axis (title, log or linear, initial range), its
alarm spans on a hidden overlay axis (0..1 covers the row), its horizontal lines, and above it a
band with its title and its own legend (plotly's ``legend2``, ``legend3``..., one horizontal line
under the title). Not a legend beside the rows: PX4's long channel names widened that margin and
squeezed every row's plot (a name longer than `LEGEND_NAME_CHARS` is shortened in the legend; the
hover gives it whole). The ground truth is the same for every row, so it is shaded once across
the whole figure (layout shapes), not once per row. A row whose statistic is constant all log long
and never alarmed (an indicator that stayed 0) is left out and named in the section's caption
(`fold_flat`).
"""

from __future__ import annotations

import html
from collections.abc import Sequence

import numpy as np

from logscan.report.decimate import collapsed
from logscan.report.figures import Figure
from logscan.report.plotly_json import (
    TIME_AXIS,
    TRUTH_FILL,
    DefinedSteps,
    allocate_points,
    figure_json,
    focus_windows,
    plain_json,
    plot_text,
    trace_data,
)

ROW_PX = 190  # a row that alarmed, or a sensor's measured vs predicted
QUIET_ROW_PX = 120  # a row without an alarm span
TITLE_PX, LEGEND_LINE_PX = 20, 20  # above each row: its title (and the statistic's words), then its legend
BAND_PX = TITLE_PX + LEGEND_LINE_PX
TOP_PX, BOTTOM_PX = 10, 60  # the figure's margins: the bottom one holds the time axis' title
RIGHT_PX = 20  # nothing beside the rows: the plots take the page's width
DOMAIN_DECIMALS = 6  # of a row's domain: pixel-exact up to 10,000 px (`row_domains`)
LEGEND_NAME_CHARS = 40  # a longer trace name is shortened in its legend (about 240 px at 10 px type)
SPIKES = {
    "showspikes": True,
    "spikemode": "across",  # one vertical line through every row
    "spikesnap": "cursor",
    "spikethickness": 1,
    "spikedash": "solid",
    "spikecolor": "#555",
}
# what a detector section's traces, row titles and y axes have unless they say otherwise, written
# once in its figure's template (plotly.js applies it to each of them) instead of on each: a section
# has a hundred traces and forty rows, and these were a tenth of a 1-hour log's page
TRACE_DEFAULTS = {"mode": "lines", "hovertemplate": "%{y:.4g}"}  # the unified hover gives the time once, on top
TITLE_DEFAULTS = {"xref": "paper", "yref": "paper", "x": 0, "yshift": LEGEND_LINE_PX, "xanchor": "left",
                  "yanchor": "bottom", "showarrow": False, "font": {"size": 12}}  # fmt: skip
AXIS_DEFAULTS = {"anchor": "x", "gridcolor": "#eee", "exponentformat": "e"}  # 1e-04, never SI prefixes ("100µ")
SECTION_TEMPLATE = {"data": {"scatter": [TRACE_DEFAULTS]}, "layout": {"annotationdefaults": TITLE_DEFAULTS,
                                                                      "yaxis": AXIS_DEFAULTS}}  # fmt: skip


def is_flat(fig: Figure) -> bool:
    """A statistic-with-band row (its first trace is the statistic it is titled by) whose statistic
    holds one value all log long and which has no alarm span."""
    if fig.spans.get("alarm") or not fig.traces or fig.traces[0].name != fig.y_title:
        return False
    y = collapsed(np.asarray(fig.traces[0].y))
    # one value: its finite samples' least and greatest are equal (none: flat too); fmin and fmax
    # skip NaN, so finite results are those (a masked min and max took 100 times as long)
    lo, hi = (float(np.fmin.reduce(y)), float(np.fmax.reduce(y))) if y.size else (np.inf, -np.inf)
    if not (np.isfinite(lo) and np.isfinite(hi)):  # every sample NaN, or infinities among them
        finite = np.isfinite(y)
        lo, hi = np.min(y, where=finite, initial=np.inf), np.max(y, where=finite, initial=-np.inf)
    return bool(lo >= hi)


def fold_flat(rows: Sequence[Figure]) -> tuple[list[Figure], list[str]]:
    """(the rows to draw, the names of the flat ones left out); a section keeps one row at least."""
    flat = [fig for fig in rows if is_flat(fig)]
    if len(flat) == len(rows):
        flat = flat[1:]
    kept = [fig for fig in rows if not any(fig is f for f in flat)]
    return kept, [fig.y_title for fig in flat]


def _row_heights(rows: Sequence[Figure]) -> list[int]:
    return [ROW_PX if fig.spans.get("alarm") or fig.x_range or "measured vs predicted" in fig.title else QUIET_ROW_PX
            for fig in rows]  # fmt: skip


def row_band(layout: dict, r: int, domain: list[float], title: str, subtitle: str = "") -> str:
    """Row ``r``'s band above its ``domain`` (paper fractions): its title and, under it, its legend on
    one horizontal line (scrolled, never wrapped into the row above); the legend's key."""
    legend = "legend" if r == 1 else f"legend{r}"
    layout[legend] = {"orientation": "h", "x": 0, "xanchor": "left", "y": domain[1], "yanchor": "bottom",
                      "font": {"size": 10}, "maxheight": LEGEND_LINE_PX, "tracegroupgap": 2}  # fmt: skip
    words = f"  <span style='font-size:11px;color:#555'>{plot_text(subtitle)}</span>" if subtitle else ""
    layout["annotations"].append({"text": f"<b>{plot_text(title)}</b>{words}", **TITLE_DEFAULTS, "y": domain[1]})
    return legend


def base_layout(plot_px: int) -> dict:
    """A stacked figure's layout before its rows: one hover and one spike line across every row."""
    return {
        "height": plot_px + TOP_PX + BOTTOM_PX,
        "margin": {"l": 70, "r": RIGHT_PX, "t": TOP_PX, "b": BOTTOM_PX},
        "hovermode": "x unified",
        "hoversubplots": "axis",  # hovering one row hovers every row at that time
        "plot_bgcolor": "white",
        "paper_bgcolor": "white",
        "template": {},
        "annotations": [],
    }


def row_domains(heights: Sequence[int]) -> tuple[int, list[list[float]]]:
    """(the plot's height in px, each row's domain): rows top to bottom, a band above each. A
    domain's ends are whole pixels of the plot, as fractions of it to 6 decimals (a hundredth of
    a pixel of a 10,000 px figure; 17 digits each were 2 KB of a 1-hour log's page)."""
    plot_px = sum(heights) + BAND_PX * len(heights)
    top, domains = plot_px, []
    for height in heights:
        top -= BAND_PX
        domains.append([round((top - height) / plot_px, DOMAIN_DECIMALS), round(top / plot_px, DOMAIN_DECIMALS)])
        top -= height
    return plot_px, domains


def stacked_layout(rows: Sequence[Figure]) -> tuple[dict, list[int]]:
    """The layout of ``rows`` stacked on one time axis, and each row's y-axis number (1, 2, ...)."""
    plot_px, domains = row_domains(_row_heights(rows))
    layout = base_layout(plot_px)
    n = len(rows)
    for r, (fig, domain) in enumerate(zip(rows, domains), 1):
        axis = "yaxis" if r == 1 else f"yaxis{r}"
        layout[axis] = {  # and AXIS_DEFAULTS, from the template
            "domain": domain,
            "title": {"text": plot_text(fig.y_title), "font": {"size": 11}},
            "type": "log" if fig.log_y else "linear",
            **({"range": list(fig.y_range)} if fig.y_range else {}),
        }
        layout[f"yaxis{n + r}"] = {"overlaying": f"y{'' if r == 1 else r}", "domain": domain, "range": [0, 1],
                                   "visible": False, "fixedrange": True}  # fmt: skip
        row_band(layout, r, domain, fig.title, fig.subtitle)
    layout["annotations"] = [_without(note, TITLE_DEFAULTS) for note in layout["annotations"]]
    layout["xaxis"] = {**TIME_AXIS, "anchor": f"y{'' if n == 1 else n}", **SPIKES}
    layout["template"] = SECTION_TEMPLATE
    return layout, list(range(1, n + 1))


def _without(item: dict, defaults: dict) -> dict:
    """``item`` without the keys whose values are the ``defaults`` (a template gives them)."""
    return {key: value for key, value in item.items() if key not in defaults or defaults[key] != value}


def legend_name(trace: dict) -> None:
    """A trace whose name is longer than LEGEND_NAME_CHARS keeps its head and tail in the legend
    and its whole name in the hover."""
    name = str(trace.get("name", ""))
    shown = html.unescape(name)  # as plotly shows it (`plot_text`): its length on the page
    if len(shown) <= LEGEND_NAME_CHARS:
        return
    keep = (LEGEND_NAME_CHARS - 1) // 2
    trace["name"] = plot_text(f"{shown[:keep]}…{shown[-keep:]}")
    if "hovertemplate" in trace:
        trace["hovertemplate"] = f"{name}: {trace['hovertemplate']}<extra></extra>"


def on_row(trace: dict, axes: dict[str, str], legend: str) -> dict:
    """``trace`` on its row: its y axis (``y``) or the row's overlay (``y2``) as ``axes`` name them,
    its row's legend, a long name shortened there (`legend_name`); plotly's defaults left out
    (scatter, the x axis ``x``, the first legend): a section has a hundred traces."""
    trace = {key: value for key, value in trace.items() if not (key == "type" and value == "scatter")}
    trace["yaxis"] = axes[trace.get("yaxis", "y")]
    if legend != "legend":
        trace["legend"] = legend
    legend_name(trace)
    return trace


def truth_shapes(rows: Sequence[Figure], clock) -> list[dict]:
    """The ground-truth spans (the same on every row) shaded once across the whole figure."""
    spans = next((fig.spans.get("ground truth") for fig in rows if fig.spans.get("ground truth")), None) or []
    at = (lambda v: clock.axis_value(v)) if clock is not None else float
    return [{"type": "rect", "xref": "x", "yref": "paper", "x0": at(a), "x1": at(b), "y0": 0, "y1": 1,
             "fillcolor": TRUTH_FILL, "line": {"width": 0}, "layer": "below"} for a, b in spans]  # fmt: skip


def stacked_json(
    rows: Sequence[Figure],
    t: np.ndarray,
    points: dict[int, int],
    windows: np.ndarray,
    clock,
    steps: DefinedSteps | None = None,
) -> str:
    """The rows as one figure's escaped plotly JSON, traces decimated to ``points`` (trace id ->
    points) as `logscan.report.plotly_json.figure_json` does for one figure (``steps``: the page's
    `DefinedSteps` on ``t``)."""
    layout, numbers = stacked_layout(rows)
    layout["shapes"] = truth_shapes(rows, clock)
    n = len(rows)
    data: list[dict] = []
    for fig, r in zip(rows, numbers):
        axes = {"y": f"y{'' if r == 1 else r}", "y2": f"y{n + r}"}
        legend = "legend" if r == 1 else f"legend{r}"
        for trace in trace_data(fig, t, points, windows, steps):
            if trace.get("name") == "ground truth" and layout["shapes"]:
                continue  # shaded once across the figure
            if "hovertemplate" in trace:  # the unified hover box gives the time once, on top
                trace["hovertemplate"] = TRACE_DEFAULTS["hovertemplate"]
            trace = on_row(trace, axes, legend)
            if "hovertemplate" not in trace and trace.get("hoverinfo") != "skip":
                trace["hovertemplate"] = ""  # plotly's own hover text, not the template's
            data.append(_without(trace, TRACE_DEFAULTS))
    return plain_json(data, layout, clock)


def row_captions(rows: Sequence[Figure], flat: Sequence[str]) -> list[str]:
    """What each row shows, once per distinct caption, and the rows left out as flat."""
    captions: list[str] = []
    for fig in rows:
        if fig.caption and fig.caption not in captions:
            captions.append(fig.caption)
    if flat:
        captions.append(f"Not drawn, constant all log long and never alarmed: {', '.join(flat)}.")
    if any(fig.spans.get("ground truth") for fig in rows):
        captions.append("Shaded blue across every row: the ground-truth faults.")
    return captions


def figures_json(
    figures: Sequence[tuple[str, Figure | list[Figure]]],
    t: np.ndarray,
    point_budget: int,
    extra: Sequence[dict] = (),
    clock=None,
) -> str:
    """``[{"id": ..., "figure": ...}, ...]`` for (element id, figure or rows) pairs, under one point
    budget (rows: one stacked figure, `stacked_json`), then the ``extra`` figures already serialised
    (``{"id", "json", "points"}``, e.g. `logscan.report.context_figures`), whose points come out of
    the same budget. Time axes in ``clock`` (None: seconds since the log's start)."""
    budget = max(point_budget - sum(int(spec.get("points", 0)) for spec in extra), 0)
    every = [fig for _, item in figures for fig in (item if isinstance(item, list) else [item])]
    points = allocate_points(every, budget)
    windows = focus_windows(every, t)
    steps = DefinedSteps(t)  # the series' defined steps, found once per pattern for the whole page
    parts = []
    for fig_id, item in figures:
        spec = stacked_json(item, t, points, windows, clock, steps) if isinstance(item, list) else (
            figure_json(item, t, points, windows, clock, steps))  # fmt: skip
        parts.append(f'{{"id":"{fig_id}","figure":{spec}}}')
    parts += [f'{{"id":"{spec["id"]}","figure":{spec["json"]}}}' for spec in extra]
    return "[" + ",".join(parts) + "]"
