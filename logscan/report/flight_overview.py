"""The flight at a glance when nothing alarmed: every measurement group against its prediction.

A report without incidents used to draw no data at all (only flat statistics, folded). Here every
group the filter used gets one row, its channels' normalised innovations (measured − predicted,
divided by σ of S: `logscan.report.sensor_figures`), all on the page's time axis in one stacked
figure (`logscan.report.stacked`), decimated as every figure is. It is drawn only when the log has
no incident, so it never takes points from the evidence of one.
"""

from __future__ import annotations

import numpy as np

from logscan.report.figures import Figure
from logscan.report.sensor_figures import normalised_figure
from logscan.report.sensor_views import GroupRows

FIGURE_ID = "fig-checked"


def checked_rows(innovations: GroupRows | None, t: np.ndarray, truth_spans: list) -> list[Figure]:
    """One row per measurement group: its channels' normalised innovations (the last of
    `sensor_figures`); [] without innovations (no filter ran)."""
    if innovations is None:
        return []
    rows = []
    for group in innovations.group_names:
        normalised = innovations.normalised(group)
        if normalised is None or not np.isfinite(normalised).any():
            continue
        channels = innovations.channels[group]
        times = innovations.times(group, t)  # block mode: the group's kept rows' own
        rows.append(normalised_figure(group, channels, normalised, times, {"ground truth": truth_spans}))
    return rows


def checked_view(rows: list[Figure]) -> dict | None:
    """The template's view of the overview figure (None without rows)."""
    if not rows:
        return None
    groups = ", ".join(fig.title.split(":", 1)[0] for fig in rows)
    caption = (
        f"Every measurement group the filter used ({groups}): each channel's innovation (measured − "
        "predicted) over its σ, one row per group. Normal: noise around 0, mostly within ±3 (dashed); a "
        "sustained offset or growing spread on one channel is where to look even without an alarm."
    )
    return {"id": FIGURE_ID, "rows": len(rows), "title": "every sensor against its prediction", "caption": caption}
