"""Interval matrices of the `linear` model from its profile: the UBIKF's model (docs/algorithms.md
section 2.1, docs/profiles.md).

`[vehicle] params.radius` gives each matrix's radius entry by entry around the point matrices,
[M] = M +- M_r (the point model is the midpoint):

    radius = { A = [[...]], B = [[...]], C = { group = [[...]] }, Q = [[...]], R = { group = [[...]] } }

every key optional (absent: radius 0). A radius is finite and >= 0 (an interval's lower end is
not above its upper end) and has its matrix's shape; Q's is symmetric and applies to the discrete
covariance the filters use on the grid; R's to each group's covariance. A discrete model's [A],
[B] are the given ones. A continuous model's are derived by evaluating the exact discretisation
at every vertex of the box of its uncertain entries of A and B (`enclose_over_box`, which widens
an entry found not monotone on interior samples), so at most MAX_UNCERTAIN_ENTRIES of them.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from logscan.models.interval_model import IntervalModel, enclose_over_box

MAX_UNCERTAIN_ENTRIES = 10  # 2^10 = 1,024 discretisations


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
    unknown = sorted(set(raw) - {"A", "B", "C", "Q", "R"})
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


def uncertain_entries(radius: dict) -> list[tuple[str, int, int]]:
    """(matrix, row, column) of every entry of A and B with a radius > 0."""
    return [(key, int(i), int(j)) for key in ("A", "B") if key in radius for i, j in np.argwhere(radius[key] > 0)]


def discrete_intervals(model, radius: dict, dt: float, discretise: Callable) -> tuple[tuple, tuple]:
    """((A_m, A_r), (B_m, B_r)) of the discretised system on a grid of period ``dt``
    (``discretise``: `logscan.models.linear.discretise`)."""
    Ad, Bd, _ = model._discrete(dt)
    if not model._continuous:
        return (Ad, radius.get("A", np.zeros_like(Ad))), (Bd, radius.get("B", np.zeros_like(Bd)))
    entries = uncertain_entries(radius)
    point = {"A": model._A, "B": model._B}
    box = {
        f"{k}[{i}][{j}]": (point[k][i, j] - radius[k][i, j], point[k][i, j] + radius[k][i, j]) for k, i, j in entries
    }

    def evaluate(**values: float) -> tuple[np.ndarray, np.ndarray]:
        A, B = model._A.copy(), model._B.copy()
        for (k, i, j), v in zip(entries, values.values()):
            (A if k == "A" else B)[i, j] = v
        Ad_v, Bd_v, _ = discretise(A, B, np.zeros_like(A), float(dt))
        return Ad_v, Bd_v

    (A_pair, B_pair), model.interval_widened = enclose_over_box(evaluate, box)
    return A_pair, B_pair


def linear_interval_model(model, radius: dict, dt: float, discretise: Callable) -> IntervalModel:
    """The `linear` model's interval model on a grid of period ``dt`` (see the module docstring)."""
    (A_m, A_r), (B_m, B_r) = discrete_intervals(model, radius, dt, discretise)
    names = tuple(sorted(model.groups, key=lambda g: model.groups[g].group_id))
    C_m = np.vstack([model._C[g] for g in names])
    C_r = np.vstack([radius.get("C", {}).get(g, np.zeros_like(model._C[g])) for g in names])
    sizes = np.array([model._C[g].shape[0] for g in names], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    m = int(sizes.sum())
    R_m, R_r = np.zeros((m, m)), np.zeros((m, m))
    for g, o, s in zip(names, offsets, sizes):
        R_m[o : o + s, o : o + s] = model.default_R(g)
        R_r[o : o + s, o : o + s] = radius.get("R", {}).get(g, np.zeros((s, s)))
    Q_m = model.default_Q(dt)
    interval = IntervalModel(
        A_m=A_m, A_r=A_r, B_m=B_m, B_r=B_r, C_m=C_m, C_r=C_r,
        Q_m=Q_m, Q_r=radius.get("Q", np.zeros_like(Q_m)), R_m=R_m, R_r=R_r,
        dt=float(dt), state_names=tuple(model.state_names), group_names=names,
        group_offsets=offsets, group_sizes=sizes, x0=model.default_x0(), P0=model.default_P0(),
    )  # fmt: skip
    interval.check()
    return interval
