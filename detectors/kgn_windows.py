"""KGN's windows: the gain's column norms, their window means, the steady gate and the warm-up
(docs/algorithms.md section 3; `detectors.kgn` composes them)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from logscan.detectors.modes import mode_changes

NO_MODE = "all"  # the single operating-point bin of a run without a mode channel


def column_norms(K: np.ndarray) -> np.ndarray:
    """(N, m) N_j(k) = ||K_k[:, j]||_2 of a (N, n, m) gain series, NaN where column j has no update."""
    K = np.asarray(K, dtype=np.float64)
    return np.sqrt(np.einsum("knm,knm->km", K, K))


def window_starts(n_steps: int, period: int, first: int) -> np.ndarray:
    """First step of every complete window of ``period`` steps, the first one starting at ``first``."""
    first = max(int(first), 0)
    count = max((n_steps - first) // period, 0)
    return first + period * np.arange(count, dtype=np.int64)


def window_means(values: np.ndarray, starts: np.ndarray, period: int) -> np.ndarray:
    """(W, m) mean of the finite entries of ``values`` (N, m) over steps [s, s + period) of each
    window start s (NaN where a column has no finite entry in the window), by cumulative sums."""
    values = np.asarray(values, dtype=np.float64)
    if values.ndim == 1:
        values = values[:, None]
    finite = np.isfinite(values)
    cv = np.concatenate([np.zeros((1, values.shape[1])), np.cumsum(np.where(finite, values, 0.0), axis=0)])
    cc = np.concatenate([np.zeros((1, values.shape[1]), dtype=np.int64), np.cumsum(finite, axis=0)])
    sums = cv[starts + period] - cv[starts]
    counts = cc[starts + period] - cc[starts]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)


def steady_steps(t: np.ndarray, mode: np.ndarray | None, hold_s: float) -> np.ndarray:
    """(N,) bool: the mode has not changed for ``hold_s`` seconds (the log's start counts as a change;
    a NaN mode is never steady). All True without a mode channel."""
    t = np.asarray(t, dtype=np.float64)
    if mode is None:
        return np.ones(t.size, dtype=bool)
    mode = np.asarray(mode, dtype=np.float64)
    if mode.size == 0:
        return np.zeros(0, dtype=bool)
    changed = mode_changes(mode)
    last = np.maximum.accumulate(np.where(changed, np.arange(mode.size), 0))
    return (t - t[last] >= hold_s) & np.isfinite(mode)


def settle_time(t_windows: np.ndarray, trace_p: np.ndarray, tol: float) -> float:
    """First window time after which the window mean of trace(P) stays within ``tol`` (relative) of
    its median over the second half of the windows; inf when it never settles."""
    ok = np.isfinite(trace_p)
    if not ok.any():
        return math.inf
    tail = trace_p[ok][ok.sum() // 2 :]
    median = float(np.median(tail))
    inside = ok & (np.abs(trace_p - median) <= tol * abs(median))
    outside = np.flatnonzero(~inside)
    if outside.size == 0:
        return float(t_windows[0]) if t_windows.size else 0.0
    if outside[-1] + 1 >= t_windows.size:
        return math.inf
    return float(t_windows[outside[-1] + 1])


def longest_stretch(mask: np.ndarray) -> tuple[int, int]:
    """(first index, length) of the longest run of True in ``mask`` ((0, 0) when none)."""
    mask = np.asarray(mask, dtype=bool)
    if not mask.any():
        return 0, 0
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    first, stop = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    k = int(np.argmax(stop - first))
    return int(first[k]), int(stop[k] - first[k])


def mode_key(value: float) -> str:
    """The operating-point bin of a mode value (a JSON key)."""
    return NO_MODE if not np.isfinite(value) else f"{float(value):g}"


@dataclasses.dataclass(repr=False)
class GainView:
    """What the report draws of a KGN run (the paper's Figs. 9-10, `logscan.report.kgn_view`): per
    window, each column's Nbar_j against its bin's band ref_j +- rho s_j. Small: W windows x m
    columns, float32; in the JSON summary it is one line (its ``str``), not the arrays."""

    t: np.ndarray  # (W,) each window's end time, s
    nbar: np.ndarray  # (W, m) float32
    ref: np.ndarray  # (W, m) float32, NaN where the window's bin has no reference
    spread: np.ndarray  # (W, m) float32
    judged: np.ndarray  # (W,) bool: compared with the reference (steady, trained bin, inside the envelope)
    bins: list[str]  # (W,) each window's operating-point bin in words ("" when none)
    rho: float
    groups: list[str]
    offsets: list[int]
    sizes: list[int]
    columns: list[str]  # (m,) each column's measurement channel

    def __str__(self) -> str:
        return (
            f"{self.t.size} windows x {len(self.columns)} columns of Nbar_j against ref_j +- rho s_j "
            "(drawn in the report)"
        )

    __repr__ = __str__
