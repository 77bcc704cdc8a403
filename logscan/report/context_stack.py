"""The Context section's figures on the time axis as one figure: the mode, the autopilot's state
and messages, where a fault could not be seen, and rows other modules hook in
(`logscan.report.page_parts.CONTEXT_ROWS`), each a row on one shared x axis.

Each row is a `logscan.report.context_figures.time_row` (its traces on ``y`` and the hidden overlay
``y2``, its own y axis, its annotations on ``y``); here row r gets y axis r, overlay axis n + r and
a band above it with its title and legend (`logscan.report.stacked.row_band`), as a detector
section's rows: one hover and one spike line across the rows, one zoom that follows the page's.
"""

from __future__ import annotations

from collections.abc import Sequence

from logscan.report.plotly_json import TIME_AXIS, plain_json
from logscan.report.stacked import SPIKES, base_layout, on_row, row_band, row_domains
from logscan.timebase.clock import Clock

FIGURE_ID = "ctx-time"
OWN_MARGINS_PX = 140  # a time row's figure alone: its title (40) and its legend and axis title (100) around the plot
MIN_ROW_PX = 60


def _row_axes(layout: dict, row: dict, r: int, n: int, domain: list[float]) -> dict[str, str]:
    """Row ``r``'s y axis and overlay axis in ``layout``; the names its traces' ``y``/``y2`` become."""
    own = row["layout"]
    axis = {"zeroline": False, **own.get("yaxis", {}), "domain": domain, "anchor": "x"}
    if "ticktext" in axis:  # named rows: their names inside the plot, so its left edge stays the sections'
        axis |= {"ticklabelposition": "inside", "automargin": False}
    layout["yaxis" if r == 1 else f"yaxis{r}"] = axis
    y = "y" if r == 1 else f"y{r}"
    layout[f"yaxis{n + r}"] = {"overlaying": y, "domain": domain, "range": [0, 1], "visible": False,
                               "fixedrange": True}  # fmt: skip
    for note in own.get("annotations", ()):  # a mode's names, at its rows
        layout["annotations"].append({**note, "yref": y} if note.get("yref") == "y" else dict(note))
    return {"y": y, "y2": f"y{n + r}"}


def stack_rows(rows: Sequence[dict], clock: Clock | None = None, t_span: tuple[float, float] | None = None) -> dict:
    """The rows as one serialised figure (as `logscan.report.context_figures._spec`), its element id
    FIGURE_ID, ``"rows"`` and each row's caption in ``"captions"``; its time axis spans ``t_span``
    (the analysis grid's) when given, in ``clock``."""
    heights = [max(int(row["layout"].get("height", 0)) - OWN_MARGINS_PX, MIN_ROW_PX) for row in rows]
    plot_px, domains = row_domains(heights)
    layout = base_layout(plot_px)
    layout["hoverdistance"] = -1  # a mode is a few steps: the hover gives the value in force, however far its last step
    n, data = len(rows), []
    for r, (row, domain) in enumerate(zip(rows, domains), 1):
        axes = _row_axes(layout, row, r, n, domain)
        legend = row_band(layout, r, domain, row["spec"]["title"])
        data += [on_row(trace, axes, legend) for trace in row["data"]]
    layout["xaxis"] = {**TIME_AXIS, "anchor": f"y{'' if n == 1 else n}", **SPIKES}
    if t_span is not None:
        layout["xaxis"]["range"] = [float(t_span[0]), float(t_span[1])]
    spec = {
        "id": FIGURE_ID,
        "title": "; ".join(row["spec"]["title"] for row in rows),
        "caption": "",
        "captions": [row["spec"]["caption"] for row in rows],
        "timeseries": True,
        "height": layout["height"],
        "rows": n,
        "row_ids": " ".join(row["spec"]["id"] for row in rows),  # ctx-mode, ctx-states...: what it shows
    }
    text = plain_json(data, layout, clock)  # not plotly's validated Figure: slow on many axes
    return {**spec, "json": text, "points": len(text) * 3 // 32}
