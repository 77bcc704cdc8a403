"""KGN's trained operating envelope: where the training flights flew, and which windows of a new
flight lie outside it (docs/algorithms.md section 3, "Operating envelope").

K follows the operating point through the filter's linearisation and its covariance P, so a
reference learned on normal flights says nothing about an aggressive one: there, every window
"deviates" (60 false alarms per hour on aggressive quadcopter flights after training on normal
ones). The envelope is a box over the operating-point features of the training windows, each
window's mean and spread (standard deviation) of every model input (the quadcopter's thrust and
torques, the steering torque, the motor voltage: what the vehicle is asked to do), widened on each
side by ``margin`` times its width. A window is inside when every feature is (a NaN feature, an
input held stale, does not count against it). K also carries the memory of P: after a stretch
outside, the gains relax for seconds (measured: the position columns 20 spreads off at the start of
a hover after an aggressive figure-eight, 2 after 3 s), so a window is judged only when every
window that starts within ``hold_s`` before it is inside too: the same hold as the steady gate.
The operating-point range (`fit_ranges`, `memory_gate`) takes the steady stretch after a manoeuvre
beyond what training flew: the gain remembers it for longer than the hold.
"""

from __future__ import annotations

import numpy as np


def operating_features(run, starts: np.ndarray, period: int) -> tuple[list[str], np.ndarray]:
    """(names, (W, F) features): per window, the mean and the standard deviation of every model
    input over its steps (NaN where an input has no finite value in the window); no features for a
    run without inputs."""
    u = getattr(run, "u", None)
    if u is None or np.asarray(u).ndim != 2 or np.asarray(u).shape[1] == 0 or len(starts) == 0:
        return [], np.zeros((len(starts), 0))
    u = np.asarray(u, dtype=np.float64)
    finite = np.isfinite(u)
    zero = np.zeros((1, u.shape[1]))
    c1 = np.concatenate([zero, np.cumsum(np.where(finite, u, 0.0), axis=0)])
    c2 = np.concatenate([zero, np.cumsum(np.where(finite, u * u, 0.0), axis=0)])
    cn = np.concatenate([zero, np.cumsum(finite, axis=0)])
    n = cn[starts + period] - cn[starts]
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (c1[starts + period] - c1[starts]) / n
        spread = np.sqrt(np.maximum((c2[starts + period] - c2[starts]) / n - mean * mean, 0.0))
    channels = list(getattr(run, "input_channels", None) or [f"input {j}" for j in range(u.shape[1])])
    names = [f"mean {c}" for c in channels] + [f"spread {c}" for c in channels]
    return names, np.concatenate([mean, spread], axis=1)


def fit_envelope(names: list[str], blocks: list[np.ndarray], margin: float) -> dict:
    """The box of the training windows' features (``blocks``: (W, F) per run), each side widened
    by ``margin`` x its width; an empty box (no finite value) admits everything."""
    values = np.concatenate(blocks) if blocks else np.zeros((0, len(names)))
    finite = np.isfinite(values)
    lo = np.array([values[finite[:, f], f].min() if finite[:, f].any() else -np.inf for f in range(len(names))])
    hi = np.array([values[finite[:, f], f].max() if finite[:, f].any() else np.inf for f in range(len(names))])
    width = np.where(np.isfinite(hi - lo), hi - lo, 0.0)
    return {"names": list(names), "lo": lo - margin * width, "hi": hi + margin * width}


def inside(features: np.ndarray, envelope: dict) -> np.ndarray:
    """(W,) True where every finite feature lies in the envelope (features in its order)."""
    lo, hi = np.asarray(envelope["lo"], dtype=np.float64), np.asarray(envelope["hi"], dtype=np.float64)
    if features.shape[1] != lo.size:
        return np.ones(features.shape[0], dtype=bool)  # another vehicle's inputs: the caller says so
    with np.errstate(invalid="ignore"):
        out = (features < lo) | (features > hi)
    return np.asarray(~out.any(axis=1), dtype=bool)


def held_inside(ok: np.ndarray, t_starts: np.ndarray, hold_s: float) -> np.ndarray:
    """(W,) True where window i and every window starting within ``hold_s`` before it are inside."""
    bad = np.concatenate([[0], np.cumsum(~np.asarray(ok, dtype=bool))])
    first = np.searchsorted(t_starts, t_starts - hold_s, side="left")
    last = np.arange(t_starts.size) + 1
    return np.asarray(bad[last] - bad[first] == 0, dtype=bool)


def envelope_gate(
    ok: np.ndarray, t_starts: np.ndarray, warm: np.ndarray, judged: np.ndarray, hold_s: float, share_limit: float
) -> tuple[np.ndarray, float]:
    """(the judged windows the envelope takes away, the share of the windows after warm-up outside
    it). More than ``share_limit`` outside: a flight unlike the training's, not checked as a whole
    (the gains relax for seconds after each excursion, so its windows inside are no better);
    otherwise the windows outside and those within ``hold_s`` after one."""
    share = float((~ok & warm).sum()) / max(int(warm.sum()), 1)
    if share > share_limit:
        return judged.copy(), share
    return judged & ~held_inside(ok, t_starts, hold_s), share


def outside_line(features: np.ndarray, envelope: dict, outside: np.ndarray, seconds: float, total: float) -> str:
    """The `not checked` line: how long, and the features farthest outside (in envelope widths)."""
    lo, hi = np.asarray(envelope["lo"], dtype=np.float64), np.asarray(envelope["hi"], dtype=np.float64)
    width = np.maximum(hi - lo, 1e-12)
    with np.errstate(invalid="ignore"):
        beyond = np.nanmax(np.maximum(lo - features[outside], features[outside] - hi) / width, axis=0, initial=0.0)
    worst = [f for f in np.argsort(-beyond)[:2] if beyond[f] > 0]
    cells = "; ".join(
        f"{envelope['names'][f]} {np.nanmin(features[outside, f]):.3g} to {np.nanmax(features[outside, f]):.3g} "
        f"against the trained {lo[f]:.3g} to {hi[f]:.3g}"
        for f in worst
    )
    return (
        f"outside the trained envelope for {seconds:.0f} s of {total:.0f} s judged ({cells}): the gain there "
        "is not compared with the reference (train on flights like this one to check them)"
    )


# --- the operating-point range and the gain's memory of it -----------------------------------------
# K carries the memory of P: after a manoeuvre harder than any in training, the gains relax at the
# filter's own rate for longer than the steady gate's hold (measured on `ins` flights that fly
# twice the training's distance per move: the GNSS and barometer columns 15 spreads off 10 s after
# the move, back within 1 after 20 s), so the steady stretch after it has no trained reference.


MAGNITUDES = ("speed", "yaw_rate")  # `detectors.kgn_bins` quantities >= 0; thrust departs from hover both ways


def fit_ranges(blocks: list[dict[str, np.ndarray]]) -> dict[str, list[float]]:
    """role -> [lo, hi]: the range of each operating-point quantity (`detectors.kgn_bins`) over the
    training windows after warm-up, steady or not (``blocks``: role -> (W,) per run), from 0 for a
    magnitude (speed, yaw rate); a quantity with no finite value gets no range."""
    out: dict[str, list[float]] = {}
    for role in blocks[0] if blocks else {}:
        values = np.concatenate([b[role] for b in blocks])
        values = values[np.isfinite(values)]
        if values.size:  # a magnitude's gentlest value is 0: only its top bounds the manoeuvre
            out[role] = [0.0 if role in MAGNITUDES else float(values.min()), float(values.max())]
    return out


def outside_ranges(quantities: dict[str, np.ndarray], ranges: dict[str, list[float]], n: int) -> np.ndarray:
    """(W,) True where some quantity's window mean lies outside its trained range (NaN: not outside)."""
    out = np.zeros(n, dtype=bool)
    for role, (lo, hi) in ranges.items():
        values = quantities.get(role)
        if values is not None:
            with np.errstate(invalid="ignore"):
                out |= (values < lo) | (values > hi)
    return out


def memory_gate(outside: np.ndarray, steady: np.ndarray) -> np.ndarray:
    """(W,) the steady windows the gain's memory of a manoeuvre beyond the trained range takes away:
    every window of each steady stretch (a run of ``steady`` windows) whose manoeuvre (the windows
    since the last steady stretch, which the steady gate does not judge) holds an ``outside``
    window. Outside steady windows do not count: there a fault's own reaction (closed loop: the
    commands) may move the operating point, and the envelope judges them."""
    steady = np.asarray(steady, dtype=bool)
    outside = np.asarray(outside, dtype=bool) & ~steady
    if not outside.any():
        return np.zeros(steady.size, dtype=bool)
    start = steady & ~np.concatenate([[False], steady[:-1]])
    stretch = np.cumsum(start) + ~steady  # a manoeuvre belongs to the steady stretch after it
    hard = np.zeros(int(stretch.max()) + 1, dtype=bool)
    hard[stretch[outside]] = True
    return steady & hard[stretch]


def range_line(quantities: dict[str, np.ndarray], ranges: dict, outside: np.ndarray, seconds: float) -> str:
    """The `not checked` line of the memory gate: how long, and the manoeuvres' quantities outside
    their range (``outside``: those windows)."""
    cells = []
    for role, (lo, hi) in ranges.items():
        values = quantities.get(role)
        if values is None:
            continue
        with np.errstate(invalid="ignore"):
            beyond = outside & ((values < lo) | (values > hi))
        if beyond.any():
            cells.append(
                f"{role.replace('_', ' ')} {np.nanmin(values[beyond]):.3g} to {np.nanmax(values[beyond]):.3g} "
                f"against the trained {lo:.3g} to {hi:.3g}"
            )
    return (
        f"manoeuvres beyond the trained range ({'; '.join(cells)}): the gain remembers them, so the "
        f"{seconds:.0f} s of steady windows after it are not compared with the reference (train on flights like "
        "this one to check them)"
    )


LINEAR_LINE = (
    "the model is linear: its filter's gain follows the Riccati recursion, which never reads a measurement, so "
    "the gain cannot show a sensor fault; the {seconds:.0f} s of steady windows are not compared with the "
    "reference (the blindness probe agrees)"
)
