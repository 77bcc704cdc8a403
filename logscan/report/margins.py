"""Margins: how close each statistic came to its threshold, as one ratio per statistic (1.0 = on it).

A healthy report says "no alarms"; the margin says by how much. Per statistic, over the samples
where the statistic and its threshold are both defined, the largest of:

- two-sided band (upper and lower both defined): ``|e - centre| / half_width`` with centre
  ``(upper + lower) / 2`` and half width ``(upper - lower) / 2`` (a ``mu +- rho s`` band: the
  distance from ``mu`` in units of ``rho s``);
- upper bound only: ``e / upper`` for a positive bound (a chi-square test: NIS / threshold);
  ``upper / e`` for a negative one (``e`` must stay below it);
- lower bound only: ``e / lower`` for a negative bound, ``lower / e`` for a positive one.

A detector that holds its statistic at a cap (cusum, at 1.5 h) gives its alarms' uncapped peaks
(``info["uncapped_peaks"]``): the largest, where above, is the margin.

A statistic on the wrong side of zero from a one-sided bound of the other sign, or on a zero-width
band, is infinitely far (ratio inf); a zero bound has no ratio (the sample is skipped). Only the
samples that could raise an alarm count (``DetectorResult.judged``: valid, past the warm-up); of
those, samples where the statistic is NaN (steps where it is not evaluated) are skipped. Computed on the
statistics as kept for figures: bands are float32, constant ones read-only broadcast views.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from logscan.results import Band, DetectorResult


@dataclass
class Margin:
    """The peak statistic/threshold ratio of one statistic and where it occurred.

    ratio: None when no sample had both a statistic and a ratio-able threshold (``note`` says why).
    """

    detector: str
    statistic: str
    kind: str  # "two-sided", "upper", "lower" or "" (no threshold)
    ratio: float | None = None
    time: float | None = None
    value: float | None = None
    n_alarms: int = 0
    note: str = ""


BLOCK = 1 << 20  # samples per pass: bounds the temporaries (a 24-hour 100 Hz log has 8.6 M samples)


def _side(value, n: int) -> np.ndarray | None:
    """A band side as an (N,) array as kept (float32, or a read-only broadcast view; never written)."""
    if value is None:
        return None
    arr = np.asarray(value)
    return np.broadcast_to(arr, (n,)) if arr.ndim == 0 else arr


def margin_ratios(e: np.ndarray, upper: np.ndarray | None, lower: np.ndarray | None) -> np.ndarray:
    """Per sample statistic/threshold ratio (module docstring); NaN where there is none."""
    e = np.asarray(e, dtype=np.float64)
    nan = np.full(e.shape, np.nan)
    hi = nan if upper is None else upper
    lo = nan if lower is None else lower
    has_hi, has_lo = np.isfinite(hi), np.isfinite(lo)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        centre, half = 0.5 * (hi + lo), 0.5 * (hi - lo)
        two_sided = np.where(half > 0, np.abs(e - centre) / half, np.where(e == centre, 0.0, np.inf))
        upper_only = np.where(hi > 0, e / hi, np.where(e < 0, hi / e, np.inf))
        lower_only = np.where(lo < 0, e / lo, np.where(e > 0, lo / e, np.inf))
    ratio = np.where(has_hi & has_lo, two_sided, np.where(has_hi, upper_only, np.where(has_lo, lower_only, np.nan)))
    zero_bound = (has_hi & ~has_lo & (hi == 0)) | (has_lo & ~has_hi & (lo == 0))
    ratio[zero_bound | np.isnan(e)] = np.nan
    return ratio


def _kind(upper: np.ndarray | None, lower: np.ndarray | None) -> str:
    sides = [name for name, arr in (("upper", upper), ("lower", lower)) if arr is not None and np.isfinite(arr).any()]
    return {2: "two-sided", 1: sides[0] if sides else "", 0: ""}[len(sides)]


def statistic_margin(result: DetectorResult, name: str, t: np.ndarray) -> Margin:
    """The margin of one statistic of ``result`` on the grid ``t``."""
    n = t.size
    values = np.asarray(result.series[name], dtype=np.float64)
    band = result.thresholds.get(name) or Band()
    n_alarms = sum(1 for a in result.alarms if a.signal == name)
    margin = Margin(result.detector, name, "", n_alarms=n_alarms)
    try:
        upper, lower = _side(band.upper, n), _side(band.lower, n)
    except ValueError:
        upper = lower = None
    if values.shape != (n,) or any(side is not None and side.shape != (n,) for side in (upper, lower)):
        margin.note = "statistic or threshold not on the analysis grid"
        return margin
    margin.kind = _kind(upper, lower)
    if not margin.kind:
        margin.note = "no threshold"
        return margin
    judged = result.judged.get(name)
    judged = np.asarray(judged, dtype=bool) if judged is not None and np.shape(judged) == (n,) else None
    peak = _peak(values, upper, lower, judged)
    if peak is None:
        margin.note = "never evaluated against its threshold (no valid sample past the warm-up)"
        return margin
    index, margin.ratio = peak
    margin.time, margin.value = float(t[index]), float(values[index])
    _uncapped_peak(margin, (result.info.get("uncapped_peaks") or {}).get(name) or [])
    return margin


def _uncapped_peak(margin: Margin, records: Sequence[dict]) -> None:
    """The largest uncapped peak a detector gives for the statistic it holds at a cap (cusum:
    ``info["uncapped_peaks"][name]``), where it is above the statistic's own."""
    best = max(records, key=lambda r: abs(r["peak_ratio"]), default=None)
    if best is not None and margin.ratio is not None and abs(best["peak_ratio"]) > margin.ratio:
        margin.ratio, margin.time, margin.value = abs(best["peak_ratio"]), best["peak_time"], best["peak_value"]


def _peak(values: np.ndarray, upper, lower, judged: np.ndarray | None) -> tuple[int, float] | None:
    """(index, ratio) of the largest ratio over the judged samples (None: no sample has one),
    BLOCK samples at a time."""
    best = None
    for start in range(0, values.size, BLOCK):
        part = slice(start, start + BLOCK)
        sides = [None if side is None else np.asarray(side[part], dtype=np.float64) for side in (upper, lower)]
        ratio = margin_ratios(values[part], *sides)
        if judged is not None:
            ratio[~judged[part]] = np.nan
        ranked = np.where(np.isnan(ratio), -np.inf, ratio)
        i = int(np.argmax(ranked))
        if ranked[i] > -np.inf and (best is None or ranked[i] > best[1]):
            best = (start + i, float(ratio[i]))
    return best


def result_margins(results: Sequence[DetectorResult], t: np.ndarray) -> list[Margin]:
    """One Margin per statistic of every result, results in order, statistics in order."""
    t = np.asarray(t, dtype=np.float64)
    return [statistic_margin(result, name, t) for result in results for name in result.series]


def ratio_text(ratio: float | None) -> str:
    """A ratio in plain digits: '0.62', '11.3', '1.2e+05'; 'inf'; '—' when there is none."""
    if ratio is None or math.isnan(ratio):
        return "—"
    if math.isinf(ratio):
        return "inf"
    return f"{ratio:.3g}" if ratio < 1e5 else f"{ratio:.2e}"


def peak_margin(margins: Sequence[Margin]) -> Margin | None:
    """The margin closest to (or furthest over) its threshold, None when none has a ratio."""
    rated = [m for m in margins if m.ratio is not None]
    return max(rated, key=lambda m: m.ratio) if rated else None
