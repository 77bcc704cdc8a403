"""The Jackal wheel model of the A-TFM thesis (chapter III, eqs. 2-10, Table VI): a brushed DC
motor driving the vehicle through a 25:1 gearbox.

States [i_a, w_v]: armature current (A) and wheel speed (rad/s). Input [Va]: armature voltage (V).
Continuous model (thesis eq. 9-10):
    d i_a/dt = -Ra/La i_a - K_EMF N/La w_v + Va/La
    d w_v/dt = Km N/Jv i_a - (Bf + Bv)/Jv w_v
discretised exactly (matrix exponential), because the electrical time constant La/Ra = 0.44 ms is
far below any logging period. Table VI: Va 24, Ra 0.5, La 2.2e-4, K_EMF 4.49e-2, Km 4.45e-2,
Jm 5.5e-4, Bv = Bf 0.05, N 25. The thesis gives no vehicle inertia Jv; with Jv = Jm the speed time
constant is ~0.8 ms. Here (docs/algorithms.md section 6.3) Jv is the inertia reflected to the wheel shaft:
Jv = M r^2 + N^2 Jm with M = 17 kg and r = 0.1 m (0.17 + 0.344 = 0.514 kg m^2), which gives a
speed time constant of ~0.2 s and a top speed of ~2.06 m/s at 24 V.

Measurement groups: `encoder` (left and right wheel speed, m/s, v = r w_v), `gps_speed` (m/s),
`current` (A).
"""

from __future__ import annotations

import numpy as np

from logscan.models.base import Actuators, GroupSpec
from logscan.models.dispatch import DC_MOTOR_ID
from logscan.models.linear import LinearBase

DEFAULTS = {
    "Va": 24.0,  # supply voltage (V): the input range
    "Ra": 0.5,
    "La": 2.2e-4,
    "K_EMF": 4.49e-2,
    "Km": 4.45e-2,
    "Jm": 5.5e-4,
    "Bv": 0.05,
    "Bf": 0.05,
    "N": 25.0,
    "vehicle_mass": 17.0,  # kg, Jackal
    "wheel_radius": 0.1,  # m
    "Jv": 0.0,  # kg m^2 at the wheel shaft; 0: M r^2 + N^2 Jm
    "q_voltage": 0.01,  # V / sqrt(Hz): white voltage disturbance
    "q_torque": 0.5,  # N m / sqrt(Hz): white load-torque disturbance at the wheel
}


class DcMotor(LinearBase):
    name = "dc_motor"
    model_id = DC_MOTOR_ID
    state_names = ("i_a", "w_v")
    input_names = ("Va",)

    def __init__(self, params: dict | None = None):
        super().__init__(params)
        p = self.p = self._merge_params(DEFAULTS)
        self._check_signs(
            positive=("Va", "Ra", "La", "Km", "K_EMF", "N", "vehicle_mass", "wheel_radius"),
            non_negative=("Jm", "Bv", "Bf", "Jv", "q_voltage", "q_torque"),
        )
        reflected = p["vehicle_mass"] * p["wheel_radius"] ** 2 + p["N"] ** 2 * p["Jm"]
        Jv = p["Jv"] if p["Jv"] > 0 else reflected
        self.Jv = Jv
        A = np.array(
            [
                [-p["Ra"] / p["La"], -p["K_EMF"] * p["N"] / p["La"]],
                [p["Km"] * p["N"] / Jv, -(p["Bf"] + p["Bv"]) / Jv],
            ]
        )
        B = np.array([[1.0 / p["La"]], [0.0]])
        r = p["wheel_radius"]
        C = {"encoder": [[0.0, r], [0.0, r]], "gps_speed": [[0.0, r]], "current": [[1.0, 0.0]]}
        Qc = np.diag([(p["q_voltage"] / p["La"]) ** 2, (p["q_torque"] / Jv) ** 2])
        self.groups = {
            "encoder": GroupSpec(
                "encoder",
                0,
                ("v_left", "v_right"),
                (0.02, 0.02),
                (-10.0,) * 2,
                (10.0,) * 2,
                ("m/s",) * 2,
                direct_states=(1, 1),
                direct_gains=(r, r),
            ),
            "gps_speed": GroupSpec(
                "gps_speed",
                1,
                ("v_gps",),
                (0.05,),
                (-50.0,),
                (50.0,),
                ("m/s",),
                direct_states=(1,),
                direct_gains=(r,),
            ),
            "current": GroupSpec(
                "current",
                2,
                ("i_a",),
                (0.1,),
                (-200.0,),
                (200.0,),
                ("A",),
                direct_states=(0,),
                direct_gains=(1.0,),
            ),
        }
        self._setup(A, B, C, {}, Qc, True, None)

    def state_scale(self) -> np.ndarray:
        return np.array([5.0, 5.0])

    def actuators(self) -> Actuators:
        """The motor, whose armature voltage is the input."""
        return Actuators(("motor",), np.eye(1), np.zeros(1))

    def steady_state(self, Va: float) -> np.ndarray:
        """Equilibrium [i_a, w_v] at constant voltage Va (A x + B Va = 0)."""
        return np.linalg.solve(self._A, -self._B[:, 0] * Va)
