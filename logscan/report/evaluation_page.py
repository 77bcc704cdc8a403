"""The evaluation as a page: `logscan evaluate LOGS -o eval.html`.

Per detector and check, the pooled scores (events, detections, misses, false alarms, precision,
recall, F1, latency, false alarms per hour on the healthy logs) and the latency distribution (a
box per check); per fault kind, the detection matrix (detected / events, per detector). Self-
contained as the analysis report: plotly.js embedded once, every name escaped.
"""

from __future__ import annotations

from logscan import __version__
from logscan.report.page_assets import environment, plotly_js
from logscan.report.plotly_json import plot_text, spec_json
from logscan.verdict.evaluation import CHECK_SEPARATOR, Evaluation


def _number(value, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def render_evaluation_html(evaluation: Evaluation, plotlyjs_src: str | None = None) -> str:
    """The evaluation page; plotly.js inside it, or from ``plotlyjs_src`` (a URL) if given."""
    keys = evaluation.keys()
    rows, boxes = [], []
    for key in keys:
        score = evaluation.aggregate(key)
        rows.append({
            "key": key, "check": CHECK_SEPARATOR in key, "events": score.n_events, "tp": score.tp, "fn": score.fn,
            "fp": score.fp, "precision": _number(score.precision), "recall": _number(score.recall),
            "f1": _number(score.f1), "lat_mean": _number(score.mean_latency_s), "lat_max": _number(score.max_latency_s),
            "fa_h": _number(score.false_alarms_per_hour_healthy, 1),
        })  # fmt: skip
        if score.latencies_s:
            boxes.append({"type": "box", "name": plot_text(key), "x": list(score.latencies_s), "boxpoints": "all"})
    detectors = [k for k in keys if CHECK_SEPARATOR not in k]
    by_kind = {key: evaluation.by_kind(key) for key in detectors}
    matrix = []
    for kind in evaluation.kinds():
        cells = []
        for key in detectors:
            s = by_kind[key].get(kind)
            cells.append("-" if s is None else f"{s.tp}/{s.tp + s.fn}")
        matrix.append({"kind": kind, "cells": cells})
    layout = {
        "title": {"text": "latency from fault start to alarm (s), per detector and check"},
        "height": 120 + 40 * len(boxes), "margin": {"l": 180, "r": 20, "t": 40, "b": 40},
        "xaxis": {"title": {"text": "s"}, "zeroline": False}, "showlegend": False, "template": {},
    }  # fmt: skip
    figure = spec_json(boxes, layout) if boxes else None
    hours = sum(log.duration_s for log in evaluation.logs if log.healthy) / 3600.0
    return (
        environment()
        .get_template("evaluation.html.j2")
        .render(
            title="logscan evaluation",
            version=__version__,
            n_logs=len(evaluation.logs),
            n_events=sum(len(log.events) for log in evaluation.logs),
            n_healthy=sum(log.healthy for log in evaluation.logs),
            healthy_hours=f"{hours:.2f}",
            grace_s=evaluation.grace_s,
            recovery_s=evaluation.recovery_s,
            rows=rows,
            detectors=detectors,
            matrix=matrix,
            figure_json=figure,
            plotly_js=plotly_js() if figure and not plotlyjs_src else "",
            plotlyjs_src=plotlyjs_src,
            skipped=evaluation.skipped,
            failures=[f.message for f in evaluation.failures],
        )
    )
