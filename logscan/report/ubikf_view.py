"""The UBIKF's covariance bound against the point filter's covariance: a row of the `chi2` section's
figure (`logscan.report.page_parts.DETECTOR_ROWS`). trace(P+) (the bound every admissible model's
covariance stays below) and trace(P) of the point EKF on the nominal model, on a log scale; the
caption states their settled ratio (above 1 where the model has interval uncertainty in A or C).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from logscan.detectors.ubikf_bound import BoundView
from logscan.report.decimate import edge_indices
from logscan.report.figures import LINE_COLOURS, Figure, Trace
from logscan.results import DetectorResult


class HasTruthSpans(Protocol):
    """What the row reads of the page (`logscan.report.page_parts.PageInput`)."""

    truth_spans: list[tuple[float, float]]


CAPTION = (
    "The UBIKF's covariance upper bound trace(P+) against the point Kalman filter's trace(P) on the "
    "nominal model, same log. The bound holds the covariance of every model inside the intervals, so "
    "it lies above the point filter's; by how much is the price of the parameter uncertainty. Normal: "
    "both settle (the paper's Fig. 4) and stay apart by a steady ratio, {ratio}."
)


def ubikf_rows(result: DetectorResult, page: HasTruthSpans) -> list[Figure]:
    """The bound row of a `chi2` result that carries its `BoundView` ([] for any other result)."""
    view = result.info.get("bound_view")
    if not isinstance(view, BoundView):
        return []
    t = np.asarray(view.t, dtype=np.float64)
    keep = edge_indices(t, [])
    ratio = view.settled_ratio()
    said = f"median ratio {ratio:.4f} over the second half of the log" if np.isfinite(ratio) else "no ratio"
    traces = [
        Trace("trace(P+) (UBIKF bound)", view.bound, keep, 0.5, {"line": {"color": LINE_COLOURS[0], "width": 1.2}}),
        Trace("trace(P) (point EKF)", view.point, keep, 0.5, {"line": {"color": LINE_COLOURS[1], "width": 1.0}}),
    ]
    alarms = [(float(a.start), float(a.end)) for a in result.alarms]
    return [
        Figure(
            title="chi2: the bound against the point filter's covariance",
            y_title="trace of the covariance",
            traces=traces,
            spans={"ground truth": page.truth_spans, "alarm": alarms},
            log_y=True,
            caption=CAPTION.format(ratio=said),
        )
    ]
