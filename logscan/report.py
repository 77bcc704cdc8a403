"""The HTML analysis report: ReportInput -> one offline HTML file (jinja2 + plotly figures).

The page is rendered from ``templates/report.html.j2`` with autoescaping on (topic, channel and
signal names come from untrusted logs). Figures are built with plotly graph_objects, serialised
to JSON with every ``<``, ``>`` and ``&`` escaped, placed in one ``application/json`` block and
drawn by a small inline script with ``Plotly.newPlot``; plotly.js itself is embedded once, or
written once beside the reports (``plotlyjs=<directory>``) and referenced relatively.

Traces are decimated (``logscan.decimate``: min/max per bucket, alarm edges and NaN gaps kept)
under one point budget per report, so a report stays a few hundred kilobytes plus plotly.js
whatever the log length.
"""

from __future__ import annotations

import datetime as _dt
import functools
import json
import math
import os
import urllib.parse
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from logscan.artifacts import write_atomic
from logscan.decimate import DEFAULT_MAX_POINTS, decimate_indices, edge_indices
from logscan.errors import InputError

PLOTLY_JS_NAME = "plotly.min.js"
POINT_BUDGET = 20_000  # plotted points per report, shared by all varying traces
MIN_POINTS_PER_TRACE = 400
MAX_TABLE_ROWS = 200  # alarm table rows shown; the JSON summary has them all
MAX_SPANS = 100  # shaded spans per figure (closer spans are merged for display)
_F4_MAX = float(np.finfo(np.float32).max)

ALARM_FILL = "rgba(214, 39, 40, 0.18)"
TRUTH_FILL = "rgba(31, 119, 180, 0.16)"
_LINE_COLOURS = [
    "#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2",
    "#7f7f7f", "#bcbd22", "#17becf", "#d62728", "#393b79", "#637939",
]  # fmt: skip


@dataclass
class ReportInput:
    """Everything one report shows.

    log_facts:        ``Log.summary()`` of the analysed log.
    profile_text:     the profile as TOML text.
    profile_source:   where the profile came from (a path, or "embedded").
    model:            ``Model.describe()`` (empty dict when no model is used).
    logscan_version:  version string of logscan.
    t:                (N,) analysis grid, seconds since the log's start.
    results:          one DetectorResult per detector that ran (``detectors/base.py``).
    truth_events:     ground-truth fault events: dicts with kind, target, start (or t_start),
                      end (or t_end; None: until the end of the log), magnitude (optional), or
                      ``logscan.scoring.FaultEvent`` objects. Empty: the log has no truth.
    matches:          per alarm, in the order of :func:`flat_alarms` (results in order, each
                      result's alarms in order): ``{"event": index into truth_events or None,
                      "latency_s": float or None}``. None: computed with
                      :func:`report_matches` when the log has truth.
    verdict:          "no alarms", "N alarms" or "partial input".
    warnings:         run-level warnings shown under the verdict.
    """

    log_facts: dict
    profile_text: str
    profile_source: str
    model: dict
    logscan_version: str
    t: np.ndarray
    results: list
    truth_events: list = field(default_factory=list)
    matches: list[dict] | None = None
    verdict: str = "no alarms"
    warnings: list[str] = field(default_factory=list)


# --- alarms and ground truth ------------------------------------------------------------------


def flat_alarms(results: Sequence) -> list:
    """All alarms of all results, results in order, each result's alarms in order."""
    return [alarm for result in results for alarm in getattr(result, "alarms", [])]


def _event_view(event: Any, index: int, t_end: float) -> dict:
    """A truth event (dict or FaultEvent) as {index, kind, target, start, end, magnitude, label}."""
    if isinstance(event, Mapping):
        start = event.get("start", event.get("t_start"))
        end = event.get("end", event.get("t_end"))
        kind, target = event.get("kind", ""), event.get("target", "")
        magnitude = event.get("magnitude")
    else:
        start, end = getattr(event, "t_start", None), getattr(event, "t_end", None)
        kind, target = getattr(event, "kind", ""), getattr(event, "target", "")
        magnitude = getattr(event, "magnitude", None)
    start = float(start) if start is not None else math.nan
    open_ended = end is None
    end = t_end if open_ended else float(end)
    label = f"#{index} {kind} {target}".strip()
    return {
        "index": index,
        "kind": str(kind),
        "target": str(target),
        "start": start,
        "end": end,
        "open_ended": open_ended,
        "magnitude": magnitude,
        "label": label,
    }


def report_matches(results: Sequence, truth_events: Sequence, grace_s: float | None = None) -> list[dict]:
    """Per alarm of :func:`flat_alarms`: the ground-truth event it detected and its latency.

    Uses ``logscan.scoring.match_alarms`` (ALGORITHMS.md section 7); latency = alarm start -
    event start, clipped at 0 as in scoring.
    """
    from logscan import scoring

    events = scoring.events_from_truth(
        [e if isinstance(e, Mapping) else e.to_dict() for e in truth_events]
    )
    alarms = flat_alarms(results)
    grace = scoring.DEFAULT_GRACE_S if grace_s is None else grace_s
    _, alarm_event = scoring.match_alarms(events, alarms, grace)
    out = []
    for alarm, hit in zip(alarms, alarm_event):
        latency = None if hit is None else max(float(alarm.start) - events[hit].t_start, 0.0)
        out.append({"event": hit, "latency_s": latency})
    return out


def _number(value: Any, digits: int = 4) -> str:
    if value is None:
        return "—"
    try:
        x = float(value)
    except (TypeError, ValueError):
        return str(value)
    if math.isnan(x):
        return "NaN"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:.{digits}g}"


def _alarm_rows(report: ReportInput, events: list[dict], has_truth: bool) -> list[dict]:
    alarms = flat_alarms(report.results)
    matches = report.matches
    if has_truth and matches is None and alarms:
        matches = report_matches(report.results, events)
    rows = []
    for i, alarm in enumerate(alarms[:MAX_TABLE_ROWS]):
        start, end = float(alarm.start), float(alarm.end)
        peak = getattr(alarm, "peak_value", None)
        threshold = getattr(alarm, "peak_threshold", None)
        ratio = getattr(alarm, "peak_ratio", None)
        row = {
            "index": i,
            "detector": str(getattr(alarm, "detector", "")),
            "signal": str(getattr(alarm, "signal", "")),
            "start": f"{start:.3f}",
            "end": f"{end:.3f}",
            "duration": f"{end - start:.3f}",
            "peak": _number(peak),
            "threshold": _number(threshold),
            "ratio": _number(ratio, 3),
            "bound": str(getattr(alarm, "bound", "")),
            "event": None,
            "latency": None,
        }
        if has_truth and matches is not None and i < len(matches):
            match = matches[i] or {}
            hit = match.get("event")
            if hit is not None and 0 <= int(hit) < len(events):
                row["event"] = events[int(hit)]["label"]
                row["latency"] = _number(match.get("latency_s"), 3)
        rows.append(row)
    return rows


# --- figures ------------------------------------------------------------------------------------


@dataclass
class _Trace:
    """One line to draw: full-resolution series, its weight in the point budget, its style."""

    name: str
    y: np.ndarray
    keep: np.ndarray
    weight: float
    style: dict
    varying: bool = True


@dataclass
class _Figure:
    title: str
    y_title: str
    traces: list[_Trace]
    spans: dict[str, list[tuple[float, float]]]  # "alarm" / "ground truth" -> [(start, end)]
    log_y: bool = False
    caption: str = ""
    hlines: list[tuple[float, str]] = field(default_factory=list)  # (y, name)
    y_range: tuple[float, float] | None = None  # initial view; None: autorange



def _merge_spans(spans: Sequence[tuple[float, float]], min_width: float, min_gap: float) -> list:
    """Spans widened to ``min_width`` and merged where closer than ``min_gap``, at most MAX_SPANS."""
    if not spans:
        return []
    arr = np.asarray(spans, dtype=np.float64).reshape(-1, 2)
    arr = arr[np.isfinite(arr).all(axis=1)]
    if arr.size == 0:
        return []
    arr = arr[np.argsort(arr[:, 0], kind="stable")]
    starts = arr[:, 0]
    ends = np.maximum(arr[:, 1], starts + min_width)
    gap = min_gap
    while True:
        reach = np.maximum.accumulate(ends)
        new = np.ones(starts.size, dtype=bool)
        new[1:] = starts[1:] > reach[:-1] + gap
        first = np.flatnonzero(new)
        if first.size <= MAX_SPANS:
            break
        gap = max(gap * 2.0, min_width)
    return list(zip(starts[first].tolist(), np.maximum.reduceat(ends, first).tolist()))


def _is_piecewise_flat(y: np.ndarray, limit: int = 64) -> bool:
    changes = np.count_nonzero(y[1:] != y[:-1]) if y.size > 1 else 0
    return changes <= limit


def _defined_samples(t: np.ndarray, y: np.ndarray, keep: np.ndarray) -> tuple:
    """The samples where ``y`` is defined, with one NaN where they are far apart in time.

    Statistics are NaN on steps where they are not evaluated (a 10 Hz group's NIS on a 100 Hz
    grid is NaN 9 steps in 10); drawn as is, such a line would be all gaps. So only defined
    samples are drawn, joined, except across a gap longer than 3x their typical spacing, where a
    NaN still breaks the line. ``keep`` (grid indices) is mapped onto the returned samples.
    """
    defined = ~np.isnan(y)
    if defined.all():
        return t, y, keep
    idx = np.flatnonzero(defined)
    tc, yc = t[idx], y[idx]
    if idx.size >= 2:
        spacing = np.diff(tc)
        breaks = np.flatnonzero(spacing > 3.0 * np.median(spacing)) + 1
        tc = np.insert(tc, breaks, 0.5 * (tc[breaks - 1] + tc[breaks]))
        yc = np.insert(yc, breaks, np.nan)
    kept = np.clip(np.searchsorted(tc, t[keep]), 0, max(tc.size - 1, 0)) if tc.size else keep[:0]
    return tc, yc, np.unique(kept)


def _display_values(y: np.ndarray) -> np.ndarray:
    """float32 values for the browser: inf -> NaN (a gap), finite values clipped to float32."""
    out = np.asarray(y, dtype=np.float64).copy()
    out[np.isinf(out)] = np.nan
    np.clip(out, -_F4_MAX, _F4_MAX, out=out)
    return out.astype(np.float32)


def _span_trace(name: str, spans: list, fill: str) -> dict:
    """A filled polygon per span on the hidden overlay axis y2 (0..1 covers the plot height)."""
    arr = np.asarray(spans, dtype=np.float64).reshape(-1, 2)
    x = np.column_stack([arr[:, 0], arr[:, 0], arr[:, 1], arr[:, 1], np.full(len(arr), np.nan)])
    y = np.tile(np.array([0.0, 1.0, 1.0, 0.0, np.nan]), (len(arr), 1))
    return {
        "type": "scatter",
        "name": name,
        "legendgroup": name,
        "x": x.ravel().astype(np.float32),
        "y": y.ravel().astype(np.float32),
        "yaxis": "y2",
        "mode": "lines",
        "line": {"width": 0},
        "fill": "toself",
        "fillcolor": fill,
        "hoverinfo": "skip",
        "showlegend": True,
    }


def _allocate(figures: list[_Figure], budget: int) -> dict[int, int]:
    """Points per varying trace (by id), proportional to weight, within [MIN, DEFAULT_MAX]."""
    varying = [tr for fig in figures for tr in fig.traces if tr.varying]
    total_weight = sum(tr.weight for tr in varying) or 1.0
    return {
        id(tr): int(min(DEFAULT_MAX_POINTS, max(MIN_POINTS_PER_TRACE, budget * tr.weight / total_weight)))
        for tr in varying
    }


def _figure_json(fig: _Figure, t: np.ndarray, points: dict[int, int]) -> str:
    import plotly.graph_objects as go

    data: list[dict] = []
    span_fills = {"alarm": ALARM_FILL, "ground truth": TRUTH_FILL}
    for name, spans in fig.spans.items():
        if spans:
            data.append(_span_trace(name, spans, span_fills.get(name, ALARM_FILL)))
    t0, t1 = (float(t[0]), float(t[-1])) if t.size else (0.0, 0.0)
    for y_value, name in fig.hlines:
        data.append({
            "type": "scatter", "name": name, "x": [t0, t1], "y": [y_value, y_value],
            "mode": "lines", "line": {"color": "#d62728", "dash": "dash", "width": 1},
        })  # fmt: skip
    for trace in fig.traces:
        max_points = points.get(id(trace), DEFAULT_MAX_POINTS)
        x, y, keep = _defined_samples(t, trace.y, trace.keep)
        idx = decimate_indices(y, max_points, keep=keep, simplify_flat=True)
        data.append({
            "type": "scatter",
            "name": trace.name,
            "x": x[idx].astype(np.float32),
            "y": _display_values(y[idx]),
            "mode": "lines",
            "hovertemplate": "%{y:.6g} at %{x:.3f} s",
            **trace.style,
        })  # fmt: skip
    layout = {
        "title": {"text": fig.title, "font": {"size": 14}},
        "height": 360,
        "margin": {"l": 70, "r": 20, "t": 40, "b": 80},
        "xaxis": {"title": {"text": "time since log start (s)"}, "gridcolor": "#eee", "zeroline": False},
        "yaxis": {"title": {"text": fig.y_title}, "gridcolor": "#eee", "type": "log" if fig.log_y else "linear",
                  **({"range": list(fig.y_range)} if fig.y_range else {})},
        "yaxis2": {"overlaying": "y", "range": [0, 1], "visible": False, "fixedrange": True},
        "legend": {"orientation": "h", "y": -0.22, "yanchor": "top"},
        "hovermode": "closest",
        "plot_bgcolor": "white",
        "paper_bgcolor": "white",
        "template": {},
    }
    figure = go.Figure(data=data, layout=layout, skip_invalid=False)
    return _escape_json(figure.to_json(validate=False, remove_uids=True))


def _escape_json(text: str) -> str:
    """JSON safe inside an HTML <script> element: no ``<``, ``>``, ``&`` or line separators."""
    return (
        text.replace("<", "\\u003c")
        .replace(">", "\\u003e")
        .replace("&", "\\u0026")
        .replace("\u2028", "\\u2028")
        .replace("\u2029", "\\u2029")
    )


def _bands(result: Any, n: int, problems: list[str]) -> dict[str, tuple[np.ndarray | None, np.ndarray | None]]:
    """statistic -> (upper, lower) (N,) arrays from ``result.thresholds`` (name -> Band); a side
    that is absent, all non-finite or off the grid is None (the latter reported in ``problems``)."""
    out = {}
    for name, band in (getattr(result, "thresholds", None) or {}).items():
        sides = []
        for side in ("upper", "lower"):
            value = getattr(band, side, None)
            arr = None if value is None else np.asarray(value, dtype=np.float64)
            if arr is not None and arr.ndim == 0:
                arr = np.full(n, float(arr))
            if arr is not None and arr.shape != (n,):
                problems.append(f"{side} threshold of {name!r} has shape {arr.shape}, the grid has {n} steps: not drawn")
                arr = None
            sides.append(arr if arr is not None and np.isfinite(arr).any() else None)
        out[name] = (sides[0], sides[1])
    return out


def _labels_for(key: str, width: int, result: Any, model: Mapping) -> list[str]:
    info = getattr(result, "info", None) or {}
    for candidate in (info.get(f"{key}_labels"), info.get("state_names"), model.get("states")):
        if isinstance(candidate, (list, tuple)) and len(candidate) == width:
            return [str(c) for c in candidate]
    return [f"{key}[{i}]" for i in range(width)]


def _wants_log_axis(columns: Sequence[np.ndarray]) -> bool:
    """True when every defined value is positive and they span more than three decades."""
    with np.errstate(invalid="ignore"):
        lows = [float(np.fmin.reduce(c)) for c in columns if c.size]  # fmin/fmax skip NaN
        highs = [float(np.fmax.reduce(c)) for c in columns if c.size]
    lows, highs = [v for v in lows if not math.isnan(v)], [v for v in highs if not math.isnan(v)]
    if not lows or min(lows) <= 0:
        return False
    return max(highs) / min(lows) > 1e3


def _judged_range(values: np.ndarray, upper: np.ndarray | None, lower: np.ndarray | None, peaks: list[float]):
    """Initial y range for a statistic and its band, when a settling transient (warm-up, the first
    adaptive windows) would otherwise squash the rest of the plot; None: plotly's autorange.

    Covers the 0.1-99.9 percentiles of the statistic and band where a threshold is defined, and
    every alarm's peak value; double-clicking the plot restores the full range.
    """
    defined = [band for band in (upper, lower) if band is not None]
    if not defined:
        return None
    judged = np.logical_or.reduce([np.isfinite(band) for band in defined])
    parts = np.concatenate([values[judged], *[band[judged] for band in defined]])
    parts, everything = parts[np.isfinite(parts)], values[np.isfinite(values)]
    if parts.size == 0 or everything.size == 0:
        return None
    lo, hi = np.percentile(parts[:: max(parts.size // 1_000_000, 1)], [0.1, 99.9])  # a view, not a statistic
    finite_peaks = [p for p in peaks if math.isfinite(p)]
    lo, hi = float(min([lo, *finite_peaks])), float(max([hi, *finite_peaks]))
    span = hi - lo
    full_lo = min(float(everything.min()), *(float(np.nanmin(b)) for b in defined))
    full_hi = max(float(everything.max()), *(float(np.nanmax(b)) for b in defined))
    if full_lo >= lo - span and full_hi <= hi + span:
        return None  # nothing far outside: autorange shows everything well
    pad = 0.05 * span if span > 0 else max(abs(hi), 1.0) * 0.05
    return (lo - pad, hi + pad)


def _detector_figures(
    result: Any, t: np.ndarray, truth_spans: list, model: Mapping, problems: list[str]
) -> list[_Figure]:
    """The figures of one detector section.

    Statistics with only positive upper thresholds (chi-square tests such as NIS, per group and
    overall) share one "statistic / threshold" figure; otherwise each statistic gets its own
    figure with its threshold band (e.g. e_x and e_v of the encoded checks). Extras follow
    (:func:`_extra_figures`). Alarm spans of the statistics drawn and ground-truth spans are
    shaded on every figure.
    """
    n = t.size
    dt = float(np.median(np.diff(t))) if n > 1 else 0.0
    span_len = float(t[-1] - t[0]) if n > 1 else 0.0
    min_width, min_gap = max(dt, span_len / 2000.0), span_len / 5000.0
    alarms = list(getattr(result, "alarms", []))
    series = {}
    for name, values in (getattr(result, "series", None) or {}).items():
        arr = np.asarray(values, dtype=np.float64)
        if arr.shape != (n,):
            problems.append(f"statistic {name!r} has shape {arr.shape}, the grid has {n} steps: not drawn")
            continue
        series[name] = arr
    bands = _bands(result, n, problems)
    no_band = (None, None)

    def alarm_spans(names: Sequence[str]) -> list:
        """Spans of the alarms on these statistics (all alarms if none names a drawn statistic)."""
        named = [a for a in alarms if getattr(a, "signal", "") in series]
        chosen = [a for a in named if a.signal in names] if named else alarms
        return [(float(a.start), float(a.end)) for a in chosen]

    def shading(names: Sequence[str]) -> dict:
        return {"alarm": _merge_spans(alarm_spans(names), min_width, min_gap), "ground truth": truth_spans}

    def positive_upper_only(name: str) -> bool:
        upper, lower = bands.get(name, no_band)
        return upper is not None and lower is None and bool(np.nanmin(upper) > 0)

    figures: list[_Figure] = []
    if len(series) >= 2 and all(positive_upper_only(name) for name in series):
        traces = []
        for i, (name, values) in enumerate(series.items()):
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = values / bands[name][0]
            traces.append(_Trace(
                name, ratio, edge_indices(t, alarm_spans([name])), 1.0,
                {"line": {"color": _LINE_COLOURS[i % len(_LINE_COLOURS)], "width": 1.2}},
            ))  # fmt: skip
        figures.append(_Figure(
            title=f"{result.detector}: statistic / threshold", y_title="statistic / threshold",
            traces=traces, spans=shading(list(series)),
            log_y=_wants_log_axis([tr.y for tr in traces]),
            caption="Each statistic divided by its threshold; above 1 is an exceedance.",
            hlines=[(1.0, "threshold")],
        ))  # fmt: skip
    else:
        for name, values in series.items():
            keep = edge_indices(t, alarm_spans([name]))
            traces = [_Trace(name, values, keep, 1.0, {"line": {"color": "#1f77b4", "width": 1.2}})]
            for label, band in zip(("upper threshold", "lower threshold"), bands.get(name, no_band)):
                if band is not None:
                    traces.append(_Trace(
                        label, band, keep, 0.5, {"line": {"color": "rgba(214, 39, 40, 0.75)", "width": 1}},
                        varying=not _is_piecewise_flat(band),
                    ))  # fmt: skip
            peaks = [float(a.peak_value) for a in alarms if getattr(a, "signal", "") == name]
            y_range = _judged_range(values, *bands.get(name, no_band), peaks)
            figures.append(_Figure(f"{result.detector}: {name}", name, traces, shading([name]), y_range=y_range))
    figures.extend(_extra_figures(result, n, model, shading(list(series)), problems))
    return figures


def _columns(arr: np.ndarray, block: int = 65_536) -> np.ndarray:
    """(N, k) -> contiguous (k, N), transposed in blocks of rows (cache-friendly: a plain
    transposing copy of a long array is several times slower)."""
    out = np.empty((arr.shape[1], arr.shape[0]), dtype=np.float64)
    for start in range(0, arr.shape[0], block):
        out[:, start : start + block] = arr[start : start + block].T
    return out


def _extra_figures(result: Any, n: int, model: Mapping, spans: dict, problems: list[str]) -> list[_Figure]:
    """An (N, k) extra is one figure (e.g. the coding vector, a line per state); (N,) extras
    named "<prefix>.<kind>" share one figure per kind (e.g. "nis.accel.per_dof")."""
    groups: dict[str, list[tuple[str, np.ndarray]]] = {}
    for key, values in (getattr(result, "extras", None) or {}).items():
        arr = np.asarray(values, dtype=np.float64)
        if arr.ndim not in (1, 2) or arr.shape[0] != n:
            problems.append(f"extra series {key!r} has shape {np.shape(values)}, the grid has {n} steps: not drawn")
            continue
        if arr.ndim == 2:
            labels = _labels_for(key, arr.shape[1], result, model)
            rows = _columns(arr)
            groups.setdefault(key, []).extend(zip(labels, rows))
        else:
            prefix, _, kind = key.rpartition(".")
            groups.setdefault(kind if prefix else key, []).append((prefix or key, arr))
    figures = []
    for kind, columns in groups.items():
        traces = [
            _Trace(
                label, column, np.zeros(0, np.int64), 0.25,
                {"line": {"color": _LINE_COLOURS[j % len(_LINE_COLOURS)], "width": 1}},
                varying=not _is_piecewise_flat(column),
            )
            for j, (label, column) in enumerate(columns)
        ]  # fmt: skip
        log_y = _wants_log_axis([column for _, column in columns])
        figures.append(_Figure(f"{result.detector}: {kind}", kind, traces, spans, log_y=log_y))
    return figures


# --- page ---------------------------------------------------------------------------------------


def _info_rows(info: Mapping) -> list[tuple[str, str]]:
    rows = []
    for key, value in info.items():
        if isinstance(value, np.ndarray):
            value = value.tolist()
        text = value if isinstance(value, str) else json.dumps(value, default=str)
        if len(text) > 400:
            text = text[:400] + " …"
        rows.append((str(key), text))
    return rows


def _time_text(ns: Any) -> str:
    if ns is None:
        return "—"
    ns = int(ns)
    if ns > 10**15:  # absolute epoch time (later than 1970-01-12)
        stamp = _dt.datetime.fromtimestamp(ns / 1e9, tz=_dt.timezone.utc)
        return stamp.isoformat(timespec="milliseconds").replace("+00:00", " UTC")
    return f"{ns / 1e9:.3f} s"


def _log_view(facts: Mapping) -> dict:
    return {
        "file": str(facts.get("file", "")),
        "name": os.path.basename(str(facts.get("file", ""))) or "log",
        "format": str(facts.get("format", "")),
        "start": _time_text(facts.get("start_ns")),
        "end": _time_text(facts.get("end_ns")),
        "duration": _number(facts.get("duration_s"), 6),
        "n_topics": len(facts.get("topics") or {}),
        "n_channels": len(facts.get("channels") or {}),
        "partial": bool(facts.get("partial")),
        "partial_reason": str(facts.get("partial_reason", "")),
        "skipped": [
            f"{s.get('what', '')}: {s.get('why', '')} (x{s.get('count', 1)})"
            for s in facts.get("skipped") or []
        ],
        "warnings": [str(w) for w in facts.get("warnings") or []],
        "topics": sorted(str(name) for name in (facts.get("topics") or {})),
    }


def _verdict_class(verdict: str, n_alarms: int) -> str:
    if "partial" in verdict:
        return "partial"
    return "alarm" if n_alarms else "ok"


def _plotly_js() -> str:
    from plotly.offline import get_plotlyjs

    js = get_plotlyjs()
    # "</script" inside the inline script would end it early; "<\/" is the same string in JS
    return js.replace("</script", "<\\/script").replace("</SCRIPT", "<\\/SCRIPT")


def _install_plotly_js(directory: Path, report_path: Path) -> str:
    """Write plotly.min.js into ``directory`` (if absent or different); URL relative to the report."""
    if directory.exists() and not directory.is_dir():
        raise InputError("--plotlyjs must be a directory", path=str(directory), hint="give a directory path or 'embed'")
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the plotly.js directory: {exc.strerror}", path=str(directory)) from None
    from plotly.offline import get_plotlyjs

    payload = get_plotlyjs().encode("utf-8")
    target = directory / PLOTLY_JS_NAME
    if not target.is_file() or target.read_bytes() != payload:
        write_atomic(target, payload)
    relative = os.path.relpath(target.resolve(), report_path.resolve().parent)
    return urllib.parse.quote(Path(relative).as_posix())


@functools.lru_cache(maxsize=1)
def _environment():
    import jinja2

    import logscan.templates

    return jinja2.Environment(
        loader=jinja2.FileSystemLoader(Path(logscan.templates.__file__).parent),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
    )


def render_html(report: ReportInput, *, plotlyjs_src: str | None = None, point_budget: int = POINT_BUDGET) -> str:
    """The report page as a string; plotly.js inline, or from ``plotlyjs_src`` (a URL) if given."""
    t = np.asarray(report.t, dtype=np.float64)
    t_end = float(t[-1]) if t.size else 0.0
    events = [_event_view(e, i, t_end) for i, e in enumerate(report.truth_events or [])]
    has_truth = bool(events) or bool(report.log_facts.get("has_truth"))
    truth_spans = _merge_spans([(e["start"], e["end"]) for e in events], 0.0, 0.0)

    sections, figures = [], []
    for result in report.results:
        problems: list[str] = []
        figs = _detector_figures(result, t, truth_spans, report.model or {}, problems)
        sections.append({
            "detector": str(getattr(result, "detector", "detector")),
            "n_alarms": len(getattr(result, "alarms", [])),
            "warnings": [str(w) for w in getattr(result, "warnings", [])] + problems,
            "coverage": str((getattr(result, "info", None) or {}).get("coverage", "")),
            "info": _info_rows(getattr(result, "info", None) or {}),
            "figures": [],
        })  # fmt: skip
        for fig in figs:
            fig_id = f"fig-{len(figures)}"
            sections[-1]["figures"].append({"id": fig_id, "title": fig.title, "caption": fig.caption})
            figures.append((fig_id, fig))
    points = _allocate([fig for _, fig in figures], point_budget)
    figure_json = "[" + ",".join(
        f'{{"id":"{fig_id}","figure":{_figure_json(fig, t, points)}}}' for fig_id, fig in figures
    ) + "]"

    alarms = flat_alarms(report.results)
    rows = _alarm_rows(report, events, has_truth)
    model = report.model or {}
    return _environment().get_template("report.html.j2").render(
        title=f"logscan report: {_log_view(report.log_facts)['name']}",
        log=_log_view(report.log_facts),
        profile_text=report.profile_text or "",
        profile_source=str(report.profile_source or ""),
        model={
            "name": str(model.get("name", "")),
            "states": [str(s) for s in model.get("states", [])],
            "inputs": [str(s) for s in model.get("inputs", [])],
            "groups": [str(g) for g in (model.get("groups") or {})],
            "params": _info_rows(model.get("params") or {}),
        },
        version=str(report.logscan_version),
        verdict=str(report.verdict),
        verdict_class=_verdict_class(str(report.verdict), len(alarms)),
        n_alarms=len(alarms),
        warnings=[str(w) for w in report.warnings or []],
        rows=rows,
        rows_hidden=max(len(alarms) - len(rows), 0),
        has_truth=has_truth,
        events=[{**e, "start": f"{e['start']:.3f}", "end": f"{e['end']:.3f}" + (" (open)" if e["open_ended"] else ""),
                 "magnitude": "—" if e["magnitude"] is None else str(e["magnitude"])} for e in events],
        sections=sections,
        n_figures=len(figures),
        figure_json=figure_json,
        plotlyjs_inline=None if plotlyjs_src else _plotly_js(),
        plotlyjs_src=plotlyjs_src,
        grid={"n": int(t.size), "dt": _number(float(np.median(np.diff(t))) if t.size > 1 else None)},
    )  # fmt: skip


def render_report(report: ReportInput, path: str | os.PathLike, *, plotlyjs: str | os.PathLike = "embed") -> None:
    """Write the report for ``report`` to ``path`` atomically.

    plotlyjs: "embed" puts plotly.js inside the page (one self-contained file, ~5 MB); a
    directory path writes plotly.min.js there once and references it relatively (each report
    then stays a few hundred kilobytes).
    """
    target = Path(path)
    src = None if str(plotlyjs) == "embed" else _install_plotly_js(Path(plotlyjs), target)
    write_atomic(target, render_html(report, plotlyjs_src=src))


__all__ = ["ReportInput", "flat_alarms", "render_html", "render_report", "report_matches"]
