"""Linear models from a profile (A, B, C per group, D, Q, R; continuous or discrete) and exact
discretisation shared with the dc_motor model.

Profile parameters (`[vehicle] model = "linear"`, `params = {...}`):
 - `A` (n x n), `B` (n x nu): continuous (`continuous = true`, default) or discrete matrices.
 - `C`: a table group -> (m_g x n) matrix (a bare matrix means one group called "y");
   `D`: optional table group -> (m_g x nu).
 - `Q`: process noise (n x n), continuous spectral density or discrete covariance (default 1e-4 I).
 - `R`: optional table group -> standard deviations (list of m_g) or covariance matrix.
 - `range`: optional table group -> [lo, hi] (scalars or lists); default +-1e12, so a bit-flipped
   1e20 is rejected.
 - `dt`: period of discrete matrices (required when `continuous = false`; the grid must match).
 - `states`, `inputs`: optional names; `outputs`: optional table group -> names (unique, one per
   row or column).
 - `radius`, `interval`: optional interval matrices for the UBIKF, each matrix as a radius around
   the point matrix or as [lo, hi] per entry (`logscan.models.linear_intervals`).
Every matrix must be finite and of the right shape; Q symmetric positive semi-definite, a covariance
R positive definite, standard deviations > 0; D, R, range and outputs only for groups of C. Every
problem is reported at once (one ModelError whose `problems` lists them).
Continuous models are discretised exactly: [Ad Bd; 0 I] = expm([A B; 0 0] dt), and Van Loan's
method for Q: expm([[-A, Qc], [0, A^T]] dt) = [[., G12], [0, G22]], Qd = G22^T G12.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from logscan.errors import ModelError
from logscan.models.base import GroupSpec, Model, covariance_problem, raise_problems
from logscan.models.dispatch import LINEAR_ID
from logscan.models.interval_model import IntervalModel
from logscan.models.linear_intervals import (
    MAX_UNCERTAIN_ENTRIES,
    ProfileIntervals,
    linear_interval_model,
    parse_interval,
    parse_radius,
    q_interval_problem,
)


def discretise(A: np.ndarray, B: np.ndarray, Qc: np.ndarray, dt: float):
    """Exact zero-order-hold discretisation: (Ad, Bd, Qd) for period dt.

    Qd = int_0^dt e^{As} Qc e^{A's} ds by Van Loan's method on a substep h = dt / 2^k short enough
    that e^{-Ah} stays well conditioned (stiff models: La/Ra = 0.44 ms against dt = 10 ms), then
    k doublings Q(2h) = Q(h) + Phi(h) Q(h) Phi(h)^T.
    """
    n, nu = B.shape
    M = np.zeros((n + nu, n + nu))
    M[:n, :n] = A
    M[:n, n:] = B
    # A whose exp(A dt) is beyond float range (A = 1e308) gives inf or NaN matrices, quietly:
    # `LinearBase.covariance_problems` turns them into a profile error
    with np.errstate(over="ignore", invalid="ignore"):
        E = expm(M * dt)
        Ad, Bd = E[:n, :n], E[:n, n:]
        norm = np.abs(A).sum(axis=0).max() * dt
        if not (np.isfinite(norm) and np.isfinite(Qc).all()):  # A or Qc beyond float range
            nan = np.full((n, n), np.nan)
            return nan, np.full((n, nu), np.nan), nan
        k = max(0, int(np.ceil(np.log2(max(norm, 1e-300) / 0.5))))
        h = dt / 2**k
        V = np.zeros((2 * n, 2 * n))
        V[:n, :n] = -A
        V[:n, n:] = Qc
        V[n:, n:] = A.T
        G = expm(V * h)
        Phi = G[n:, n:].T
        Qd = Phi @ G[:n, n:]
        for _ in range(k):
            Qd = Qd + Phi @ Qd @ Phi.T
            Phi = Phi @ Phi
        return Ad, Bd, 0.5 * (Qd + Qd.T)


class LinearBase(Model):
    """A model whose kernel is the packed linear one: subclasses call `_setup` in __init__."""

    gain_is_data_free = True  # fixed Q and R: K follows the Riccati recursion, never a measurement

    def _setup(self, A, B, C: dict, D: dict, Q, continuous: bool, discrete_dt: float | None):
        self._A = np.asarray(A, dtype=np.float64)
        self._B = np.asarray(B, dtype=np.float64)
        self._C = {g: np.asarray(c, dtype=np.float64) for g, c in C.items()}
        self._D = {
            g: np.asarray(D[g], dtype=np.float64) if g in D else np.zeros((self._C[g].shape[0], self._B.shape[1]))
            for g in C
        }
        self._Q = np.asarray(Q, dtype=np.float64)
        self._continuous = continuous
        self._discrete_dt = discrete_dt
        self._cache: dict[float | None, tuple] = {}

    def _discrete(self, dt: float | None):
        if dt not in self._cache:
            if not self._continuous:
                own = self._discrete_dt
                if dt is not None and own is not None and abs(dt - own) > 1e-12 * max(dt, 1.0):
                    raise ModelError(
                        f"model {self.name!r} is discrete at dt = {self._discrete_dt} s but the grid period is {dt} s",
                        hint="set the profile rate to match, or give continuous matrices",
                    )
                out = (self._A, self._B, self._Q)
            elif dt is None:  # only h/H are evaluated: the dynamics are not used
                out = (np.eye(self._A.shape[0]), np.zeros_like(self._B), self._Q)
            else:
                out = discretise(self._A, self._B, self._Q, float(dt))
            self._cache[dt] = out
        return self._cache[dt]

    def param_vector(self, dt: float | None = None) -> np.ndarray:
        Ad, Bd, _ = self._discrete(dt)
        n, nu = Bd.shape
        names = list(self.groups)
        head = [float(n), float(nu), float(len(names))]
        blocks = []
        start = 3 + len(names) + n * n + n * nu
        starts = []
        for g in names:
            C, D = self._C[g], self._D[g]
            starts.append(float(start))
            block = np.concatenate([[float(C.shape[0])], C.ravel(), D.ravel()])
            blocks.append(block)
            start += block.size
        return np.concatenate([head, starts, Ad.ravel(), Bd.ravel(), *blocks]).astype(np.float64)

    def default_Q(self, dt: float) -> np.ndarray:
        return self._discrete(dt)[2].copy()

    def covariance_problems(self, dt: float) -> list[str]:
        """A continuous model whose discretisation at ``dt`` is not finite (exp(A dt) beyond float
        range) is one problem, named as such, before its process noise Q (non-finite with it)."""
        if self._continuous:
            Ad, Bd, _ = self._discrete(dt)
            if not (np.all(np.isfinite(Ad)) and np.all(np.isfinite(Bd))):
                return [
                    f"model {self.name!r}: the dynamics (A, B) discretised at dt = {dt:g} s are not finite: "
                    "exp(A dt) overflows, A's rates are far too large for the profile's rate_hz"
                ]
        return super().covariance_problems(dt)


_KNOWN = (
    "A", "B", "C", "D", "Q", "R", "range", "dt", "continuous", "states", "inputs", "outputs", "radius", "interval",
    "x0", "P0",
)  # fmt: skip
_DEFAULT_RANGE = 1e12


def _matrix(value, name: str, shape: tuple[int | None, int | None], problems: list[str]) -> np.ndarray | None:
    """``value`` as a finite 2-D float64 matrix of ``shape`` (None: any size), else None and a
    problem."""
    try:
        M = np.atleast_2d(np.asarray(value, dtype=np.float64))
    except (TypeError, ValueError):
        problems.append(f"linear model: {name} is not a numeric matrix")
        return None
    if M.ndim != 2:
        problems.append(f"linear model: {name} must be a matrix (an array of rows), got {M.ndim} dimensions")
        return None
    for want, got, axis in zip(shape, M.shape, ("rows", "columns")):
        if want is not None and want != got:
            problems.append(f"linear model: {name} has {got} {axis}, expected {want}")
            return None
    if not np.all(np.isfinite(M)):
        problems.append(f"linear model: {name} has non-finite entries")
        return None
    return M


def _table(params: dict, key: str, groups, problems: list[str]) -> dict:
    """``params[key]`` as a table group -> value (a bare value belongs to the group ``y`` of a bare
    C); entries for groups that C does not have are problems."""
    raw = params.get(key)
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        if groups is not None and "y" not in groups:
            problems.append(f"linear model: {key} must be a table group -> value (groups: {', '.join(groups)})")
            return {}
        raw = {"y": raw}
    unknown = [g for g in raw if groups is not None and g not in groups]
    for g in unknown:
        problems.append(
            f"linear model: {key} given for group {g!r} but C has no such group (groups: {', '.join(groups)})"
        )
    return {g: v for g, v in raw.items() if g not in unknown}


def _names(raw, where: str, default: tuple[str, ...], problems: list[str]) -> tuple[str, ...]:
    """Unique non-empty names, as many as ``default``; else ``default`` and a problem."""
    if raw is None:
        return default
    if not isinstance(raw, (list, tuple)) or not all(isinstance(s, str) and s for s in raw):
        problems.append(f"linear model: {where} must be an array of names")
    elif len(raw) != len(default):
        problems.append(f"linear model: {where} has {len(raw)} names for {len(default)} columns of the matrices")
    elif len(set(raw)) != len(raw):
        problems.append(f"linear model: {where} names {sorted(s for s in raw if raw.count(s) > 1)[0]!r} twice")
    else:
        return tuple(raw)
    return default


def _noise(value, g: str, m: int, problems: list[str]) -> tuple[np.ndarray, np.ndarray | None]:
    """(standard deviation per output, covariance matrix or None) of ``R[g]``: standard deviations
    (> 0, finite; one or m) or an m x m positive-definite covariance."""
    try:
        R = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        problems.append(f"linear model: R[{g}] is not numeric (give standard deviations or a covariance matrix)")
        return np.ones(m), None
    if R.ndim == 2:
        issue = covariance_problem(R, f"R[{g}]", definite=True) if R.shape == (m, m) else f"R[{g}] is not {m} x {m}"
        if issue:
            problems.append(f"linear model: {issue}")
            return np.ones(m), None
        return np.sqrt(np.diag(R)), R
    std = np.atleast_1d(R)
    if std.ndim != 1 or std.size not in (1, m):
        problems.append(f"linear model: R[{g}] gives {std.size} standard deviations for {m} outputs")
        return np.ones(m), None
    bad = std[~(np.isfinite(std) & (std > 0))]
    if bad.size:
        problems.append(f"linear model: R[{g}] standard deviations must be > 0 and finite, got {bad[0]:g}")
        return np.ones(m), None
    return np.broadcast_to(std, (m,)).copy(), None


def _range(value, g: str, m: int, problems: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) per output of ``range[g] = [lo, hi]`` (each a number or m numbers, finite, lo < hi)."""
    try:
        lo, hi = (np.broadcast_to(np.asarray(v, dtype=np.float64), (m,)) for v in value)
    except (TypeError, ValueError):
        problems.append(f"linear model: range[{g}] must be [lo, hi], each a number or {m} numbers")
        return np.full(m, -_DEFAULT_RANGE), np.full(m, _DEFAULT_RANGE)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo < hi)):
        problems.append(f"linear model: range[{g}] needs finite lo < hi, got {value!r}")
    return lo, hi


def _timing(params: dict, problems: list[str]) -> tuple[bool, float | None]:
    """(continuous, dt of discrete matrices or None)."""
    continuous = params.get("continuous", True)
    if not isinstance(continuous, (bool, np.bool_)):
        problems.append(f"linear model: continuous must be true or false, got {continuous!r}")
        continuous = True
    dt = params.get("dt")
    if dt is not None:
        if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not (np.isfinite(dt) and dt > 0):
            problems.append(f"linear model: dt must be a finite number > 0 (seconds), got {dt!r}")
            dt = None
    elif not continuous:
        problems.append("linear model: discrete matrices need `dt` (their period in s)")
    return bool(continuous), None if dt is None else float(dt)


def _system(params: dict, problems: list[str]):
    """(A, B, C, D, Q) checked: A square, B with A's rows, C a table of matrices with A's columns
    (a bare matrix: group ``y``), D per group (rows of C, columns of B), Q positive semi-definite
    (default 1e-4 I). A part that cannot be read is None (C, D: left out)."""
    for key in ("A", "B", "C"):
        if key not in params:
            problems.append(f"linear model: parameter {key} is missing")
    A = _matrix(params["A"], "A", (None, None), problems) if "A" in params else None
    if A is not None and A.shape[0] != A.shape[1]:
        problems.append(f"linear model: A must be square, got {A.shape[0]} x {A.shape[1]}")
        A = None
    n = None if A is None else A.shape[0]
    B = _matrix(params["B"], "B", (n, None), problems) if "B" in params else None
    nu = None if B is None else B.shape[1]
    read = {g: _matrix(v, f"C[{g}]", (None, n), problems) for g, v in _table(params, "C", None, problems).items()}
    if "C" in params and not read:
        problems.append("linear model: C has no group")
    C = {g: c for g, c in read.items() if c is not None}
    D = {
        g: _matrix(v, f"D[{g}]", (C[g].shape[0] if g in C else None, nu), problems)
        for g, v in _table(params, "D", list(C), problems).items()
    }
    Q = None
    if "Q" in params:
        Q = _covariance(params["Q"], "Q", n, problems)
    elif n is not None:
        Q = 1e-4 * np.eye(n)
    return A, B, C, {g: d for g, d in D.items() if d is not None}, Q


def _prior(params: dict, n: int | None, problems: list[str]) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The profile's x0 (n values) and P0 (n x n covariance) checked; None where not given."""
    x0 = P0 = None
    if n is None:
        return x0, P0
    if "x0" in params:
        row = _matrix(params["x0"], "x0", (1, n), problems)
        x0 = None if row is None else row[0]
    if "P0" in params:
        P0 = _covariance(params["P0"], "P0", n, problems)
    return x0, P0


def _covariance(value, name: str, n: int | None, problems: list[str]) -> np.ndarray | None:
    """``value`` as an n x n matrix, a problem when it is no covariance (symmetric positive
    semi-definite); the matrix is returned all the same (Q's intervals are checked against it)."""
    M = _matrix(value, name, (n, n), problems)
    issue = None if M is None else covariance_problem(M, name, definite=False)
    if issue:
        problems.append(f"linear model: {issue}")
    return M


class LinearModel(LinearBase):
    """A linear model from a profile's matrices; every parameter problem is reported at once."""

    name = "linear"
    model_id = LINEAR_ID

    def __init__(self, params: dict | None = None):
        super().__init__(params)
        p = self.params
        problems: list[str] = []
        unknown = sorted(set(p) - set(_KNOWN))
        if unknown:
            problems.append(f"linear model: unknown parameter(s) {', '.join(unknown)} (known: {', '.join(_KNOWN)})")
        A, B, C, D, Q = _system(p, problems)
        self._prior = _prior(p, None if A is None else A.shape[0], problems)
        continuous, dt = _timing(p, problems)
        if A is not None:
            self.state_names = _names(p.get("states"), "states", tuple(f"x{i}" for i in range(A.shape[0])), problems)
        if B is not None:
            self.input_names = _names(p.get("inputs"), "inputs", tuple(f"u{i}" for i in range(B.shape[1])), problems)
        self.groups, self._R_full = self._group_specs(C, D, problems)
        self._intervals = ProfileIntervals()
        if A is not None and B is not None:
            self._intervals = self._profile_intervals(A, B, C, None if continuous else Q, problems)
        uncertain = len(self._intervals.uncertain_entries())
        if continuous and uncertain > MAX_UNCERTAIN_ENTRIES:
            problems.append(
                f"linear model: {uncertain} entries of continuous A, B have a radius or an interval; "
                f"vertex evaluation takes at most {MAX_UNCERTAIN_ENTRIES} (or discrete matrices: continuous = false)"
            )
        raise_problems(problems)
        self._setup(A, B, C, D, Q, continuous, dt)

    def default_x0(self) -> np.ndarray:
        """The profile's x0, else zeros (the directly measured states are seeded from their first
        samples either way)."""
        x0 = self._prior[0]
        return super().default_x0() if x0 is None else x0.copy()

    def default_P0(self) -> np.ndarray:
        """The profile's P0, else the identity: a state the sensors do not measure directly starts
        this far from x0 at most a few times, so P0 must cover where the system may be when the log
        begins (a motor already turning), or the filter's first second reads as a fault."""
        P0 = self._prior[1]
        return super().default_P0() if P0 is None else P0.copy()

    def _profile_intervals(self, A, B, C: dict, Q_discrete, problems: list[str]) -> ProfileIntervals:
        """The profile's ``radius`` and ``interval`` checked (``Q_discrete``: Q when it is the
        discrete covariance, None when the grid period sets it)."""
        p = self.params
        radius = parse_radius(p.get("radius"), A.shape[0], B.shape[1], C, problems)
        point = {
            "n": A.shape[0], "A": A, "B": B, "Q": Q_discrete, "C": C,
            "R": {g: self.default_R(g) for g in C if g in self.groups},
        }  # fmt: skip
        return ProfileIntervals(radius, parse_interval(p.get("interval"), point, p.get("radius"), problems))

    def covariance_problems(self, dt: float) -> list[str]:
        """`LinearBase.covariance_problems`, then whether Q's interval holds the discrete
        covariance at ``dt`` (a continuous model's is known only with the grid period)."""
        found = super().covariance_problems(dt)
        if not found and self._continuous:
            issue = q_interval_problem(self._intervals, self.default_Q(dt))
            found += [f"{issue} (at dt = {dt:g} s)"] if issue else []
        return found

    def interval_model(self, dt: float) -> IntervalModel:
        """The UBIKF's interval model: the point matrices +- the profile's ``radius``, or its
        ``interval`` boxes (`logscan.models.linear_intervals`)."""
        return linear_interval_model(self, self._intervals, dt, discretise)

    def _group_specs(self, C: dict, D: dict, problems: list[str]) -> tuple[dict[str, GroupSpec], dict]:
        """GroupSpecs of C's groups (names, noise from R, ranges) and the full R matrices given."""
        p, groups, R_full = self.params, {}, {}
        outputs = _table(p, "outputs", list(C), problems)
        R_tab = _table(p, "R", list(C), problems)
        ranges = _table(p, "range", list(C), problems)
        for gid, (g, Cg) in enumerate(C.items()):
            m = Cg.shape[0]
            names = _names(outputs.get(g), f"outputs[{g}]", tuple(f"{g}{i}" for i in range(m)), problems)
            std, full = _noise(R_tab[g], g, m, problems) if g in R_tab else (np.ones(m), None)
            if full is not None:
                R_full[g] = full
            lo, hi = (
                _range(ranges[g], g, m, problems)
                if g in ranges
                else (np.full(m, -_DEFAULT_RANGE), np.full(m, _DEFAULT_RANGE))
            )
            Dg = D.get(g)
            direct, gains = [], []
            for row_i, row in enumerate(Cg):
                nz = np.flatnonzero(row)
                ok = nz.size == 1 and (Dg is None or not np.any(Dg[row_i]))
                direct.append(int(nz[0]) if ok else -1)
                gains.append(float(row[nz[0]]) if ok else 1.0)
            groups[g] = GroupSpec(
                g,
                gid,
                names,
                tuple(float(s) for s in std),
                tuple(lo.tolist()),
                tuple(hi.tolist()),
                direct_states=tuple(direct),
                direct_gains=tuple(gains),
            )
        return groups, R_full

    def default_R(self, group: str) -> np.ndarray:
        if group in self._R_full:
            return self._R_full[group].copy()
        return super().default_R(group)
