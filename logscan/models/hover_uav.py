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
    vx' = g pitch - (drag/mass) vx,  vy' = -g roll - (drag/mass) vy,  vz' = u1 / mass - (drag/mass) vz
    roll' = p, pitch' = q, yaw' = r
    p' = u2 / Ixx,  q' = u3 / Iyy,  r' = u4 / Izz

discretised exactly (zero-order hold, `logscan.models.linear.discretise`). Process noise: white
accelerations, q_accel on vx, vy, vz and q_angacc on p, q, r (continuous densities, Van Loan).
Measurements: position and attitude directly, velocity through a scale factor vel_scale (nominal
1: an optical-flow velocity, the AR.Drone 2's own, scales with the camera's calibration and the
altitude it is scaled by).

Interval parameters: mass, Ixx, Iyy, Izz, arm, k_yaw, drag and vel_scale each lie in
nominal * (1 +- rel) with rel = mass_rel, inertia_rel (the three inertias independently), arm_rel,
k_yaw_rel, drag_rel, vel_scale_rel. drag / mass puts them in A, vel_scale in C, mass, inertias,
arm and k_yaw in B. The point model (the EKF's; the simulator's truth unless it draws an
off-nominal plant, `logscan simulate --plant-draw`) uses the nominal values; `interval_model(dt)`
encloses the discretised system of every parameter set in the box (see its docstring).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from logscan.models.base import Actuators, GroupSpec, raise_problems
from logscan.models.dispatch import HOVER_UAV_ID
from logscan.models.interval_model import IntervalModel, enclose_over_box
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
    "drag": 0.25,  # N s/m, linear translational drag (the quadcopter model's k_D)
    "vel_scale": 1.0,  # velocity output = vel_scale * velocity
    # relative half-widths of the parameter intervals: p in nominal * [1 - rel, 1 + rel]
    "mass_rel": 0.05,
    "inertia_rel": 0.05,  # Ixx, Iyy and Izz, each independently
    "arm_rel": 0.05,
    "k_yaw_rel": 0.05,
    "drag_rel": 0.1,  # drag coefficients are known less well than masses (+-10 %, the spec's upper end)
    "vel_scale_rel": 0.05,
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
    "drag": "drag_rel",
    "vel_scale": "vel_scale_rel",
}
POINT_PARAMS = ("mass", "Ixx", "Iyy", "Izz", "arm", "k_yaw", "g", "drag")  # those of (A, B)
Q_FLOOR = 1e-12  # added to Q's diagonal (as the quadcopter's): positive definite for a simulator


def hover_matrices(mass, Ixx, Iyy, Izz, arm, k_yaw, g, drag=0.0) -> tuple[np.ndarray, np.ndarray]:
    """Continuous (A, B) of the linearised hover model for one parameter set."""
    A = np.zeros((12, 12))
    for i in range(3):
        A[i, 3 + i] = 1.0  # position <- velocity
        A[3 + i, 3 + i] = -drag / mass  # linear drag
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
            positive=("mass", "Ixx", "Iyy", "Izz", "arm", "k_yaw", "vel_scale"),
            non_negative=("g", "drag", "q_accel", "q_angacc", *sorted(set(INTERVAL_PARAMS.values()))),
        )
        too_wide = [k for k in sorted(set(INTERVAL_PARAMS.values())) if not p[k] < 1.0]
        if too_wide:
            raise_problems([f"{self.name}: parameter {k} must be < 1 (got {p[k]})" for k in too_wide])
        if p["vel_scale"] != 1.0:  # the velocity outputs' gain (the class's groups say 1)
            velocity = replace(type(self).groups["velocity"], direct_gains=(p["vel_scale"],) * 3)
            self.groups = {**type(self).groups, "velocity": velocity}
        A, B = hover_matrices(*(p[k] for k in POINT_PARAMS))
        C = {
            "position": np.eye(12)[0:3],
            "velocity": p["vel_scale"] * np.eye(12)[3:6],
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
        q = {k: self.p[k] for k in POINT_PARAMS}
        q.update({k: v for k, v in values.items() if k in q})
        A, B = hover_matrices(**q)
        Ad, Bd, _ = discretise(A, B, np.zeros((12, 12)), float(dt))
        return Ad, Bd

    def output_matrix(self, **values: float) -> np.ndarray:
        """C (9, 12) of the position, velocity and attitude groups stacked, for the nominal
        parameters with ``values`` replacing some (vel_scale)."""
        C = np.eye(12)[:9].copy()
        C[3:6] *= values.get("vel_scale", self.p["vel_scale"])
        return C

    def point_system(self, dt: float, **values: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(Ad, Bd, C) of one parameter set (the nominal ones with ``values`` replacing some)."""
        return (*self.discrete_AB(dt, **values), self.output_matrix(**values))

    def interval_model(self, dt: float) -> IntervalModel:
        """The interval linear model on a grid of period ``dt`` (docs/algorithms.md section 2).

        [A_d], [B_d], [C]: the exact discretisation evaluated at every vertex of the parameter box
        (2^8 = 256 parameter sets), elementwise min and max, as midpoint and radius
        (`enclose_over_box`, which checks on random parameter sets that no entry leaves the
        vertex hull, and widens by a margin if one does). An enclosure because every entry is
        monotone in each parameter: drag and mass enter A only as a = drag / mass, on the
        velocity diagonal; each chain (z, vz; x, vx, pitch, q; y, vy, roll, p; yaw, r) is
        decoupled, and the entries of expm(A dt) and of Gamma = int_0^dt expm(A s) ds are
        integrals of e^{-a s} times non-negative polynomials in s (monotone in a); each entry of
        B_d is one entry of Gamma times one of +-1/mass, +-arm/Ixx, +-arm/Iyy, +-k_yaw/Izz (the
        vz entry (1 - e^{-drag dt / mass}) / drag falls with mass); C holds vel_scale alone.
        (tests/test_hover_uav.py checks it on random parameter sets; `enclose_over_box` would say
        so if it failed.) Q and R the point model's (radius 0): the noise model has no parameter
        uncertainty. x0 the hover point, P0 = diag(state_scale^2).
        """
        (A, B, C), self.interval_widened = enclose_over_box(
            lambda **v: self.point_system(dt, **v), self.parameter_box()
        )
        group_names = tuple(sorted(self.groups, key=lambda g: self.groups[g].group_id))
        sizes = np.array([self.groups[g].size for g in group_names], dtype=np.int64)
        offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        m = int(sizes.sum())
        R_m = np.zeros((m, m))
        for g, o, s in zip(group_names, offsets, sizes):
            R_m[o : o + s, o : o + s] = self.default_R(g)
        Q_m = self.default_Q(dt)
        model = IntervalModel(
            A_m=A[0], A_r=A[1], B_m=B[0], B_r=B[1], C_m=C[0], C_r=C[1],
            Q_m=Q_m, Q_r=np.zeros_like(Q_m), R_m=R_m, R_r=np.zeros_like(R_m),
            dt=float(dt),
            state_names=tuple(self.state_names),
            group_names=group_names,
            group_offsets=offsets,
            group_sizes=sizes,
            x0=self.default_x0(),
            P0=self.default_P0(),
        )  # fmt: skip
        model.check()
        return model
