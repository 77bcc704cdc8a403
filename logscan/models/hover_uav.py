"""The linearised hover quadcopter of the UBIKF paper (section IV) with interval parameters
(docs/algorithms.md section 6.6).

States [x, y, z, vx, vy, vz, roll, pitch, yaw, p, q, r]: position and velocity relative to the
hover point (world frame, z up), small Euler angles (ZYX, as the quadcopter model), body rates.
Inputs [F1, F2, F3, F4]: the four rotor thrusts as deviations from the hover thrust m g / 4 (N),
through the paper's mixer

    u1 = F1 + F2 + F3 + F4                  (total thrust deviation)
    u2 = (-F1 + F2 + F3 - F4) arm            (roll torque)
    u3 = (-F1 - F2 + F3 + F4) arm            (pitch torque)
    u4 = (F1 - F2 + F3 - F4) k_yaw           (yaw torque)

(rotor i at body (x, y) = (+arm, -arm), (+arm, +arm), (-arm, +arm), (-arm, -arm): front right,
front left, rear left, rear right; rotors 1 and 3 spin clockwise seen from above), so the arm
enters B and a rotor loss is an input fault. Linearised about hover with the quadcopter model's
conventions (z up, body FLU, small-angle inversion of a = R e3 T/m - g e3):

    x' = vx, y' = vy, z' = vz
    vx' = g pitch,  vy' = -g roll,  vz' = u1 / mass
    roll' = p, pitch' = q, yaw' = r
    p' = u2 / Ixx,  q' = u3 / Iyy,  r' = u4 / Izz

discretised exactly (zero-order hold, `logscan.models.linear.discretise`). Process noise: white
accelerations, q_accel on vx, vy, vz and q_angacc on p, q, r (continuous densities, Van Loan).

Interval parameters: mass, Ixx, Iyy, Izz, arm and k_yaw each lie in nominal * (1 +- rel) with
rel = mass_rel, inertia_rel (the three inertias independently), arm_rel, k_yaw_rel. The point
model (the EKF's, the simulator's truth) uses the nominal values; `interval_model(dt)` encloses
the discretised system of every parameter set in the box (see its docstring).
"""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np

from logscan.models.base import Actuators, GroupSpec, raise_problems
from logscan.models.dispatch import HOVER_UAV_ID
from logscan.models.interval_model import IntervalModel
from logscan.models.linear import LinearBase, discretise
from logscan.models.quadcopter import Quadcopter

DEFAULTS = {
    "mass": 1.2,  # kg (the quadcopter model's, paper section VI of the encoded-EKF paper)
    "Ixx": 0.0212,  # kg m^2 (the quadcopter model's)
    "Iyy": 0.0212,
    "Izz": 0.0392,
    "arm": 0.3,  # m, lever arm of each rotor about the roll and pitch axes (l = l')
    "k_yaw": 0.0245,  # m, yaw torque per unit thrust (the quadcopter's b_tau)
    "g": 9.81,
    # relative half-widths of the parameter intervals: p in nominal * [1 - rel, 1 + rel]
    "mass_rel": 0.05,
    "inertia_rel": 0.05,  # Ixx, Iyy and Izz, each independently
    "arm_rel": 0.05,
    "k_yaw_rel": 0.05,
    # process noise: continuous white accelerations
    "q_accel": 0.05,  # m/s^2 / sqrt(Hz) on vx, vy, vz
    "q_angacc": 0.02,  # rad/s^2 / sqrt(Hz) on p, q, r
}
# the parameters with intervals and the relative half-width that applies to each
INTERVAL_PARAMS = {
    "mass": "mass_rel",
    "Ixx": "inertia_rel",
    "Iyy": "inertia_rel",
    "Izz": "inertia_rel",
    "arm": "arm_rel",
    "k_yaw": "k_yaw_rel",
}
Q_FLOOR = 1e-12  # added to Q's diagonal (as the quadcopter's): positive definite for a simulator


def hover_matrices(mass, Ixx, Iyy, Izz, arm, k_yaw, g) -> tuple[np.ndarray, np.ndarray]:
    """Continuous (A, B) of the linearised hover model for one parameter set."""
    A = np.zeros((12, 12))
    for i in range(3):
        A[i, 3 + i] = 1.0  # position <- velocity
        A[6 + i, 9 + i] = 1.0  # angle <- body rate (small angles)
    A[3, 7] = g  # vx' = g pitch
    A[4, 6] = -g  # vy' = -g roll
    mixer = mixer_matrix(arm, k_yaw)
    B = np.zeros((12, 4))
    B[5] = mixer[0] / mass
    B[9] = mixer[1] / Ixx
    B[10] = mixer[2] / Iyy
    B[11] = mixer[3] / Izz
    return A, B


def mixer_matrix(arm: float, k_yaw: float) -> np.ndarray:
    """M with [u1, u2, u3, u4] = M @ [F1, F2, F3, F4] (the paper's mixer)."""
    return np.array(
        [
            [1.0, 1.0, 1.0, 1.0],
            [-arm, arm, arm, -arm],
            [-arm, -arm, arm, arm],
            [k_yaw, -k_yaw, k_yaw, -k_yaw],
        ]
    )


class HoverUav(LinearBase):
    name = "hover_uav"
    model_id = HOVER_UAV_ID
    state_names = ("x", "y", "z", "vx", "vy", "vz", "roll", "pitch", "yaw", "p", "q", "r")
    input_names = ("F1", "F2", "F3", "F4")
    # position and attitude as the quadcopter's (noise, ranges, wrapped angles), velocity
    groups = {
        "position": replace(Quadcopter.groups["position"], group_id=0),
        "velocity": GroupSpec(
            "velocity",
            1,
            ("vx", "vy", "vz"),
            (0.1, 0.1, 0.1),
            (-100.0,) * 3,
            (100.0,) * 3,
            ("m/s",) * 3,
            direct_states=(3, 4, 5),
        ),
        "attitude": replace(Quadcopter.groups["attitude"], group_id=2),
    }

    def __init__(self, params: dict | None = None):
        super().__init__(params)
        p = self.p = self._merge_params(DEFAULTS)
        self._check_signs(
            positive=("mass", "Ixx", "Iyy", "Izz", "arm", "k_yaw"),
            non_negative=("g", "q_accel", "q_angacc", "mass_rel", "inertia_rel", "arm_rel", "k_yaw_rel"),
        )
        too_wide = [k for k in sorted(set(INTERVAL_PARAMS.values())) if not p[k] < 1.0]
        if too_wide:
            raise_problems([f"{self.name}: parameter {k} must be < 1 (got {p[k]})" for k in too_wide])
        A, B = hover_matrices(*(p[k] for k in ("mass", "Ixx", "Iyy", "Izz", "arm", "k_yaw", "g")))
        C = {
            "position": np.eye(12)[0:3],
            "velocity": np.eye(12)[3:6],
            "attitude": np.eye(12)[6:9],
        }
        self._setup(A, B, C, {}, self._Qc(), True, None)

    def _Qc(self) -> np.ndarray:
        qa, qw = self.p["q_accel"] ** 2, self.p["q_angacc"] ** 2
        return np.diag([0.0, 0.0, 0.0, qa, qa, qa, 0.0, 0.0, 0.0, qw, qw, qw])

    def default_Q(self, dt: float) -> np.ndarray:
        """Van Loan's discretisation of the white-acceleration density, plus Q_FLOOR on the
        diagonal."""
        return super().default_Q(dt) + Q_FLOOR * np.eye(12)

    def state_scale(self) -> np.ndarray:
        return np.array([5.0, 5.0, 5.0, 1.0, 1.0, 1.0, 0.2, 0.2, 0.2, 0.2, 0.2, 0.2])

    def hover_thrust(self) -> float:
        """Thrust of each rotor in hover (N): the operating point the inputs F1..F4 deviate from."""
        return self.p["mass"] * self.p["g"] / 4.0

    def mixer_matrix(self) -> np.ndarray:
        """The nominal mixer: [u1, u2, u3, u4] = M @ [F1, F2, F3, F4]."""
        return mixer_matrix(self.p["arm"], self.p["k_yaw"])

    def actuators(self) -> Actuators:
        """rotor1..rotor4: the inputs F1..F4 are their thrust deviations from hover (the mixer is
        inside the model), a fault acts on the total thrust hover + F."""
        return Actuators(("rotor1", "rotor2", "rotor3", "rotor4"), np.eye(4), np.full(4, self.hover_thrust()))

    # --- interval model (the UBIKF's) ----------------------------------------------------------
    def parameter_box(self) -> dict[str, tuple[float, float]]:
        """Interval parameter -> (lo, hi): nominal * (1 -+ rel)."""
        return {
            k: (self.p[k] * (1.0 - self.p[rel]), self.p[k] * (1.0 + self.p[rel])) for k, rel in INTERVAL_PARAMS.items()
        }

    def discrete_AB(self, dt: float, **values: float) -> tuple[np.ndarray, np.ndarray]:
        """(Ad, Bd) at period ``dt`` for the nominal parameters with ``values`` replacing some
        (mass, Ixx, ...): the point system of one parameter set."""
        q = {k: self.p[k] for k in ("mass", "Ixx", "Iyy", "Izz", "arm", "k_yaw", "g")}
        q.update(values)
        A, B = hover_matrices(**q)
        Ad, Bd, _ = discretise(A, B, np.zeros((12, 12)), float(dt))
        return Ad, Bd

    def interval_model(self, dt: float) -> IntervalModel:
        """The interval linear model on a grid of period ``dt`` (docs/algorithms.md section 2).

        [A_d], [B_d]: the exact discretisation evaluated at every vertex of the parameter box
        (2^6 = 64 parameter sets), elementwise min and max, as midpoint and radius. An enclosure of
        every parameter set in the box, because every entry of A_d and B_d is monotone in each
        parameter: A_d = expm(A dt) does not depend on them (A holds only g and integrators), and
        B_d = Gamma B with Gamma = int_0^dt expm(A s) ds fixed; the four chains (z; x <- pitch <- q;
        y <- roll <- p; yaw <- r) are decoupled, so each entry of B_d is one entry of Gamma times
        one of +-1/mass, +-arm/Ixx, +-arm/Iyy, +-k_yaw/Izz: monotone in each parameter, hence
        extreme at vertices. (tests/test_hover_uav.py checks it on random parameter sets.)
        C exact (radius 0), Q and R the point model's (radius 0): the noise model has no
        parameter uncertainty. x0 the hover point, P0 = diag(state_scale^2).
        """
        box = self.parameter_box()
        names = list(box)
        lo_A = hi_A = lo_B = hi_B = None
        for corner in itertools.product(*(box[k] for k in names)):
            Ad, Bd = self.discrete_AB(dt, **dict(zip(names, corner)))
            if lo_A is None or hi_A is None or lo_B is None or hi_B is None:  # the first corner sets all four
                lo_A, hi_A, lo_B, hi_B = Ad.copy(), Ad.copy(), Bd.copy(), Bd.copy()
            else:
                lo_A, hi_A = np.minimum(lo_A, Ad), np.maximum(hi_A, Ad)
                lo_B, hi_B = np.minimum(lo_B, Bd), np.maximum(hi_B, Bd)
        assert lo_A is not None and hi_A is not None and lo_B is not None and hi_B is not None  # a box has a corner
        group_names = tuple(sorted(self.groups, key=lambda g: self.groups[g].group_id))
        C_m = np.vstack([self._C[g] for g in group_names])
        sizes = np.array([self.groups[g].size for g in group_names], dtype=np.int64)
        offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        m = int(sizes.sum())
        R_m = np.zeros((m, m))
        for g, o, s in zip(group_names, offsets, sizes):
            R_m[o : o + s, o : o + s] = self.default_R(g)
        Q_m = self.default_Q(dt)
        model = IntervalModel(
            A_m=0.5 * (lo_A + hi_A),
            A_r=0.5 * (hi_A - lo_A),
            B_m=0.5 * (lo_B + hi_B),
            B_r=0.5 * (hi_B - lo_B),
            C_m=C_m,
            C_r=np.zeros_like(C_m),
            Q_m=Q_m,
            Q_r=np.zeros_like(Q_m),
            R_m=R_m,
            R_r=np.zeros_like(R_m),
            dt=float(dt),
            state_names=tuple(self.state_names),
            group_names=group_names,
            group_offsets=offsets,
            group_sizes=sizes,
            x0=self.default_x0(),
            P0=self.default_P0(),
        )
        model.check()
        return model
