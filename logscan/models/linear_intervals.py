"""Interval matrices of the `linear` model from its profile: the UBIKF's model (docs/algorithms.md
section 2.1, docs/profiles.md).

Each matrix is given in one of two forms (not both). `[vehicle] params.radius` gives its radius
entry by entry around the point matrix, [M] = M +- M_r (the point model is the midpoint):

    radius = { A = [[...]], B = [[...]], C = { group = [[...]] }, Q = [[...]], R = { group = [[...]] } }

`[vehicle] params.interval` gives each entry's ends, [lo, hi], as an array of rows of pairs:

    interval = { A = [[[lo, hi], ...], ...], B = ..., C = { group = ... }, Q = ..., R = { group = ... } }

every key optional (absent: exact, radius 0). A radius is finite and >= 0 (an interval's lower end
is not above its upper end) and has its matrix's shape; an interval is finite, lo <= hi, of its
matrix's shape x 2, and holds the point matrix's entry (the point model, the EKF's, must be one of
the interval model's). Q's and R's are symmetric (an interval's lo and hi both); Q's applies to
the discrete covariance the filters use on the grid (checked against it when the grid period is
known, `LinearModel.covariance_problems`); R's to each group's covariance.

An interval is used as the exact box: midpoint (lo + hi) / 2 and radius (hi - lo) / 2, which need
not be the point matrix. The UBIKF only ever reads the interval model (`IntervalModel`: its
mid-model estimate, zonotope and covariance bound all start from M_m and M_r, and Q+, R+ are
Loewner bounds of the whole box), so its midpoint is free: `hover_uav`'s vertex-hull midpoints
already differ from its nominal model, as a continuous model's [A_d] here does.

A discrete model's [A], [B] are the given ones. A continuous model's are derived by evaluating the
exact discretisation at every vertex of the box of its uncertain entries of A and B (radius > 0 or
lo < hi; `enclose_over_box`, which widens an entry found not monotone on interior samples), so at
most MAX_UNCERTAIN_ENTRIES of them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from logscan.errors import ModelError
from logscan.models.interval_model import IntervalModel, enclose_over_box

MAX_UNCERTAIN_ENTRIES = 10  # 2^10 = 1,024 discretisations
_KEYS = ("A", "B", "C", "Q", "R")


def _radius_matrix(value, name: str, shape: tuple[int, int], problems: list[str]) -> np.ndarray | None:
    try:
        M = np.atleast_2d(np.asarray(value, dtype=np.float64))
    except (TypeError, ValueError):
        problems.append(f"linear model: radius {name} is not a numeric matrix")
        return None
    if M.shape != shape:
        problems.append(
            f"linear model: radius {name} has shape {M.shape[0]} x {M.shape[-1]}, expected {shape[0]} x {shape[1]}"
        )
        return None
    if not np.all(np.isfinite(M)):
        problems.append(f"linear model: radius {name} has non-finite entries")
        return None
    if np.any(M < 0):
        i, j = np.argwhere(M < 0)[0]
        problems.append(
            f"linear model: radius {name}[{i}][{j}] = {M[i, j]:g} is negative (an interval's lower end above its upper)"
        )
        return None
    return M


def parse_radius(raw, n: int, nu: int, C: dict[str, np.ndarray], problems: list[str]) -> dict:
    """The ``radius`` table checked: {"A", "B", "Q": matrix, "C", "R": {group: matrix}}; every
    problem appended (one line each)."""
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        problems.append("linear model: radius must be a table with A, B, C, Q and R (each optional)")
        return {}
    out: dict = {}
    unknown = sorted(set(raw) - set(_KEYS))
    if unknown:
        problems.append(f"linear model: radius has unknown key(s) {', '.join(unknown)} (known: A, B, C, Q, R)")
    for key, shape in (("A", (n, n)), ("B", (n, nu)), ("Q", (n, n))):
        if key in raw:
            M = _radius_matrix(raw[key], key, shape, problems)
            if M is not None and key == "Q" and not np.allclose(M, M.T, rtol=0, atol=0):
                problems.append("linear model: radius Q must be symmetric")
            elif M is not None:
                out[key] = M
    for key in ("C", "R"):
        table = raw.get(key, {})
        if not isinstance(table, dict):
            problems.append(f"linear model: radius {key} must be a table group -> matrix (groups: {', '.join(C)})")
            continue
        for g, value in table.items():
            if g not in C:
                problems.append(f"linear model: radius {key} given for group {g!r} but C has no such group")
                continue
            m = C[g].shape[0]
            M = _radius_matrix(value, f"{key}[{g}]", (m, n) if key == "C" else (m, m), problems)
            if M is not None:
                out.setdefault(key, {})[g] = M
    return out


def _entry(name: str, lo: np.ndarray, hi: np.ndarray, i: int, j: int) -> str:
    """``A[1][0] = [0.9, 0.8]``: one entry of an interval matrix, named."""
    return f"{name}[{i}][{j}] = [{lo[i, j]:g}, {hi[i, j]:g}]"


def _first(mask: np.ndarray) -> tuple[int, int, str]:
    """(row, column) of the first True entry of ``mask`` and how many more there are, as words."""
    i, j = (int(v) for v in np.argwhere(mask)[0])
    more = int(mask.sum()) - 1
    return i, j, f" (and {more} more)" if more else ""


def _interval_pair(value, name: str, shape: tuple[int, int], problems: list[str]) -> tuple | None:
    """(lo, hi) of an interval matrix given as rows of [lo, hi] pairs: finite, lo <= hi, of
    ``shape``; else None and a problem naming the entry."""
    try:
        M = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        problems.append(f"linear model: interval {name} is not an array of rows of [lo, hi] pairs")
        return None
    if M.shape != (*shape, 2):
        got = " x ".join(str(s) for s in M.shape) or "a single number"
        problems.append(
            f"linear model: interval {name} has shape {got}, expected {shape[0]} x {shape[1]} x 2 "
            "(rows x columns x [lo, hi])"
        )
        return None
    lo, hi = M[..., 0], M[..., 1]
    bad = ~(np.isfinite(lo) & np.isfinite(hi))
    if bad.any():
        i, j, more = _first(bad)
        problems.append(f"linear model: interval {_entry(name, lo, hi, i, j)} is not finite{more}")
        return None
    if np.any(lo > hi):
        i, j, more = _first(lo > hi)
        problems.append(f"linear model: interval {_entry(name, lo, hi, i, j)}: lower end above the upper{more}")
        return None
    return lo, hi


def point_outside(name: str, lo: np.ndarray, hi: np.ndarray, point: np.ndarray) -> str | None:
    """The problem when an entry of the point matrix lies outside its interval, else None."""
    outside = ~((lo <= point) & (point <= hi))
    if not outside.any():
        return None
    i, j, more = _first(outside)
    return (
        f"linear model: interval {_entry(name, lo, hi, i, j)} does not hold the point matrix's entry "
        f"{point[i, j]:g}{more}: the point model must be one of the interval model's"
    )


def _checked_interval(value, name: str, shape, point, problems: list[str], *, symmetric: bool) -> tuple | None:
    """`_interval_pair` and then: symmetric if asked (Q, R: lo and hi both), holding ``point``
    (None: not known yet, Q of a continuous model)."""
    pair = _interval_pair(value, name, shape, problems)
    if pair is None:
        return None
    lo, hi = pair
    if symmetric and not (np.array_equal(lo, lo.T) and np.array_equal(hi, hi.T)):
        i, j, _ = _first((lo != lo.T) | (hi != hi.T))
        problems.append(
            f"linear model: interval {name} must be symmetric (lo and hi both): "
            f"{_entry(name, lo, hi, i, j)} but {_entry(name, lo, hi, j, i)}"
        )
        return None
    issue = None if point is None else point_outside(name, lo, hi, point)
    if issue:
        problems.append(issue)
        return None
    return pair


def parse_interval(raw, point: dict, radius_raw, problems: list[str]) -> dict:
    """The ``interval`` table checked: {"A", "B", "Q": (lo, hi), "C", "R": {group: (lo, hi)}};
    every problem appended (one line each). ``point``: {"A", "B": matrix, "Q": the discrete
    covariance or None when the grid sets it, "n": states, "C", "R": {group: matrix}};
    ``radius_raw``: the profile's ``radius``, for a matrix given in both forms."""
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        problems.append("linear model: interval must be a table with A, B, C, Q and R (each optional)")
        return {}
    unknown = sorted(set(raw) - set(_KEYS))
    if unknown:
        problems.append(f"linear model: interval has unknown key(s) {', '.join(unknown)} (known: A, B, C, Q, R)")
    radius_raw = radius_raw if isinstance(radius_raw, dict) else {}
    both = "linear model: {} is given both as radius and as interval: give one"
    out: dict = {}
    n = point["n"]
    for key, shape in (("A", (n, n)), ("B", point["B"].shape), ("Q", (n, n))):
        if key in raw and key in radius_raw:
            problems.append(both.format(key))
        elif key in raw:
            pair = _checked_interval(raw[key], key, shape, point[key], problems, symmetric=key == "Q")
            if pair is not None:
                out[key] = pair
    for key in ("C", "R"):
        table, given = raw.get(key, {}), radius_raw.get(key, {})
        if not isinstance(table, dict):
            problems.append(
                f"linear model: interval {key} must be a table group -> matrix (groups: {', '.join(point['C'])})"
            )
            continue
        for g, value in table.items():
            name = f"{key}[{g}]"
            if g not in point["C"]:
                problems.append(f"linear model: interval {key} given for group {g!r} but C has no such group")
            elif isinstance(given, dict) and g in given:
                problems.append(both.format(name))
            else:
                pair = _checked_interval(
                    value, name, point[key][g].shape, point[key][g], problems, symmetric=key == "R"
                )
                if pair is not None:
                    out.setdefault(key, {})[g] = pair
    return out


@dataclass(frozen=True)
class ProfileIntervals:
    """A `linear` model's interval matrices as the profile gives them: ``radius`` {matrix or group
    table of radii} and ``interval`` {(lo, hi) or group table of them}, each matrix in one form."""

    radius: dict = field(default_factory=dict)
    interval: dict = field(default_factory=dict)

    def mid_rad(self, key: str, point: np.ndarray, group: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(midpoint, radius) of matrix ``key`` (of ``group`` for C and R) around ``point``:
        an interval's exact box, else the point and its radius (0 when absent)."""
        interval, radius = self.interval.get(key), self.radius.get(key)
        if group is not None:
            interval = None if interval is None else interval.get(group)
            radius = None if radius is None else radius.get(group)
        if interval is not None:
            lo, hi = interval
            mid = 0.5 * lo + 0.5 * hi  # halves first: lo + hi cannot overflow
            # the larger distance to either end: a rounded midpoint's radius still reaches both
            return mid, np.maximum(hi - mid, mid - lo)
        return point, np.zeros_like(point) if radius is None else radius

    def uncertain_entries(self) -> list[tuple[str, int, int]]:
        """(matrix, row, column) of every entry of A and B with a radius > 0 or lo < hi."""
        found = []
        for key in ("A", "B"):
            wide = self.interval[key][1] > self.interval[key][0] if key in self.interval else self.radius.get(key)
            if wide is not None:
                found += [(key, int(i), int(j)) for i, j in np.argwhere(wide > 0)]
        return found

    def entry_box(self, key: str, i: int, j: int, point: np.ndarray) -> tuple[float, float]:
        """(lo, hi) of entry [i, j] of A or B (``point`` that matrix)."""
        if key in self.interval:
            lo, hi = self.interval[key]
            return float(lo[i, j]), float(hi[i, j])
        r = self.radius[key][i, j]
        return float(point[i, j] - r), float(point[i, j] + r)


def discrete_intervals(model, intervals: ProfileIntervals, dt: float, discretise: Callable) -> tuple[tuple, tuple]:
    """((A_m, A_r), (B_m, B_r)) of the discretised system on a grid of period ``dt``
    (``discretise``: `logscan.models.linear.discretise`)."""
    Ad, Bd, _ = model._discrete(dt)
    if not model._continuous:
        return intervals.mid_rad("A", Ad), intervals.mid_rad("B", Bd)
    entries = intervals.uncertain_entries()
    point = {"A": model._A, "B": model._B}
    box = {f"{k}[{i}][{j}]": intervals.entry_box(k, i, j, point[k]) for k, i, j in entries}

    def evaluate(**values: float) -> tuple[np.ndarray, np.ndarray]:
        A, B = model._A.copy(), model._B.copy()
        for (k, i, j), v in zip(entries, values.values()):
            (A if k == "A" else B)[i, j] = v
        Ad_v, Bd_v, _ = discretise(A, B, np.zeros_like(A), float(dt))
        return Ad_v, Bd_v

    (A_pair, B_pair), model.interval_widened = enclose_over_box(evaluate, box)
    return A_pair, B_pair


def q_interval_problem(intervals: ProfileIntervals, Q_point: np.ndarray) -> str | None:
    """The problem when Q's interval does not hold the discrete covariance ``Q_point``, else None."""
    if "Q" not in intervals.interval:
        return None
    lo, hi = intervals.interval["Q"]
    return point_outside("Q", lo, hi, Q_point)


def linear_interval_model(model, intervals: ProfileIntervals, dt: float, discretise: Callable) -> IntervalModel:
    """The `linear` model's interval model on a grid of period ``dt`` (see the module docstring)."""
    Q_point = model.default_Q(dt)
    issue = q_interval_problem(intervals, Q_point)
    if issue:
        raise ModelError(f"{issue} (at dt = {dt:g} s)")
    (A_m, A_r), (B_m, B_r) = discrete_intervals(model, intervals, dt, discretise)
    names = tuple(sorted(model.groups, key=lambda g: model.groups[g].group_id))
    C_pairs = [intervals.mid_rad("C", model._C[g], g) for g in names]
    R_pairs = [intervals.mid_rad("R", model.default_R(g), g) for g in names]
    sizes = np.array([model._C[g].shape[0] for g in names], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    m = int(sizes.sum())
    R_m, R_r = np.zeros((m, m)), np.zeros((m, m))
    for (mid, rad), o, s in zip(R_pairs, offsets, sizes):
        R_m[o : o + s, o : o + s], R_r[o : o + s, o : o + s] = mid, rad
    Q_m, Q_r = intervals.mid_rad("Q", Q_point)
    interval = IntervalModel(
        A_m=A_m, A_r=A_r, B_m=B_m, B_r=B_r,
        C_m=np.vstack([c for c, _ in C_pairs]), C_r=np.vstack([r for _, r in C_pairs]),
        Q_m=Q_m, Q_r=Q_r, R_m=R_m, R_r=R_r,
        dt=float(dt), state_names=tuple(model.state_names), group_names=names,
        group_offsets=offsets, group_sizes=sizes, x0=model.default_x0(), P0=model.default_P0(),
    )  # fmt: skip
    interval.check()
    return interval
