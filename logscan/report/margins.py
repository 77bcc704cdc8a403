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
statistics as kept for figures: bands are float32, constant ones read-only broadcast views; in float64,
one compiled pass over each statistic (a pass per case and per temporary of numpy took a third of a
1-hour log's report).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from logscan.numba_cache import follow_dependencies
from logscan.report.decimate import collapsed
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


_ABSENT = np.full(1, np.nan)  # a side that is not there: never finite


def _kernel_array(value, dtype) -> np.ndarray:
    """``value`` as the kernels take it: writable C-contiguous ``dtype`` (one compiled version for
    every caller), a constant as one element (`collapsed`), None as `_ABSENT`."""
    if value is None:
        return _ABSENT
    return np.require(collapsed(np.asarray(value)), dtype, ["C", "W"])


@njit(cache=True, error_model="numpy")
def _ratio_of(e, hi, lo):  # pragma: no cover - compiled
    # one sample's ratio (module docstring), NaN where there is none
    has_hi, has_lo = math.isfinite(hi), math.isfinite(lo)
    if math.isnan(e) or not (has_hi or has_lo):
        return math.nan
    if has_hi and has_lo:
        centre, half = 0.5 * (hi + lo), 0.5 * (hi - lo)
        if half > 0:
            return abs(e - centre) / half
        return 0.0 if e == centre else math.inf
    bound, sign = (hi, 1.0) if has_hi else (lo, -1.0)
    if bound == 0:
        return math.nan
    if sign * bound > 0:
        return e / bound
    return bound / e if sign * e < 0 else math.inf  # e on the bound's side of zero, or nowhere near


@njit(cache=True, error_model="numpy")
def _ratios_kernel(e, hi, lo, out):  # pragma: no cover - compiled
    # hi, lo: one element (a constant) or one per sample
    for i in range(e.size):
        out[i] = _ratio_of(e[i], hi[i if hi.size > 1 else 0], lo[i if lo.size > 1 else 0])


@njit(cache=True, error_model="numpy")
def _peak_kernel(e, hi, lo, judged):  # pragma: no cover - compiled
    # (index, ratio) of the first largest ratio over the judged samples; index -1: none has one
    best, at = -math.inf, -1
    for i in range(e.size):
        if judged[i if judged.size > 1 else 0]:
            ratio = _ratio_of(e[i], hi[i if hi.size > 1 else 0], lo[i if lo.size > 1 else 0])
            if ratio > best:  # NaN never is
                best, at = ratio, i
    return at, best


def margin_ratios(e: np.ndarray, upper: np.ndarray | None, lower: np.ndarray | None) -> np.ndarray:
    """Per sample statistic/threshold ratio (module docstring); NaN where there is none."""
    e = _kernel_array(e, np.float64)
    out = np.empty(e.shape)
    _ratios_kernel(e, _kernel_array(upper, np.float64), _kernel_array(lower, np.float64), out)
    return out


def _kind(upper: np.ndarray | None, lower: np.ndarray | None) -> str:
    sides = [name for name, arr in (("upper", upper), ("lower", lower))
             if arr is not None and np.isfinite(collapsed(arr)).any()]  # fmt: skip
    return {2: "two-sided", 1: sides[0] if sides else "", 0: ""}[len(sides)]


def statistic_margin(result: DetectorResult, name: str, t: np.ndarray) -> Margin:
    """The margin of one statistic of ``result`` on the grid ``t``."""
    n = t.size
    values = np.asarray(result.series[name])  # float32 as kept: widened block by block (`_peak`)
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
    """(index, ratio) of the largest ratio over the judged samples (None: no sample has one), in
    one compiled pass over each BLOCK of samples (float64 copies of float32 series are per block)."""
    best = None
    every = np.ones(1, dtype=bool)
    for start in range(0, values.size, BLOCK):
        part = slice(start, start + BLOCK)
        hi, lo = (_kernel_array(None if side is None else side[part], np.float64) for side in (upper, lower))
        mask = every if judged is None else _kernel_array(judged[part], np.bool_)
        i, ratio = _peak_kernel(_kernel_array(values[part], np.float64), hi, lo, mask)
        if i >= 0 and (best is None or ratio > best[1]):
            best = (start + int(i), float(ratio))
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


follow_dependencies(__name__)  # the disk cache filed by what the kernels compile (logscan.numba_cache)
