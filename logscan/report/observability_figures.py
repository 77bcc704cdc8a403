"""The report's observability figure: one row per (actuator or sensor, fault kind), shaded where a
fault of that kind could not have been seen (`logscan.verdict.observability`), on the shared time axis."""

from __future__ import annotations

from logscan.docs import doc_url
from logscan.report.context_figures import _time_row_layout, _time_row_spec, row_figure, time_row
from logscan.report.plotly_json import plot_text
from logscan.timebase.clock import Clock

BLIND_FILL = "rgba(127, 127, 127, 0.35)"
ROW_HEIGHT = 28  # px per row beyond the figure's base height


def observability_figures(observability, clock: Clock | None = None) -> list[dict]:
    """`observability_rows` as figures of their own."""
    return [row_figure(row, clock) for row in observability_rows(observability)]


def observability_rows(observability) -> list[dict]:
    """[] without a verdict or when every judged fault could be seen throughout; else one `time_row`."""
    if observability is None:
        return []
    blind = observability.blind_periods()
    if not blind:
        return []
    data, names = [], []
    for row, period in enumerate(blind):
        x, y = [], []
        for a, b in period["intervals"]:  # a filled rectangle per unobservable span on its row
            x += [a, a, b, b, None]
            y += [row - 0.4, row + 0.4, row + 0.4, row - 0.4, None]
        name = f"{period['kind']}: {period['target']}"
        names.append(plot_text(name))
        data.append({
            "type": "scatter", "name": plot_text(name), "x": x, "y": y, "mode": "lines", "fill": "toself",
            "fillcolor": BLIND_FILL, "line": {"width": 0}, "hoveron": "fills", "showlegend": False,
            "text": plot_text(period["words"]), "hoverinfo": "text",
        })  # fmt: skip
    yaxis = {"tickvals": list(range(len(names))), "ticktext": names, "range": [-0.6, len(names) - 0.4],
             "fixedrange": True, "automargin": True}  # fmt: skip
    layout = _time_row_layout("where a fault could not be seen", yaxis, (observability.t_first, observability.t_end))
    layout["height"] = _time_row_spec("", "", "")["height"] + ROW_HEIGHT * max(len(names) - 3, 0)
    words = "; ".join(dict.fromkeys(p["words"].split(": ", 1)[1] for p in blind))
    size = f"of the size named in {doc_url('algorithms.md')} section 10"
    caption = (
        f"Grey: a fault of that kind, {size} (actuator offset 10 %, a lost actuator, a sensor bias of 1 unit), "
        f"starting there would leave less than {observability.snr_min:.3g} standard deviations of evidence in the "
        f"filter's innovations within {observability.window_s:g} s, so no detector reading these sensors could "
        f"promise to see it ({words}). A missed fault there is no detector's failure; `logscan evaluate` counts it "
        "apart."
    )
    if any(d.startswith("judged around") for d in observability.notes):  # `observability_for`
        caption += " Judged only from a second before each fault of the ground truth to its end: elsewhere, no verdict."
    spec = _time_row_spec("ctx-observability", "where a fault could not be seen", caption)
    spec["height"] = layout["height"]
    return [time_row(spec, data, layout)]
