"""KGN's gain norms against the trained band, per group (the Kalman gain norm paper's Figs. 9-10):
rows of the `kgn` section's figure (`logscan.report.page_parts.DETECTOR_ROWS`).

Per measurement group, one row: each column's window mean Nbar_j (solid) and its operating-point
bin's band ref_j +- rho s_j (dashed, the same colour), drawn where the window was judged (steady,
trained bin, inside the trained envelope); the band steps where the flight moves into another bin.
Alarm spans of that group's statistic and the ground truth are shaded as on the statistic's row.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from logscan.detectors.kgn_windows import GainView
from logscan.report.decimate import edge_indices
from logscan.report.figures import LINE_COLOURS, Figure, Trace
from logscan.results import DetectorResult


class HasTruthSpans(Protocol):
    """What the rows read of the page (`logscan.report.page_parts.PageInput`)."""

    truth_spans: list[tuple[float, float]]


CAPTION = (
    "The Kalman gain norm per measurement column, as in the paper's Figs. 9-10: each column's norm "
    "||K[:, j]|| averaged over the window (solid) against the band its healthy reference allows, "
    "ref ± rho × spread (dashed, same colour; per operating-point bin: the band steps when the flight "
    "moves into another bin), drawn only where the window was judged. A norm outside its band for "
    "two windows is an alarm (shaded red)."
)


def judged_view(view: GainView, cols: slice) -> tuple[float, float] | None:
    """The initial y range: the judged windows' norms and bands (the filter's start-up transient
    would squash them), padded by a tenth; None when no window was judged."""
    judged = np.asarray(view.judged, dtype=bool)
    half = np.float32(view.rho) * view.spread[judged, cols]
    values = np.concatenate([view.nbar[judged, cols], view.ref[judged, cols] + half, view.ref[judged, cols] - half])
    values = values[np.isfinite(values)]
    if values.size == 0:
        return None
    lo, hi = float(values.min()), float(values.max())
    pad = 0.1 * (hi - lo) if hi > lo else 0.1 * max(abs(hi), 1e-12)
    return lo - pad, hi + pad


def group_rows(view: GainView, spans: dict, alarms: dict[str, list[tuple[float, float]]]) -> list[Figure]:
    """One row per group of ``view``; ``alarms``: group -> the spans of its statistic's alarms."""
    rows = []
    x = np.asarray(view.t, dtype=np.float64)
    judged = np.asarray(view.judged, dtype=bool)
    for group, offset, size in zip(view.groups, view.offsets, view.sizes):
        own = alarms.get(group, [])
        keep = edge_indices(x, own)
        traces = []
        for k, j in enumerate(range(offset, offset + size)):
            colour = LINE_COLOURS[k % len(LINE_COLOURS)]
            half = np.float32(view.rho) * view.spread[:, j]
            upper = np.where(judged, view.ref[:, j] + half, np.nan)
            lower = np.where(judged, view.ref[:, j] - half, np.nan)
            column = view.columns[j] or f"{group}[{k}]"
            dashed = {"line": {"color": colour, "width": 0.8, "dash": "dash", "shape": "hv"}, "legendgroup": column}
            traces += [
                Trace(f"{column}: ref ± rho·s", upper, keep, 0.25, dashed, t=x),
                Trace(f"{column}: ref - rho·s", lower, keep, 0.25, {**dashed, "showlegend": False}, t=x),
                Trace(column, view.nbar[:, j], keep, 0.5, {"line": {"color": colour, "width": 1.2}}, t=x),
            ]
        rows.append(
            Figure(
                title=f"kgn: {group} gain norms against the trained band",
                y_title=f"Nbar ({group})",
                traces=traces,
                spans={**spans, "alarm": own},
                caption=CAPTION,
                y_range=judged_view(view, slice(offset, offset + size)),
            )
        )
    return rows


def kgn_rows(result: DetectorResult, page: HasTruthSpans) -> list[Figure]:
    """The rows of a `kgn` result that carries its `GainView` ([] for any other result)."""
    view = result.info.get("gain_view")
    if not isinstance(view, GainView):
        return []
    alarms: dict[str, list[tuple[float, float]]] = {}
    for alarm in result.alarms:
        group = alarm.signal.partition(".")[2]
        alarms.setdefault(group, []).append((float(alarm.start), float(alarm.end)))
    return group_rows(view, {"ground truth": page.truth_spans}, alarms)
