"""Detector results as figure specs: statistic vs threshold band, alarm and truth spans, extras.

A `Figure` holds full-resolution traces and span lists; `logscan.report.plotly_json` decimates
and serialises it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from logscan.report.decimate import collapsed, edge_indices
from logscan.results import DetectorResult

MAX_SPANS = 100  # shaded spans per figure (closer spans are merged for display)
# values the initial y range's percentiles are taken from, evenly spread (`judged_range`): a 1-hour
# 100 Hz statistic and its band are a million values, whose percentiles cost more than drawing them
RANGE_SAMPLE = 100_000
STEP_SAMPLE = 10_000  # steps of the grid its typical step is the median of (`grid_step`)
MAX_NAMED_IN_CAPTION = 6  # a shared figure's caption says the words of this many statistics at most
ALARM_TAIL = "long enough is an alarm (shaded red)"

# Captions of the extra series' figures, by kind (the part of "<prefix>.<kind>" after the last dot,
# or the extra's own name); others get a generic "for context" caption.
EXTRA_CAPTIONS = {
    "per_dof": "Windowed NIS per measurement, per group. Normal: about 1 (the sensor agrees with the "
    "model's prediction within its noise); well above 1: that sensor disagrees with the prediction.",
    "coding_vector": "The coding vector: each state's weight in e_x (1/sigma, scaled). For context: no "
    "threshold applies; a weight that jumps shows the filter's uncertainty in that state changing.",
}
NO_BAND = (None, None)

LINE_COLOURS = [
    "#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2",
    "#7f7f7f", "#bcbd22", "#17becf", "#d62728", "#393b79", "#637939",
]  # fmt: skip


@dataclass
class Trace:
    """One line to draw: full-resolution series, its weight in the point budget, its style."""

    name: str
    y: np.ndarray
    keep: np.ndarray
    weight: float
    style: dict
    varying: bool = True
    t: np.ndarray | None = None  # the samples' own times, when they are not the whole grid
    max_points: int | None = None  # its share of the page's points at most (a smooth band needs few)


@dataclass
class Figure:
    title: str
    y_title: str
    traces: list[Trace]
    spans: dict[str, list[tuple[float, float]]]  # "alarm" / "ground truth" -> [(start, end)]
    log_y: bool = False
    caption: str = ""
    hlines: list[tuple[float, str]] = field(default_factory=list)  # (y, name)
    y_range: tuple[float, float] | None = None  # initial view; None: autorange
    subtitle: str = ""  # the statistic in plain words, under the title (`Detector.signal_label`)
    x_range: tuple[float, float] | None = None  # initial time range (s); None: the whole log


def merge_spans(spans: Sequence[tuple[float, float]], min_width: float, min_gap: float) -> list:
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
        # doubled from a positive start (the least space between two of them): a gap of 0 and no
        # width would never merge more of them
        apart = starts[1:] - reach[:-1]
        gap = max(gap * 2.0, min_width, float(apart[apart > 0].min()))
    return list(zip(starts[first].tolist(), np.maximum.reduceat(ends, first).tolist()))


def _is_piecewise_flat(y: np.ndarray, limit: int = 64) -> bool:
    y = collapsed(y)
    changes = np.count_nonzero(y[1:] != y[:-1]) if y.size > 1 else 0
    return changes <= limit


def _bands(
    result: DetectorResult, n: int, problems: list[str]
) -> dict[str, tuple[np.ndarray | None, np.ndarray | None]]:
    """statistic -> (upper, lower) (N,) arrays from ``result.thresholds`` (name -> Band); a side
    that is absent, all non-finite or off the grid is None (the latter reported in ``problems``)."""
    out = {}
    for name, band in result.thresholds.items():
        sides = []
        for side, value in (("upper", band.upper), ("lower", band.lower)):
            arr = None if value is None else _as_float(value)
            if arr is not None and arr.ndim == 0:
                arr = np.full(n, float(arr), dtype=arr.dtype)
            if arr is not None and arr.shape != (n,):
                problems.append(
                    f"{side} threshold of {name!r} has shape {arr.shape}, the grid has {n} steps: not drawn"
                )
                arr = None
            sides.append(arr if arr is not None and np.isfinite(collapsed(arr)).any() else None)
        out[name] = (sides[0], sides[1])
    return out


def _labels_for(key: str, width: int, result: DetectorResult, model: Mapping) -> list[str]:
    for candidate in (result.info.get(f"{key}_labels"), result.info.get("state_names"), model.get("states")):
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


def judged_range(values: np.ndarray, upper: np.ndarray | None, lower: np.ndarray | None, peaks: list[float]):
    """Initial y range for a statistic and its band, when a settling transient (warm-up, the first
    adaptive windows) would otherwise squash the rest of the plot; None: plotly's autorange.

    Covers the 0.1-99.9 percentiles of the statistic and band where a threshold is defined (of
    RANGE_SAMPLE of their values at most, evenly spread), and every alarm's peak value;
    double-clicking the plot restores the full range.
    """
    defined = [band for band in (upper, lower) if band is not None]
    if not defined or values.size == 0:
        return None
    everything, parts, bounds = _judged_parts(values, defined)
    n_parts = sum(part.size for part in parts)
    if n_parts == 0 or everything.size == 0:
        return None
    step = max(n_parts // RANGE_SAMPLE, 1)  # a view, not a statistic
    lo, hi = np.percentile(np.concatenate([part[::step] for part in parts]), [0.1, 99.9])
    finite_peaks = [p for p in peaks if math.isfinite(p)]
    lo, hi = float(min([lo, *finite_peaks])), float(max([hi, *finite_peaks]))
    span = hi - lo
    full_lo = min(low for low, _ in bounds)
    full_hi = max(high for _, high in bounds)
    if full_lo >= lo - span and full_hi <= hi + span:
        return None  # nothing far outside: autorange shows everything well
    pad = 0.05 * span if span > 0 else max(abs(hi), 1.0) * 0.05
    return (lo - pad, hi + pad)


def _judged_parts(values: np.ndarray, bands: list[np.ndarray]) -> tuple[np.ndarray, list, list]:
    """(the statistic's finite values, the parts `judged_range` takes percentiles of: the finite
    values of the statistic and of each band where a threshold is defined, and the least and
    greatest finite value of the statistic and of each whole band). A band whose least and
    greatest values are finite has neither NaN nor infinity, and a statistic too: then an array
    is its own finite part, two passes over it, no mask and no copy (the usual case)."""
    band_bounds = [_extremes(band) for band in bands]
    if all(math.isfinite(lo) and math.isfinite(hi) for lo, hi in band_bounds):  # judged everywhere
        finite = values if all(map(math.isfinite, _extremes(values))) else _finite(values)
        return finite, [finite, *bands], [_extremes(finite), *band_bounds]
    judged = np.logical_or.reduce([np.isfinite(band) for band in bands])
    finite = _finite(values)
    parts = [_finite(part[judged]) for part in (values, *bands)]
    return finite, parts, [_extremes(finite), *((float(np.fmin.reduce(b)), float(np.fmax.reduce(b))) for b in bands)]


def _extremes(values: np.ndarray) -> tuple[float, float]:
    """(least, greatest) of an array, NaN when it holds a NaN; (inf, -inf) when it is empty."""
    values = collapsed(values)
    return (float(values.min()), float(values.max())) if values.size else (math.inf, -math.inf)


def _finite(values: np.ndarray) -> np.ndarray:
    """``values`` without its NaN and infinities (``values`` itself when it has none)."""
    finite = np.isfinite(values)
    return values if finite.all() else values[finite]


def _as_float(values) -> np.ndarray:
    """``values`` as a float array without widening float32 (kept for drawing: every figure of a
    report is built before any is written, so a 1-hour log's float64 copies cost 100 MB and more)."""
    arr = np.asarray(values)
    return arr if arr.dtype in (np.float32, np.float64) else arr.astype(np.float64)


def _grid_series(result: DetectorResult, n: int, problems: list[str]) -> dict[str, np.ndarray]:
    """The result's statistics that lie on the grid; the others reported in ``problems``."""
    series = {}
    for name, values in result.series.items():
        arr = _as_float(values)
        if arr.shape != (n,):
            problems.append(f"statistic {name!r} has shape {arr.shape}, the grid has {n} steps: not drawn")
            continue
        series[name] = arr
    return series


def detector_figures(
    result: DetectorResult,
    t: np.ndarray,
    truth_spans: list,
    model: Mapping,
    problems: list[str],
    labels: Mapping[str, str] | None = None,
) -> list[Figure]:
    """The figures of one detector section; ``labels``: statistic -> its plain words, shown beside
    its name (a statistic's own figure: under the title; the shared ratio figure: in the caption).

    Statistics with only positive upper thresholds (chi-square tests such as NIS, per group and
    overall) share one "statistic / threshold" figure; otherwise each statistic gets its own
    figure with its threshold band (e.g. e_x and e_v of the encoded checks). Extras follow
    (:func:`_extra_figures`). Alarm spans of the statistics drawn and ground-truth spans are
    shaded on every figure.
    """
    n = t.size
    min_width, min_gap = span_limits(t)
    alarms = result.alarms
    series = _grid_series(result, n, problems)
    bands = _bands(result, n, problems)

    def chosen(names: Sequence[str]) -> list:
        """The alarms on these statistics (all alarms if none names a drawn statistic)."""
        named = [a for a in alarms if a.signal in series]
        return [a for a in named if a.signal in names] if named else alarms

    def alarm_spans(names: Sequence[str]) -> list:
        return [(float(a.start), float(a.end)) for a in chosen(names)]

    def kept(names: Sequence[str]) -> np.ndarray:
        """The grid samples every line of these statistics draws: each alarm's first, last and peak."""
        peaks = [(float(a.peak_time),) * 2 for a in chosen(names) if math.isfinite(a.peak_time)]
        return edge_indices(t, alarm_spans(names) + peaks)

    possible = merge_spans([(float(p.start), float(p.end)) for p in result.possible], min_width, min_gap)

    def shading(names: Sequence[str]) -> dict:
        spans = {"alarm": merge_spans(alarm_spans(names), min_width, min_gap), "ground truth": truth_spans}
        return {**spans, "possible fault": possible} if possible else spans

    if len(series) >= 2 and all(_positive_upper_only(bands.get(name, NO_BAND)) for name in series):
        figures = [_ratio_figure(result.detector, t, series, bands, kept, shading(list(series)))]
        named = [f"{name}: {labels[name]}" for name in series if (labels or {}).get(name)]
        if 0 < len(named) <= MAX_NAMED_IN_CAPTION:
            figures[0].caption += " The statistics: " + "; ".join(named) + "."
        elif named:  # many: the section's list says them, one per line
            figures[0].caption += " What each statistic means: the list above."
    else:
        figures = [
            _band_figure(result, t, name, values, bands.get(name, NO_BAND), kept, shading([name]))
            for name, values in series.items()
        ]
        for fig, name in zip(figures, series):
            fig.subtitle = (labels or {}).get(name, "")
    figures.extend(_extra_figures(result, n, model, shading(list(series)), problems))
    return figures


def span_limits(t: np.ndarray) -> tuple[float, float]:
    """(min_width, min_gap) of shaded spans on the grid ``t``: a step or 1/2000 of the log wide at
    least, merged when closer than 1/5000 of it (`merge_spans`)."""
    n = t.size
    dt = grid_step(t) or 0.0
    span_len = float(t[-1] - t[0]) if n > 1 else 0.0
    return max(dt, span_len / 2000.0), span_len / 5000.0


def grid_step(t: np.ndarray) -> float | None:
    """The grid's typical step: the median of at most STEP_SAMPLE of its steps, evenly spread (all
    of a shorter grid's); None for fewer than two samples."""
    if t.size < 2:
        return None
    every = max((t.size - 1) // STEP_SAMPLE, 1)
    return float(np.median(t[1::every] - t[:-1:every]))


def _positive_upper_only(band: tuple) -> bool:
    upper, lower = band
    return upper is not None and lower is None and bool(np.nanmin(collapsed(upper)) > 0)


def _ratio_figure(detector: str, t: np.ndarray, series: dict, bands: dict, kept, spans: dict) -> Figure:
    """One figure of every statistic divided by its (positive, upper) threshold; ``kept``: the
    samples a statistic's line keeps, by its name (its alarms' first, last and peak samples)."""
    traces = []
    for i, (name, values) in enumerate(series.items()):
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = values / bands[name][0]
        traces.append(Trace(
            name, ratio, kept([name]), 1.0,
            {"line": {"color": LINE_COLOURS[i % len(LINE_COLOURS)], "width": 1.2}},
        ))  # fmt: skip
    log_y = _wants_log_axis([tr.y for tr in traces])
    return Figure(
        title=f"{detector}: statistic / threshold", y_title="statistic / threshold",
        traces=traces, spans=spans,
        log_y=log_y,
        caption="Each statistic divided by its threshold (1 = on the threshold, dashed line). Normal: below 1 "
        f"throughout; above 1 long enough is an alarm (shaded red). {'Logarithmic' if log_y else 'Linear'} y axis.",
        hlines=[(1.0, "threshold")],
    )  # fmt: skip


def _band_figure(
    result: DetectorResult, t: np.ndarray, name: str, values: np.ndarray, band: tuple, kept, spans: dict
) -> Figure:
    """One statistic against its threshold band, in the judged y range; ``kept``: as `_ratio_figure`'s."""
    keep = kept([name])
    traces = [Trace(name, values, keep, 1.0, {"line": {"color": "#1f77b4", "width": 1.2}})]
    for label, side in zip(("upper threshold", "lower threshold"), band):
        if side is not None:
            traces.append(Trace(
                label, side, keep, 0.5, {"line": {"color": "rgba(214, 39, 40, 0.75)", "width": 1}},
                varying=not _is_piecewise_flat(side),
            ))  # fmt: skip
    peaks = [float(a.peak_value) for a in result.alarms if a.signal == name]
    y_range = judged_range(values, *band, peaks)
    return Figure(f"{result.detector}: {name}", name, traces, spans, y_range=y_range, caption=band_caption(name, band))


def band_caption(name: str, band: tuple) -> str:
    """One line: what a statistic-with-band figure shows and what normal looks like."""
    if name.startswith("rejected."):
        group = name.removeprefix("rejected.")
        return (
            f"1 where the filter refused a {group} sample as outside the physical range (and skipped it), "
            "else 0. Normal: 0 throughout."
        )
    upper, lower = band
    if upper is not None and lower is not None:
        return f"{name} (blue) inside its threshold band (red). Normal: between the red lines; outside {ALARM_TAIL}."
    if upper is not None:
        return f"{name} (blue) against its upper threshold (red). Normal: below the red line; above it {ALARM_TAIL}."
    if lower is not None:
        return f"{name} (blue) against its lower threshold (red). Normal: above the red line; below it {ALARM_TAIL}."
    return f"{name}: no threshold is defined for it, shown for context."


def _columns(arr: np.ndarray, block: int = 65_536) -> np.ndarray:
    """(N, k) -> contiguous (k, N), transposed in blocks of rows (cache-friendly: a plain
    transposing copy of a long array is several times slower)."""
    out = np.empty((arr.shape[1], arr.shape[0]), dtype=arr.dtype)  # float32 stays float32
    for start in range(0, arr.shape[0], block):
        out[:, start : start + block] = arr[start : start + block].T
    return out


def _extra_figures(result: DetectorResult, n: int, model: Mapping, spans: dict, problems: list[str]) -> list[Figure]:
    """An (N, k) extra is one figure (e.g. the coding vector, a line per state); (N,) extras
    named "<prefix>.<kind>" share one figure per kind (e.g. "nis.accel.per_dof")."""
    groups: dict[str, list[tuple[str, np.ndarray]]] = {}
    for key, values in result.extras.items():
        arr = _as_float(values)
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
            Trace(
                label, column, np.zeros(0, np.int64), 0.25,
                {"line": {"color": LINE_COLOURS[j % len(LINE_COLOURS)], "width": 1}},
                varying=not _is_piecewise_flat(column),
            )
            for j, (label, column) in enumerate(columns)
        ]  # fmt: skip
        log_y = _wants_log_axis([column for _, column in columns])
        own = result.info.get("extra_captions")  # a detector may say what its extras show
        caption = (own.get(kind) if isinstance(own, dict) else None) or EXTRA_CAPTIONS.get(
            kind, f"{kind}: a supporting series of {result.detector}, for context (no threshold)."
        )
        figures.append(Figure(f"{result.detector}: {kind}", kind, traces, spans, log_y=log_y, caption=caption))
    return figures
