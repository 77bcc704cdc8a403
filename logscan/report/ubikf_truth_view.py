"""The UBIKF's estimation error against its envelopes, per state the truth gives (the UBIKF paper's
figure of the error and its bounds): rows of the `chi2` section's figure
(`logscan.report.page_parts.DETECTOR_ROWS`), on a simulated log only.

Per state, one row: the error of the mid-model estimate, x_mid - x_true, inside two bands around
zero: the hull of the posterior zonotope seen from the estimate (x_lo - x_mid .. x_hi - x_mid:
every admissible model's estimate lies there) and +-3 sqrt(P+_ii) (the covariance bound). The true
state comes from the run context (`logscan.report.run_context.true_states`: the samples are
released before the detectors run), the estimate and bands from the `chi2` result's `EnvelopeView`.
The caption states per state the share of steps where the true state lies inside the hull and
inside +-3 sqrt(P+_ii), counted on every step (not the drawn ones), where all of them are defined
and the UBIKF did not restart.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Protocol

import numpy as np

from logscan.detectors.ubikf_bound import EnvelopeView
from logscan.report.decimate import decimate_indices
from logscan.report.figures import LINE_COLOURS, Figure, Trace
from logscan.report.report_input import ReportInput
from logscan.results import DetectorResult

SIGMAS = 3.0  # the covariance band's half-width in standard deviations
HULL_FILL, SIGMA_FILL = "rgba(255, 127, 14, 0.25)", "rgba(127, 127, 127, 0.18)"
ERROR_STYLE = {"line": {"color": LINE_COLOURS[0], "width": 1.0}}
NO_KEEP = np.zeros(0, dtype=np.int64)  # no sample every drawing must keep (the rows shade no alarm)
# the rows' points: at most these (12 states' rows add about 30 KB to a page) for the error line and
# each edge of a band (smooth: few points draw it), whatever their weight in the page's point budget
ERROR_POINTS, SIGMA_EDGE_POINTS, HULL_EDGE_POINTS = 64, 16, 18
WEIGHT = 0.05  # small: a capped trace's weight would only shrink the other rows' shares
CAPTION = (
    "The UBIKF's estimation error x_mid − x_true in each state the simulator's ground truth gives (blue), "
    "as in the paper's figure of the error and its bounds, with two envelopes seen from the estimate: the "
    "hull of its zonotope (orange: the estimates of every admissible model on the same data; it holds the "
    "model's uncertainty, not the noise, so the truth may lie outside it on a healthy log too) and "
    "±{k:g}√P+ (grey: the covariance bound; normal: the error stays inside it at nearly every step). "
    "Share of the steps where the true state lies inside the hull / inside ±{k:g}√P+ (every step, not "
    "only those drawn): {shares}."
)


class HasReport(Protocol):
    """What the rows read of the page (`logscan.report.page_parts.PageInput`)."""

    report: ReportInput
    truth_spans: list[tuple[float, float]]


class InsideShares(NamedTuple):
    """Per state, the share of the judged steps where the true state lies inside the envelope."""

    hull: float  # x_lo <= x_true <= x_hi
    sigma: float  # |x_mid - x_true| <= SIGMAS sqrt(P+_ii)
    steps: int  # the steps judged: every value defined, the UBIKF not restarted


def matched_states(view: EnvelopeView, truth: dict[str, np.ndarray]) -> list[str]:
    """The view's states the truth gives, in the view's order."""
    return [name for name in view.state_names if name in truth]


def inside_shares(view: EnvelopeView, truth: dict[str, np.ndarray]) -> dict[str, InsideShares]:
    """State -> `InsideShares` of every state of `matched_states` (all steps at once, per column)."""
    states = matched_states(view, truth)
    if not states:
        return {}
    cols = [view.state_names.index(name) for name in states]
    x_true = np.column_stack([truth[name] for name in states])
    x_mid, x_lo, x_hi = view.x_mid[:, cols], view.x_lo[:, cols], view.x_hi[:, cols]
    sigma = SIGMAS * np.sqrt(np.asarray(view.P_diag[:, cols], dtype=np.float64))
    judged = np.isfinite(x_true) & np.isfinite(x_mid) & np.isfinite(x_lo) & np.isfinite(x_hi) & np.isfinite(sigma)
    judged &= np.asarray(view.valid, dtype=bool)[:, None]
    steps = judged.sum(axis=0)
    with np.errstate(invalid="ignore"):
        in_hull = judged & (x_lo <= x_true) & (x_true <= x_hi)
        in_sigma = judged & (np.abs(x_mid - x_true) <= sigma)
    with np.errstate(invalid="ignore", divide="ignore"):  # a state never judged: NaN shares
        hull, within = in_hull.sum(axis=0) / steps, in_sigma.sum(axis=0) / steps
    return {name: InsideShares(float(hull[k]), float(within[k]), int(steps[k])) for k, name in enumerate(states)}


def percent(share: float) -> str:
    """A share as a percentage, rounded down (100.0 % only when every step is inside)."""
    return "–" if not math.isfinite(share) else f"{math.floor(1000.0 * share) / 10.0:.1f}\u00a0%"


def shares_text(shares: dict[str, InsideShares]) -> str:
    """The caption's shares: "x 100.0 % / 99.7 %, y ..." (inside the hull / inside the bound)."""
    return ", ".join(f"{name} {percent(s.hull)} / {percent(s.sigma)}" for name, s in shares.items())


def start_indices(n: int) -> np.ndarray:
    """Steps 0, 1, 2, 4, 8, ... below ``n``: a bound's start-up transient (decaying from P0 within
    a few dozen steps) kept in the drawing whatever the buckets, at log2(n) points."""
    return np.unique(np.concatenate([[0], 2 ** np.arange(max(int(n).bit_length() - 1, 0))]))


def band_trace(
    name: str, t: np.ndarray, lower: np.ndarray, upper: np.ndarray, edge_points: int, fill: str, transient: bool
) -> Trace:
    """A band as one filled outline (plotly's ``fill: "toself"``): the upper edge forward in time,
    the lower edge back, over the steps where both are defined, each edge decimated on its own
    (`decimate_indices`: its first and last step kept, and with ``transient`` its start-up
    transient, `start_indices`) to at most ``edge_points``; the outline is drawn as it is (its
    ``max_points`` is its length)."""
    ok = np.flatnonzero(np.isfinite(lower) & np.isfinite(upper))
    start = start_indices(ok.size) if transient else None
    up = ok[decimate_indices(upper[ok], edge_points, keep=start)]
    down = ok[decimate_indices(lower[ok], edge_points, keep=start)][::-1]
    x, y = np.concatenate([t[up], t[down]]), np.concatenate([upper[up], lower[down]])
    style = {"fill": "toself", "fillcolor": fill, "line": {"width": 0}, "hoverinfo": "skip"}
    return Trace(name, y, NO_KEEP, WEIGHT, style, t=x, max_points=max(y.size, 1))


def y_view(*series: np.ndarray) -> tuple[float, float] | None:
    """A symmetric initial y range over the 0.1-99.9 percentiles of the drawn values' magnitude,
    padded by a tenth: the start-up transient (x0 and P0) would squash the rest; double-clicking
    the plot restores the full range. None when nothing is defined."""
    values = np.abs(np.concatenate(series))
    values = values[np.isfinite(values)]
    if values.size == 0:
        return None
    top = 1.1 * float(np.percentile(values, 99.9)) or 1.0
    return -top, top


def state_row(view: EnvelopeView, col: int, x_true: np.ndarray, spans: dict, caption: str) -> Figure:
    """One state's row: its error inside the hull and the +-SIGMAS sqrt(P+) band."""
    name = view.state_names[col]
    t = np.asarray(view.t, dtype=np.float64)
    x_mid = view.x_mid[:, col]
    sigma = SIGMAS * np.sqrt(np.asarray(view.P_diag[:, col], dtype=np.float64))
    hull_lo, hull_hi = view.x_lo[:, col] - x_mid, view.x_hi[:, col] - x_mid
    error = x_mid - x_true
    traces = [
        band_trace(f"±{SIGMAS:g}√P+ (UBIKF bound)", t, -sigma, sigma, SIGMA_EDGE_POINTS, SIGMA_FILL, True),
        band_trace("zonotope hull − x_mid", t, hull_lo, hull_hi, HULL_EDGE_POINTS, HULL_FILL, False),
        Trace("x_mid − x_true", error, NO_KEEP, WEIGHT, ERROR_STYLE, max_points=ERROR_POINTS),
    ]
    return Figure(
        title=f"chi2: the UBIKF's error in {name} against its envelopes",
        y_title=f"{name} error",
        traces=traces,
        spans=spans,
        caption=caption,
        y_range=y_view(error, sigma, hull_lo, hull_hi),
    )


def ubikf_truth_rows(result: DetectorResult, page: HasReport) -> list[Figure]:
    """One row per state of a `chi2` result's `EnvelopeView` the log's true state gives ([] for
    any other result, and for a log without a true state)."""
    view = result.info.get("envelope_view")
    context = page.report.context
    truth = context.true_states if context is not None else {}
    if not isinstance(view, EnvelopeView) or not matched_states(view, truth):
        return []
    caption = CAPTION.format(k=SIGMAS, shares=shares_text(inside_shares(view, truth)))
    spans = {"ground truth": page.truth_spans}
    return [
        state_row(view, view.state_names.index(name), truth[name], spans, caption)
        for name in matched_states(view, truth)
    ]
