"""KGN's operating-point bins: the mode, and the flight's own speed, yaw rate and thrust where the
model has them (docs/algorithms.md section 3, "Operating-point bins").

K follows the operating point through the filter's linearisation and its covariance P: the same
mode flown faster, turning harder or at another thrust has other gains. A reference per mode alone
pools them, which widens its spread (retraining on normal and aggressive flights together halved
the slope detection). Each window is therefore keyed by its mode value and, per quantity the model
allows, the index of its window mean among edges learned from the training windows of that mode:

- Quantities (what the model's states and inputs name; a model without one skips it): speed, the
  norm of the estimated velocity (``vx, vy, vz``; ``v_north, v_east, v_down``; the wheel speed
  ``w_v``) or the magnitude of a speed input ``v``; yaw rate, the magnitude of the estimated ``r``
  or ``gamma``, or of the input ``w`` / ``gyro_z``; thrust, the input ``thrust``, the sum of the
  rotor forces ``F1..F4``, or the magnitude of the specific force ``accel_z`` of an IMU-driven model.
- Edges: per mode and quantity, the quantiles k/B (k = 1 .. B-1) of the mode's judged training
  windows, B = min(``op_bins``, floor((n / ``min_windows``)^(1/Q))) for Q quantities: each of the
  B^Q joint bins can hold ``min_windows`` windows (their standard deviation then known to about
  +-24 % at 10), so a mode with few windows is not split.
- A bin (mode x quantity indices) with fewer than ``min_windows`` training windows is not populated:
  its windows are not judged, and the result says for how long.
- Reference per populated bin and column: ref_j = the bin's mean of Nbar_j; s_j = the mode's pooled
  within-bin standard deviation (one-way ANOVA's: sum over the mode's bins of the squared
  deviations from each bin's own mean, over sum(n_b - 1)). The bin removes the operating point's
  shift of the mean; the scatter around it is estimated from all of the mode's windows, not from a
  bin's 10-50 (whose own standard deviation is uncertain by 10-25 %, and biased low on the very
  windows it normalises).
"""

from __future__ import annotations

import math

import numpy as np

# role -> candidates, first match wins: ("state" | "input", names, how to combine the columns)
QUANTITIES: dict[str, list[tuple[str, tuple[str, ...], str]]] = {
    "speed": [
        ("state", ("vx", "vy", "vz"), "norm"),
        ("state", ("v_north", "v_east", "v_down"), "norm"),
        ("state", ("w_v",), "norm"),
        ("input", ("v",), "norm"),
    ],
    "yaw_rate": [
        ("state", ("r",), "norm"),
        ("state", ("gamma",), "norm"),
        ("input", ("w",), "norm"),
        ("input", ("gyro_z",), "norm"),
    ],
    "thrust": [
        ("input", ("thrust",), "norm"),
        ("input", ("F1", "F2", "F3", "F4"), "sum"),
        ("input", ("accel_z",), "norm"),
    ],
}


def _columns(names: list[str], wanted: tuple[str, ...]) -> list[int] | None:
    return [names.index(n) for n in wanted] if all(n in names for n in wanted) else None


def quantity_series(run, trace, sources: dict[str, str] | None = None) -> dict[str, np.ndarray]:
    """role -> (N,) the quantity per step, for the roles this model has (states from the filter's
    posterior ``trace.x_post``, inputs from ``run.u``); ``sources``, when given, gets role ->
    "state" or "input"."""
    states = list(getattr(trace, "state_names", None) or [])
    inputs = list(getattr(run, "input_names", None) or [])
    x = getattr(trace, "x_post", None)
    u = getattr(run, "u", None)
    out = {}
    for role, candidates in QUANTITIES.items():
        for source, wanted, how in candidates:
            names, values = (states, x) if source == "state" else (inputs, u)
            cols = _columns(names, wanted) if values is not None else None
            if cols is None:
                continue
            block = np.asarray(values, dtype=np.float64)[:, cols]
            out[role] = np.sqrt(np.sum(block * block, axis=1)) if how == "norm" else np.sum(block, axis=1)
            if sources is not None:
                sources[role] = source
            break
    return out


def window_quantities(series: dict[str, np.ndarray], starts: np.ndarray, period: int, means) -> dict[str, np.ndarray]:
    """role -> (W,) the window mean of each quantity (``means``: `detectors.kgn.window_means`)."""
    return {role: means(values, starts, period)[:, 0] for role, values in series.items()}


def fit_edges(
    modes: np.ndarray, quantities: dict[str, np.ndarray], op_bins: int, min_windows: int
) -> dict[str, dict[str, list[float]]]:
    """mode key -> role -> the inner edges (quantiles k/B of that mode's training windows)."""
    edges: dict[str, dict[str, list[float]]] = {}
    for mode in sorted(set(modes.tolist())):
        sel = modes == mode
        finite = {role: values[sel & np.isfinite(values)] for role, values in quantities.items()}
        n = min((v.size for v in finite.values()), default=0)
        # B per quantity so that the B^Q joint bins can each hold min_windows windows
        bins = int(min(op_bins, math.floor((n / max(min_windows, 1)) ** (1.0 / max(len(finite), 1)) + 1e-9)))
        edges[mode] = {
            role: [float(e) for e in np.quantile(v, np.arange(1, bins) / bins)] if bins > 1 else []
            for role, v in finite.items()
        }
    return edges


def bin_keys(modes: np.ndarray, quantities: dict[str, np.ndarray], edges: dict) -> list[str | None]:
    """Each window's bin key ("<mode>" or "<mode> speed1 thrust0": the index among the mode's edges
    of every quantity split there); None for a mode without edges (unseen in training) or a
    quantity NaN in the window."""
    keys: list[str | None] = []
    for w, mode in enumerate(modes.tolist()):
        row = edges.get(mode)
        if row is None:
            keys.append(None)
            continue
        parts = [mode]
        for role, inner in row.items():
            if not inner:
                continue
            value = quantities[role][w] if role in quantities else np.nan
            if not np.isfinite(value):
                parts = []
                break
            parts.append(f"{role}{int(np.searchsorted(inner, value, side='right'))}")
        keys.append(" ".join(parts) if parts else None)
    return keys


def bin_words(key: str, edges: dict) -> str:
    """A bin key in words: "mode 1, speed 0.84 to 1.9 m/s ..." (edges of the mode; open ends)."""
    mode, *parts = key.split(" ")
    words = [f"mode {mode}"]
    for part in parts:
        role = part.rstrip("0123456789")
        i = int(part[len(role) :])
        inner = edges.get(mode, {}).get(role, [])
        lo = f"{inner[i - 1]:.3g}" if i > 0 else "-inf"
        hi = f"{inner[i]:.3g}" if i < len(inner) else "inf"
        words.append(f"{role.replace('_', ' ')} {lo} to {hi}")
    return ", ".join(words)


def bin_references(values: dict[str, np.ndarray], min_windows: int, floor: float) -> tuple[dict, dict]:
    """(bins, sparse): per bin key with at least ``min_windows`` windows (``values``: key -> (n, m)
    Nbar), {"ref", "spread", "windows"}, the spread the mode's pooled within-bin standard deviation
    floored at ``floor`` x |ref|; sparse: key -> windows of the bins left out."""
    kept = {key: v for key, v in values.items() if v.shape[0] >= min_windows}
    sparse = {key: int(v.shape[0]) for key, v in values.items() if key not in kept}
    squares: dict[str, np.ndarray] = {}
    dof: dict[str, np.ndarray] = {}
    for key, v in kept.items():
        mode = key.split(" ")[0]
        finite = np.isfinite(v)
        centred = np.where(finite, v - np.nanmean(v, axis=0), 0.0)
        squares[mode] = squares.get(mode, 0.0) + np.sum(centred * centred, axis=0)
        dof[mode] = dof.get(mode, 0) + np.maximum(finite.sum(axis=0) - 1, 0)
    bins = {}
    for key, v in kept.items():
        mode = key.split(" ")[0]
        ref = np.nanmean(v, axis=0)
        pooled = np.sqrt(squares[mode] / np.maximum(dof[mode], 1))
        spread = np.maximum(np.nanstd(v, axis=0), pooled)
        bins[key] = {"ref": ref, "spread": np.maximum(spread, floor * np.abs(ref)), "windows": int(v.shape[0])}
    return bins, sparse
