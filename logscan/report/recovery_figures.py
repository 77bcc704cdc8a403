"""The report's recovery section (`logscan.report.recovery_view.RecoveryView`): per loop and recovered
state, the measurement that reads it, the shared EKF's estimate and the recovered estimate with its
k-sigma bound as a band, the anomalies shaded and the checkpoints used marked; and a table with one
row per anomaly (checkpoint, roll-forward length, T_max, whether recovery stayed trustworthy)."""

from __future__ import annotations

import numpy as np

from logscan.alarms import true_runs
from logscan.report.context_figures import _band_trace, _spec, _time_row_layout
from logscan.report.plotly_json import plot_text
from logscan.timebase.clock import Clock

HEIGHT = 320
COLOURS = {
    "measured": "#9a9a9a", "ekf": "#1f77b4", "recovered": "#2ca02c", "band": "rgba(44,160,44,0.18)", "truth": "#111",
}  # fmt: skip


def _line(name: str, t: np.ndarray, y: np.ndarray, colour: str, **extra) -> dict:
    return {
        "type": "scatter", "name": name, "x": t.astype(np.float64), "y": y.astype(np.float64), "mode": "lines",
        "line": {"color": colour, "width": 1.5}, "hovertemplate": "%{y:.4g} at %{x:.2f} s", **extra,
    }  # fmt: skip


def _band(name: str, t: np.ndarray, centre: np.ndarray, bound: np.ndarray) -> dict:
    """centre +- bound as one filled polygon per recovered span (NaN elsewhere): a fill between two
    lines would bridge the gaps between spans."""
    finite = np.isfinite(centre) & np.isfinite(bound)
    x: list[float] = []
    y: list[float] = []
    for first, stop in zip(*true_runs(finite)):
        span = slice(first, stop)
        x += [*t[span], *t[span][::-1], np.nan]
        y += [*(centre[span] + bound[span]), *(centre[span] - bound[span])[::-1], np.nan]
    return {
        "type": "scatter", "name": name, "x": np.asarray(x, dtype=np.float64), "y": np.asarray(y, dtype=np.float64),
        "mode": "lines", "line": {"width": 0}, "fill": "toself", "fillcolor": COLOURS["band"], "hoverinfo": "skip",
    }  # fmt: skip


def _checkpoint_trace(times: list[float]) -> dict:
    """Each checkpoint used as a vertical dashed line on the overlay axis y2 (0..1)."""
    x = [v for t in times for v in (t, t, np.nan)]
    y = [v for _ in times for v in (0.0, 1.0, np.nan)]
    return {
        "type": "scatter", "name": "checkpoint used", "x": np.asarray(x, dtype=np.float64), "y": y,
        "yaxis": "y2", "mode": "lines", "line": {"color": "#444", "dash": "dash", "width": 1}, "hoverinfo": "skip",
    }  # fmt: skip


def state_figure(view, sv, index: int, clock: Clock) -> dict:
    """One recovered state: measured, EKF, recovered +- bound, anomalies and checkpoints."""
    mine = [a for a in view.anomalies if sv.loop in a.loops and a.t_checkpoint is not None]
    spans = [(a.t_detect, a.t_recovered_end if a.t_recovered_end is not None else a.t_end) for a in mine]
    data = [_band_trace("anomaly (recovering)", spans, "rgba(214,39,40,0.10)")] if spans else []
    if mine:
        data.append(_checkpoint_trace([a.t_checkpoint for a in mine]))
    if sv.measured is not None:
        data.append(_line(f"measured ({plot_text(sv.measured_name)})", sv.t, sv.measured, COLOURS["measured"]))
    data += [
        _band(f"recovered +- {view.k_sigma:g} sigma", sv.t, sv.recovered, sv.bound),
        *([_line("truth", sv.t, sv.truth, COLOURS["truth"], line={"color": COLOURS["truth"], "dash": "dot"})]
          if sv.truth is not None else []),
        _line("shared EKF", sv.t, sv.ekf, COLOURS["ekf"]),
        _line("recovered", sv.t, sv.recovered, COLOURS["recovered"], line={"color": COLOURS["recovered"], "width": 3}),
    ]  # fmt: skip
    title = f"{sv.loop}: {sv.state}"
    layout = _time_row_layout(title, {"title": {"text": plot_text(sv.state)}, "gridcolor": "#eee"})
    layout["height"] = HEIGHT
    layout["yaxis2"] = {"overlaying": "y", "range": [0, 1], "visible": False, "fixedrange": True}
    caption = (
        f"Loop {sv.loop}, state {sv.state}: what the estimator believed (shared EKF, blue) and what it should "
        f"have believed during each anomaly (recovered from the checkpoint, green, with its {view.k_sigma:g}-sigma "
        "bound from the covariance carried through the recovery)"
        + (f"; grey: {sv.measured_name} as logged" if sv.measured is not None else "")
        + ("; dotted: the true state (the log's ground truth)" if sv.truth is not None else "")
        + ". Dashed lines: the checkpoints used."
    )
    spec = {"id": f"rec-{index}", "title": title, "caption": caption, "timeseries": True, "height": HEIGHT}
    return _spec(spec, data, layout, clock)


def recovery_figures(view, clock: Clock) -> list[dict]:
    if view is None:
        return []
    return [state_figure(view, sv, i, clock) for i, sv in enumerate(view.states)]


def _seconds(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def _ended(a) -> str:
    """The "alarm" cell: whether recovery went on past the detector's alarm, and why it ended."""
    kept = ("kept until the sensors agreed" if a.t_agreed is not None else "kept") if a.alarm_kept else "-"
    return f"{kept}; ended: {a.end_reason}" if a.end_reason else kept


def recovery_rows(view, clock: Clock) -> list[dict]:
    """One row per anomaly, times in ``clock``."""
    if view is None:
        return []
    rows = []
    for n, a in enumerate(view.anomalies, 1):
        sensors = "all (generic detector)" if a.targets is None else "; ".join(
            f"{loop}: {', '.join(groups)}" for loop, groups in a.targets.items()
        )  # fmt: skip
        t_max = ", ".join(f"{state} {_seconds(v)} s" for state, v in a.t_max.items()) or "-"
        rows.append({
            "index": n, "detected": clock.text(a.t_detect), "sensors": sensors, "method": a.method,
            "checkpoint": "-" if a.t_checkpoint is None else clock.text(a.t_checkpoint),
            "rollforward": _seconds(a.rollforward_s),
            "end": "-" if a.t_recovered_end is None else clock.text(a.t_recovered_end),
            "kept": _ended(a),
            "t_max": t_max, "verdict": a.verdict or a.note or "trustworthy",
            "untrusted": bool(a.outlasted),
        })  # fmt: skip
    return rows
