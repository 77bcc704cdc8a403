"""One figure per detector section: its statistics, its sensors and its extras as rows on one time axis.

A section used to be a column of separate figures (cusum's 12 axes were 12 figures, each 360 px,
each zoomed by its own `relayout`). Here they are the rows of one plotly figure, as
``make_subplots(rows=n, shared_xaxes=True)`` lays them out but with every row on the same x axis
``x`` (plotly's shared axes are several axes linked by ``matches``; one axis lets
``hoversubplots: "axis"`` put one hover and one spike line across every row): one crosshair over
the rows, one zoom for the section, one `relayout` to follow the page's time axis.

Each row keeps what its `Figure` had: its own y axis (title, log or linear, initial range), its
shaded spans on a hidden overlay axis (0..1 covers the row), its horizontal lines, its own legend
beside it (plotly's ``legend2``, ``legend3``...), and its title as an annotation above it. A row
whose statistic is constant all log long and never alarmed (an indicator that stayed 0) is left
out and named in the section's caption (`fold_flat`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from logscan.report.figures import Figure
from logscan.report.plotly_json import (
    TIME_AXIS,
    allocate_points,
    figure_json,
    focus_windows,
    plain_json,
    plot_text,
    trace_data,
)

ROW_PX = 190  # a row that alarmed, or a sensor's measured vs predicted
QUIET_ROW_PX = 120  # a row without an alarm span
TITLE_PX = 34  # above each row: its title (and the statistic's words)
TOP_PX, BOTTOM_PX = 10, 60  # the figure's margins: the bottom one holds the time axis' title
LEGEND_PX = 210  # right margin: each row's legend beside it
SPIKES = {
    "showspikes": True,
    "spikemode": "across",  # one vertical line through every row
    "spikesnap": "cursor",
    "spikethickness": 1,
    "spikedash": "solid",
    "spikecolor": "#555",
}


def is_flat(fig: Figure) -> bool:
    """A statistic-with-band row (its first trace is the statistic it is titled by) whose statistic
    holds one value all log long and which has no alarm span."""
    if fig.spans.get("alarm") or not fig.traces or fig.traces[0].name != fig.y_title:
        return False
    y = np.asarray(fig.traces[0].y)
    finite = y[np.isfinite(y)]
    return finite.size == 0 or bool(np.all(finite == finite[0]))


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


def stacked_layout(rows: Sequence[Figure]) -> tuple[dict, list[int]]:
    """The layout of ``rows`` stacked on one time axis, and each row's y-axis number (1, 2, ...)."""
    heights = _row_heights(rows)
    plot_px = sum(heights) + TITLE_PX * len(rows)
    total_px = plot_px + TOP_PX + BOTTOM_PX
    layout: dict = {
        "height": total_px,
        "margin": {"l": 70, "r": LEGEND_PX, "t": TOP_PX, "b": BOTTOM_PX},
        "hovermode": "x unified",
        "hoversubplots": "axis",  # hovering one row hovers every row at that time
        "plot_bgcolor": "white",
        "paper_bgcolor": "white",
        "template": {},
        "annotations": [],
    }
    top = plot_px
    n = len(rows)
    for r, (fig, height) in enumerate(zip(rows, heights), 1):
        top -= TITLE_PX
        domain = [(top - height) / plot_px, top / plot_px]
        top -= height
        axis = "yaxis" if r == 1 else f"yaxis{r}"
        layout[axis] = {
            "domain": domain,
            "anchor": "x",
            "title": {"text": plot_text(fig.y_title), "font": {"size": 11}},
            "gridcolor": "#eee",
            "exponentformat": "e",  # 1e-04, never SI prefixes ("100µ") on ratios and statistics
            "type": "log" if fig.log_y else "linear",
            **({"range": list(fig.y_range)} if fig.y_range else {}),
        }
        layout[f"yaxis{n + r}"] = {"overlaying": f"y{'' if r == 1 else r}", "domain": domain, "range": [0, 1],
                                   "visible": False, "fixedrange": True}  # fmt: skip
        legend = "legend" if r == 1 else f"legend{r}"
        layout[legend] = {"x": 1.01, "xanchor": "left", "y": domain[1], "yanchor": "top", "font": {"size": 10},
                          "tracegroupgap": 2}  # fmt: skip
        words = f"  <span style='font-size:11px;color:#555'>{plot_text(fig.subtitle)}</span>" if fig.subtitle else ""
        layout["annotations"].append({
            "text": f"<b>{plot_text(fig.title)}</b>{words}", "xref": "paper", "yref": "paper", "x": 0,
            "y": domain[1], "xanchor": "left", "yanchor": "bottom", "showarrow": False, "font": {"size": 12},
        })  # fmt: skip
    layout["xaxis"] = {**TIME_AXIS, "anchor": f"y{'' if n == 1 else n}", **SPIKES}
    return layout, list(range(1, n + 1))


def stacked_json(rows: Sequence[Figure], t: np.ndarray, points: dict[int, int], windows: np.ndarray, clock) -> str:
    """The rows as one figure's escaped plotly JSON, traces decimated to ``points`` (trace id ->
    points) as `logscan.report.plotly_json.figure_json` does for one figure."""
    layout, numbers = stacked_layout(rows)
    n = len(rows)
    data: list[dict] = []
    for fig, r in zip(rows, numbers):
        axes = {"y": f"y{'' if r == 1 else r}", "y2": f"y{n + r}"}
        legend = "legend" if r == 1 else f"legend{r}"
        for trace in trace_data(fig, t, points, windows):
            if "hovertemplate" in trace:  # the unified hover box gives the time once, on top
                trace["hovertemplate"] = "%{y:.4g}"
            trace["xaxis"] = "x"
            trace["yaxis"] = axes[trace.get("yaxis", "y")]
            trace["legend"] = legend
            data.append(trace)
    return plain_json(data, layout, clock)


def row_captions(rows: Sequence[Figure], flat: Sequence[str]) -> list[str]:
    """What each row shows, once per distinct caption, and the rows left out as flat."""
    captions: list[str] = []
    for fig in rows:
        if fig.caption and fig.caption not in captions:
            captions.append(fig.caption)
    if flat:
        captions.append(f"Not drawn, constant all log long and never alarmed: {', '.join(flat)}.")
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
    parts = []
    for fig_id, item in figures:
        spec = stacked_json(item, t, points, windows, clock) if isinstance(item, list) else (
            figure_json(item, t, points, windows, clock))  # fmt: skip
        parts.append(f'{{"id":"{fig_id}","figure":{spec}}}')
    parts += [f'{{"id":"{spec["id"]}","figure":{spec["json"]}}}' for spec in extra]
    return "[" + ",".join(parts) + "]"
