"""The training report of `logscan train`: the tables document -> one offline HTML page.

Shows what the tables file holds and how each number was chosen: the training logs, per A-TFM
group the lookup table (eps and e per mode value and sensor, the knee before the monotone envelope
where the envelope raised it), eps against the mode value, and per sensor and mode value the
e/w-vs-eps curves of every trained window with their knees; then the other detectors' trained
values.

The page follows the analysis report's rules (`logscan.report.page`): ``templates/training.html.j2``
rendered with autoescaping on (group, sensor and log names come from untrusted logs and profiles),
plotly.js embedded once, the figures' JSON escaped in one ``application/json`` block
(`plotly_json.spec_json`, names through `plot_text`). Its look, its JavaScript error recorder and
its drawing script are the analysis report's own: taken from ``templates/report.html.j2`` at render
time (`shared_parts`), so both pages stay alike.
"""

from __future__ import annotations

import functools
import json
import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from logscan.detectors.base import decode_state_value
from logscan.report.context import number_text
from logscan.report.page_assets import environment, plotly_js
from logscan.report.plotly_json import plot_text, spec_json
from logscan.training.calibration import calibration_failures

CURVE_HEIGHT = 260  # px, the small e/w-vs-eps figures (three to a row)
TABLE_HEIGHT = 340  # px, eps against the mode value
SHORT_HASH = 12  # characters of a SHA-256 shown (the whole one in the cell's title)
KNEE_LIMIT = 0.5  # e/w of a knee stays below this (logscan.redundant.tfm.KNEE_MAX_RATIO)
COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f")
SMALL_MODEBAR_REMOVED = ["toImage", "sendDataToCloud", "lasso2d", "select2d", "zoomIn2d", "zoomOut2d", "autoScale2d"]
AXIS = {"gridcolor": "#eee", "zeroline": False, "exponentformat": "e"}

# the analysis report's pieces this page reuses, found in templates/report.html.j2 by these patterns
_SHARED = {
    "style": re.compile(r"<style>.*?</style>", re.S),
    "recorder": re.compile(r"<script>\s*/\* Records script errors.*?</script>", re.S),
    "drawing": re.compile(r"<script>\s*/\* Draws every figure from the JSON block above.*?</script>", re.S),
}


@functools.lru_cache(maxsize=1)
def shared_parts() -> dict[str, str]:
    """The analysis report's <style> block, error recorder and drawing script (each "" when the
    template no longer has it: the tests check all three are found)."""
    env = environment()
    source = env.loader.get_source(env, "report.html.j2")[0]
    parts = {}
    for key, pattern in _SHARED.items():
        match = pattern.search(source)
        parts[key] = match.group(0) if match else ""
    return parts


# --- numbers and names --------------------------------------------------------------------------


def _num(value: Any, digits: int = 4) -> str:
    return number_text(value, digits)


def _size_text(n_bytes: Any) -> str:
    try:
        n = int(n_bytes)
    except (TypeError, ValueError):
        return "—"
    for unit, scale in (("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= scale:
            return f"{n / scale:.1f} {unit} ({n:,} bytes)"
    return f"{n} bytes"


def _short(text: Any, n: int = SHORT_HASH) -> str:
    text = "" if text is None else str(text)
    return text if len(text) <= n else text[:n] + "…"


def _value_text(value: Any) -> str:
    """A trained value in a table cell: numbers in 6 digits, short arrays in full, long ones summed up."""
    if isinstance(value, np.ndarray):
        if value.size <= 12:
            return (
                "["
                + ", ".join(_num(x, 6) for x in value.ravel())
                + "]"
                + (f" (shape {value.shape})" if value.ndim > 1 else "")
            )
        finite = value[np.isfinite(value)] if value.dtype.kind == "f" else value
        span = (
            f", {_num(finite.min(), 6)} to {_num(finite.max(), 6)}" if finite.size and value.dtype.kind in "fiu" else ""
        )
        return f"array {'×'.join(map(str, value.shape))} ({value.dtype}){span}"
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return str(value)
    if isinstance(value, (int, float, np.integer, np.floating)):
        return _num(value, 6)
    if isinstance(value, Mapping):
        return "; ".join(f"{k}: {_value_text(v)}" for k, v in value.items())
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_value_text(v) for v in value) + "]"
    return str(value)


def _param_rows(params: Mapping) -> list[tuple[str, str]]:
    return [(str(k), _value_text(v)) for k, v in sorted((params or {}).items())]


# --- A-TFM: the lookup table, eps against the mode value, the curves -------------------------------


def _table_rows(table: Mapping) -> list[dict]:
    """One row per mode value: per sensor {eps, e, knee (None unless the envelope raised eps)}."""
    eps, e = np.asarray(table["eps"], float), np.asarray(table["e"])
    raw = np.asarray(table.get("eps_knee", eps), float)
    rows = []
    for r, mode in enumerate(np.asarray(table["modes"], float)):
        cells = []
        for i in range(len(table["sensors"])):
            raised = np.isfinite(raw[r, i]) and eps[r, i] > raw[r, i]
            cells.append({"eps": _num(eps[r, i]), "e": str(int(e[r, i])), "knee": _num(raw[r, i]) if raised else None})
        rows.append({"mode": _num(mode), "cells": cells})
    return rows


def _eps_mode_figure(group: str, table: Mapping) -> str:
    """eps (after the envelope) against the mode value, a line per sensor; the knees as hollow markers."""
    modes = [float(m) for m in np.asarray(table["modes"], float)]
    eps, raw = np.asarray(table["eps"], float), np.asarray(table.get("eps_knee", table["eps"]), float)
    data = []
    for i, sensor in enumerate(table["sensors"]):
        color = COLORS[i % len(COLORS)]
        name = plot_text(sensor)
        data.append({
            "type": "scatter", "mode": "lines+markers", "name": name, "legendgroup": name,
            "x": modes, "y": [float(v) for v in eps[:, i]], "line": {"color": color, "width": 2},
            "marker": {"color": color, "size": 8},
            "hovertemplate": "mode %{x:.4g}: eps %{y:.4g}<extra>" + name + "</extra>",
        })  # fmt: skip
        data.append({
            "type": "scatter", "mode": "markers", "name": f"{name} knee (before envelope)", "legendgroup": name,
            "x": modes, "y": [float(v) for v in raw[:, i]],
            "marker": {"color": color, "size": 12, "symbol": "circle-open", "line": {"width": 2}},
            "hovertemplate": "mode %{x:.4g}: knee eps %{y:.4g}<extra>" + name + "</extra>",
        })  # fmt: skip
    layout = {
        "title": {"text": plot_text(f"{group}: eps per mode value (w = {table['w']})"), "font": {"size": 14}},
        "height": TABLE_HEIGHT,
        "margin": {"l": 70, "r": 20, "t": 40, "b": 50},
        "xaxis": {**AXIS, "title": {"text": "mode value"}},
        "yaxis": {**AXIS, "title": {"text": "eps"}, "rangemode": "tozero"},
        "legend": {"orientation": "v", "x": 1.02, "xanchor": "left", "y": 1},
        "hovermode": "closest",
        "plot_bgcolor": "white",
        "paper_bgcolor": "white",
        "template": {},
    }
    return spec_json(data, layout)


def _curve_figure(sensor: str, mode_text: str, curve: Mapping, windows: Sequence[int], w: int) -> str:
    """e/w against eps for each window, the knees marked (the detection window's emphasised), the
    diagonal from (0, 1) to (eps_max, 0) dashed and e/w = 0.5 dotted. The knees' labels stand in a
    column right of the rightmost knee (arrows to their knees), so they never overlap."""
    grid = np.asarray(curve["eps"], dtype=float)
    counts = np.asarray(curve["counts"], dtype=float).reshape(grid.size, len(windows))
    eps_max = float(grid[-1]) if grid.size and grid[-1] > 0 else 1.0
    windows = [int(window) for window in windows]
    color = {window: COLORS[k % len(COLORS)] for k, window in enumerate(windows)}
    data = []
    for k, window in enumerate(windows):
        data.append({
            "type": "scatter", "mode": "lines", "name": f"w={window}", "legendgroup": f"w={window}",
            "x": grid.astype(np.float32), "y": (counts[:, k] / window).astype(np.float32),
            "line": {"color": color[window], "width": 2.5 if window == w else 1.3},
            "hovertemplate": f"w={window}: " + "e/w %{y:.3f} at eps %{x:.4g}<extra></extra>",
        })  # fmt: skip
    knees = {int(k[0]): (float(k[1]), int(k[2])) for k in curve["knees"]}
    shown = [window for window in windows if window in knees]
    main = [window == w for window in shown]
    data.append(_knee_markers(knees, shown, main, color))
    column = min(max([knees[window][0] for window in shown], default=0.0) + 0.12 * eps_max, 0.7 * eps_max)
    annotations = _knee_labels(knees, shown, main, color, column)
    return spec_json(data, _curve_layout(sensor, mode_text, eps_max, annotations))


def _knee_markers(knees: dict, shown: list[int], main: list[bool], color: dict) -> dict:
    """The knees' markers (the detection window's a larger diamond)."""
    return {
        "type": "scatter", "mode": "markers", "name": "knees", "showlegend": False,
        "x": [knees[window][0] for window in shown],
        "y": [knees[window][1] / window for window in shown],
        "customdata": [[window, knees[window][1]] for window in shown],
        "marker": {
            "color": [color[window] for window in shown],
            "size": [13 if m else 8 for m in main],
            "symbol": ["diamond" if m else "circle" for m in main],
            "line": {"color": "black", "width": [1.5 if m else 0.5 for m in main]},
        },
        "hovertemplate": "w=%{customdata[0]} knee: eps %{x:.4g}, e %{customdata[1]}<extra></extra>",
    }  # fmt: skip


def _knee_labels(knees: dict, shown: list[int], main: list[bool], color: dict, column: float) -> list[dict]:
    """The knees' labels in a column at eps ``column``, arrows to their knees."""
    return [
        {"x": knees[window][0], "y": knees[window][1] / window, "xref": "x", "yref": "y",
         "text": f"<b>w={window} knee</b>" if m else f"w={window} knee",
         "showarrow": True, "arrowhead": 0, "arrowwidth": 1, "arrowcolor": "#999",
         "axref": "x", "ayref": "y", "ax": column, "ay": 0.62 - 0.13 * n, "xanchor": "left",
         "bgcolor": "rgba(255, 255, 255, 0.85)", "font": {"size": 10, "color": color[window]}}
        for n, (window, m) in enumerate(zip(shown, main))
    ]  # fmt: skip


def _curve_layout(sensor: str, mode_text: str, eps_max: float, annotations: list[dict]) -> dict:
    """The figure's axes, the diagonal and the e/w = 0.5 line, its labels and legend."""
    return {
        "title": {"text": plot_text(f"{sensor} · mode {mode_text}"), "font": {"size": 12}, "x": 0.01, "y": 0.97},
        "height": CURVE_HEIGHT,
        "margin": {"l": 45, "r": 10, "t": 30, "b": 38},
        "xaxis": {**AXIS, "title": {"text": "eps", "standoff": 2, "font": {"size": 11}}, "range": [0, eps_max]},
        "yaxis": {**AXIS, "title": {"text": "e/w", "standoff": 2, "font": {"size": 11}}, "range": [0, 1.05],
                  "tickvals": [0.2, 0.4, 0.6, 0.8, 1.0]},  # no "0" on top of the eps axis's "0"
        "shapes": [
            {"type": "line", "xref": "x", "yref": "y", "x0": 0, "y0": 1, "x1": eps_max, "y1": 0,
             "line": {"color": "#999", "width": 1, "dash": "dash"}},
            {"type": "line", "xref": "x", "yref": "y", "x0": 0, "y0": KNEE_LIMIT, "x1": eps_max, "y1": KNEE_LIMIT,
             "line": {"color": "#999", "width": 1, "dash": "dot"}},
        ],
        "annotations": annotations,
        # top right, above the diagonal, where no curve goes
        "legend": {"x": 0.99, "xanchor": "right", "y": 0.99, "yanchor": "top", "font": {"size": 9}, "tracegroupgap": 0},
        "modebar": {"remove": SMALL_MODEBAR_REMOVED},
        "hovermode": "closest",
        "plot_bgcolor": "white",
        "paper_bgcolor": "white",
        "font": {"size": 10},
        "template": {},
    }  # fmt: skip


def _curve_caption(sensor: str, mode_text: str, curve: Mapping, w: int) -> tuple[str, str]:
    """(caption, warning): what the figure shows and the detection window's knee; a warning when
    the knee cannot be trusted (no point below e/w = 0.5, or fewer samples than one window)."""
    knees = {int(k[0]): (float(k[1]), int(k[2])) for k in curve["knees"]}
    n = int(curve.get("n_samples", 0))
    knee = knees.get(int(w))
    at = f"w={w} knee eps {_num(knee[0])}, e {knee[1]}" if knee else f"no w={w} curve"
    caption = f"{sensor}, mode {mode_text}, {n} samples: {at}. Good: a sharp bend far below the diagonal."
    grid = np.asarray(curve["eps"], dtype=float)
    warning = ""
    if knee and grid.size and knee[0] >= float(grid[-1]):
        warning = "no point has e/w < 0.5: the knee is the grid's end, not a bend"
    elif n < int(w):
        warning = f"only {n} samples, fewer than one window of {w}: e is a count over all of them"
    return caption, warning


def _curve(table: Mapping, r: int, i: int) -> Mapping | None:
    curves = table.get("curves") or []
    return curves[r][i] if r < len(curves) and i < len(curves[r]) and curves[r][i] else None


def _atfm_groups(state: Mapping, figures: list[tuple[str, str]]) -> list[dict]:
    """The page's view of each A-TFM group; its figures appended to ``figures`` as (id, json)."""
    tables = decode_state_value((state.get("state") or {}).get("tables_")) or {}
    groups = []
    for group, table in tables.items():
        windows = [int(x) for x in table["windows"]]
        w = int(table["w"])
        table_id = f"tf-{len(figures)}"
        figures.append((table_id, _eps_mode_figure(group, table)))
        rows = []
        for r, mode in enumerate(np.asarray(table["modes"], float)):
            mode_text, views = _num(mode), []
            for i, sensor in enumerate(table["sensors"]):
                curve = _curve(table, r, i)
                if curve is None:  # a table without its curves: the lookup table only
                    continue
                fig_id = f"tf-{len(figures)}"
                figures.append((fig_id, _curve_figure(sensor, mode_text, curve, windows, w)))
                caption, warning = _curve_caption(sensor, mode_text, curve, w)
                views.append(
                    {"id": fig_id, "title": f"{sensor} at mode {mode_text}", "caption": caption, "warning": warning}
                )
            if views:
                rows.append({"mode": mode_text, "figures": views})
        groups.append({
            "name": group, "w": w, "windows": ", ".join(map(str, windows)), "sensors": list(table["sensors"]),
            "n_modes": len(table["modes"]), "rows": _table_rows(table), "table_figure": table_id, "curve_rows": rows,
        })  # fmt: skip
    return groups


def _other_detector(state: Mapping) -> dict:
    trained = [(str(k), _value_text(decode_state_value(v))) for k, v in (state.get("state") or {}).items()]
    return {
        "name": str(state.get("detector", "")),
        "schema_version": state.get("schema_version", "—"),
        "trained": trained,
        "params": _param_rows(state.get("params") or {}),
    }


# --- the page -------------------------------------------------------------------------------------


LOOKUP_KEYS = {"sensors", "modes", "eps", "e"}  # a transient-fault-model lookup table (logscan.redundant.tfm)


def _holds_lookup_tables(state: Mapping) -> bool:
    """Whether a trained state is lookup tables by group (A-TFM and its residual flavour), drawn
    with their curves; the page names no detector: it reads what the state holds."""
    tables = (state.get("state") or {}).get("tables_")
    return (
        isinstance(tables, dict)
        and bool(tables)
        and all(isinstance(table, dict) and LOOKUP_KEYS <= set(table) for table in tables.values())
    )


def _calibration_rows(calibration: Mapping | None) -> list[dict]:
    """The calibrated noise per group (`logscan.training.calibration`), as table cells."""
    rows = []
    for name, entry in ((calibration or {}).get("groups") or {}).items():
        after = ", ".join(f"{v:.3g}" for v in entry.get("noise_std") or [])
        rows.append({
            "name": str(name),
            "before": ", ".join(f"{v:.3g}" for v in entry.get("profile_noise_std") or []),
            "after": (after + (f"; logged std x {entry['noise_factor']:.3g}" if entry.get("logged_noise") else ""))
            if entry.get("calibrated")
            else "(not calibrated)",
            "updates": str(entry.get("updates", "")),
            "nis_before": f"{entry.get('mean_nis_per_output_before', float('nan')):.3g}",
            "nis_after": f"{entry.get('mean_nis_per_output_after', float('nan')):.3g}",
            "note": _calibration_note(entry),
        })  # fmt: skip
    return rows + _process_noise_rows(calibration)


def _calibration_note(entry: Mapping) -> str:
    """Why a group's noise sits where it does, when it is not simply calibrated."""
    if entry.get("nis_at_floor") is not None:
        return (
            f" (no noise_std brings it to 1: at the floor its NIS per output was {entry['nis_at_floor']:.3g}; "
            "the profile's kept)"
        )
    return " (at the floor: the process noise may be too large)" if entry.get("at_floor") else ""


def _process_noise_rows(calibration: Mapping | None) -> list[dict]:
    """The Q scale of each block of states (`logscan.training.process_noise`), as rows of the same table."""
    rows = []
    for name, entry in ((calibration or {}).get("process_noise_blocks") or {}).items():
        identified = bool(entry.get("identified"))
        rows.append({
            "name": f"process noise Q: {name} ({', '.join(map(str, entry.get('states') or []))})",
            "before": "model's Q x 1",
            "after": f"Q x {entry.get('scale', 1.0):.3g}" if identified else "Q x 1 (not identifiable from these logs)",
            "updates": "",
            "nis_before": "",
            "nis_after": "",
            "note": "",
        })  # fmt: skip
    return rows


def _tuning_rows(tuning: Mapping | None) -> list[dict]:
    """The tuned multipliers (`logscan.training.tuning`), with their false-alarm counts by value."""
    rows = []
    for detector, params in (tuning or {}).items():
        for param, entry in (params or {}).items():
            value = entry.get("value")
            grid, counts, f1 = entry.get("grid") or [], entry.get("false_alarms") or [], entry.get("f1") or []
            curve = ", ".join(f"{g:g}: {c}" for g, c in zip(grid, counts) if c) or "none at any value"
            at = grid.index(value) if value in grid else None
            free = entry.get("smallest_without_false_alarms")
            rows.append({
                "name": f"{detector}.{param}",
                "value": "—" if value is None else f"{value:g}",
                "free": "—" if free is None else f"{free:g}",
                "curve": curve,
                "f1": "—" if at is None or at >= len(f1) or f1[at] is None else f"{f1[at]:.2f}",
            })  # fmt: skip
    return rows


def window_text(window: dict | None) -> str:
    """'10 s to 25 s' (or 'from 10 s', 'up to 25 s') of a --start/--end window, else ''."""
    start, end = (window or {}).get("start_s"), (window or {}).get("end_s")
    if start is not None and end is not None:
        return f"{start:g} s to {end:g} s"
    return f"from {start:g} s" if start is not None else (f"up to {end:g} s" if end is not None else "")


def render_training_html(document: dict, plotlyjs_src: str | None = None) -> str:
    """The training report of a tables document (`logscan.training.train.tables_document`) as a string;
    plotly.js inside it, or from ``plotlyjs_src`` (a URL: `logscan.report.plotly_script`) if given."""
    figures: list[tuple[str, str]] = []
    atfm, others = [], []
    for state in document.get("detectors") or []:
        if _holds_lookup_tables(state):
            atfm.append({
                "name": str(state.get("detector", "")), "params": _param_rows(state.get("params") or {}),
                "groups": _atfm_groups(state, figures),
            })  # fmt: skip
        else:
            others.append(_other_detector(state))
    logs = [
        {"name": str(log.get("name", "")), "path": str(log.get("path", "")), "size": _size_text(log.get("bytes")),
         "sha": _short(log.get("sha256")), "sha_full": str(log.get("sha256", ""))}
        for log in document.get("training_logs") or []
    ]  # fmt: skip
    figure_json = "[" + ",".join(f'{{"id":{json.dumps(i)},"figure":{spec}}}' for i, spec in figures) + "]"
    fingerprint = document.get("profile_fingerprint") or ""
    return (
        environment()
        .get_template("training.html.j2")
        .render(
            title="logscan training report",
            version=str(document.get("logscan_version", "")),
            tables_format=f"{document.get('format', '')} v{document.get('schema_version', '')}",
            profile_name=str(document.get("profile_name") or "—"),
            fingerprint=_short(fingerprint) or "—",
            fingerprint_full=str(fingerprint),
            logs=logs,
            window=window_text(document.get("training_window")),
            atfm=atfm,
            others=others,
            n_detectors=len(document.get("detectors") or []),
            calibration=_calibration_rows(document.get("calibration")),
            calibration_failures=calibration_failures(document.get("calibration")),
            tuning=_tuning_rows(document.get("tuning")),
            n_figures=len(figures),
            figure_json=figure_json,
            plotlyjs_inline=None if plotlyjs_src else plotly_js(),
            plotlyjs_src=plotlyjs_src,
            shared=shared_parts(),
        )
    )
