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
 - `states`, `inputs`: optional names; `outputs`: optional table group -> names.
Continuous models are discretised exactly: [Ad Bd; 0 I] = expm([A B; 0 0] dt), and Van Loan's
method for Q: expm([[-A, Qc], [0, A^T]] dt) = [[., G12], [0, G22]], Qd = G22^T G12.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from logscan.errors import ModelError
from logscan.models.base import GroupSpec, Model
from logscan.models.dispatch import LINEAR_ID


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
    E = expm(M * dt)
    Ad, Bd = E[:n, :n], E[:n, n:]
    k = max(0, int(np.ceil(np.log2(max(np.abs(A).sum(axis=0).max() * dt, 1e-300) / 0.5))))
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


def _matrix(params: dict, key: str, shape: tuple[int | None, int | None], required=True):
    if key not in params:
        if required:
            raise ModelError(f"linear model: parameter {key} is missing")
        return None
    try:
        M = np.atleast_2d(np.asarray(params[key], dtype=np.float64))
    except (TypeError, ValueError):
        raise ModelError(f"linear model: parameter {key} is not a numeric matrix") from None
    for want, got, axis in zip(shape, M.shape, ("rows", "columns")):
        if want is not None and want != got:
            raise ModelError(f"linear model: {key} has {got} {axis}, expected {want}")
    if not np.all(np.isfinite(M)):
        raise ModelError(f"linear model: {key} has non-finite entries")
    return M


_KNOWN = ("A", "B", "C", "D", "Q", "R", "range", "dt", "continuous", "states", "inputs", "outputs")


class LinearModel(LinearBase):
    name = "linear"
    model_id = LINEAR_ID

    def __init__(self, params: dict | None = None):
        super().__init__(params)
        p = self.params
        unknown = sorted(set(p) - set(_KNOWN))
        if unknown:
            raise ModelError(
                f"linear model: unknown parameter(s) {', '.join(unknown)}",
                hint="known parameters: " + ", ".join(_KNOWN),
            )
        A = _matrix(p, "A", (None, None))
        n = A.shape[0]
        if A.shape != (n, n):
            raise ModelError(f"linear model: A must be square, got {A.shape}")
        B = _matrix(p, "B", (n, None))
        nu = B.shape[1]
        C_raw = p.get("C")
        if C_raw is None:
            raise ModelError("linear model: parameter C is missing")
        C_tab = C_raw if isinstance(C_raw, dict) else {"y": C_raw}
        C = {g: _matrix(C_tab, g, (None, n)) for g in C_tab}
        D_tab = p.get("D") or {}
        if not isinstance(D_tab, dict):
            D_tab = {"y": D_tab}
        D = {g: _matrix(D_tab, g, (C[g].shape[0], nu)) for g in D_tab if g in C}
        Q = _matrix(p, "Q", (n, n), required=False)
        Q = 1e-4 * np.eye(n) if Q is None else Q
        continuous = bool(p.get("continuous", True))
        dt = p.get("dt")
        if not continuous and dt is None:
            raise ModelError("linear model: discrete matrices need `dt` (their period in s)")
        self.state_names = tuple(p.get("states") or (f"x{i}" for i in range(n)))
        self.input_names = tuple(p.get("inputs") or (f"u{i}" for i in range(nu)))
        if len(self.state_names) != n or len(self.input_names) != nu:
            raise ModelError("linear model: `states`/`inputs` names do not match A and B")
        outputs = p.get("outputs") or {}
        R_tab = p.get("R") or {}
        ranges = p.get("range") or {}
        groups = {}
        for gid, (g, Cg) in enumerate(C.items()):
            m = Cg.shape[0]
            names = tuple(outputs.get(g) or (f"{g}{i}" for i in range(m)))
            std = np.ones(m)
            if g in R_tab:
                Rg = np.atleast_1d(np.asarray(R_tab[g], dtype=np.float64))
                std = np.sqrt(np.diag(Rg)) if Rg.ndim == 2 else np.broadcast_to(Rg, (m,))
            lo, hi = ranges.get(g, (-1e12, 1e12))
            Dg = D.get(g)
            direct = []
            gains = []
            for row_i, row in enumerate(Cg):
                nz = np.flatnonzero(row)
                no_feedthrough = Dg is None or not np.any(Dg[row_i])
                ok = nz.size == 1 and no_feedthrough
                direct.append(int(nz[0]) if ok else -1)
                gains.append(float(row[nz[0]]) if ok else 1.0)
            groups[g] = GroupSpec(
                g,
                gid,
                names,
                tuple(float(s) for s in std),
                tuple(np.broadcast_to(np.asarray(lo, dtype=float), (m,)).tolist()),
                tuple(np.broadcast_to(np.asarray(hi, dtype=float), (m,)).tolist()),
                direct_states=tuple(direct),
                direct_gains=tuple(gains),
            )
        self.groups = groups
        self._R_full = {g: np.asarray(R_tab[g], dtype=np.float64) for g in R_tab if np.ndim(R_tab[g]) == 2}
        self._setup(A, B, C, D, Q, continuous, None if dt is None else float(dt))

    def default_R(self, group: str) -> np.ndarray:
        if group in self._R_full:
            return self._R_full[group].copy()
        return super().default_R(group)
