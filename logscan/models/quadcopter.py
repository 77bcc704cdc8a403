"""The 12-state quadcopter model (encoded-EKF paper section V.A) and its motor mixer.

States [x, y, z, vx, vy, vz, roll, pitch, yaw, p, q, r]: world-frame position and velocity
(z up), ZYX Euler angles, body rates. Inputs: collective thrust and body torques
(`inputs = "wrench"`, default) or the four motor speeds in rad/s (`inputs = "motors"`, mapped
through the mixer inside the model). Discretised with one RK4 step per grid period (F is the exact
Jacobian of that step).

Parameters (defaults and where they come from):
 - mass 1.2 kg, arm L 0.3 m: paper section VI.
 - drag k_D 0.25 N s/m (linear, world frame, F(3:5, 3:5) = -k_D I / m): the value of the paper's
   reference [32] (Gibiansky, "Quadcopter dynamics, simulation, and control").
 - inertia: the paper gives none. Ix = Iy = 2/5 M_c r^2 + 2 m_mot L^2,
   Iz = 2/5 M_c r^2 + 4 m_mot L^2
   with the paper's body radius r = 0.1 m, a 0.8 kg central body and four 0.1 kg motors on the
   0.3 m arms: Ix = Iy = 0.0212, Iz = 0.0392 kg m^2.
 - thrust coefficient kT = C_T rho D^4 / (4 pi^2) = 1.29e-5 N/(rad/s)^2 for the paper's 10 x 4.5 in
   propeller (C_T = 0.1, rho = 1.225): hover at ~477 rad/s per motor.
 - yaw torque per unit thrust b = 0.0245 m: the paper's "b = 0.0245", read as the propeller's
   torque-to-thrust ratio (typical for 10 in propellers).
"""

from __future__ import annotations

import math

import numpy as np

from logscan.errors import ModelError
from logscan.models.base import Actuators, GroupSpec, Model
from logscan.models.dispatch import QUADCOPTER_ID

_WRENCH_INPUTS = ("thrust", "tau_x", "tau_y", "tau_z")
_MOTOR_INPUTS = ("w1", "w2", "w3", "w4")

DEFAULTS = {
    "mass": 1.2,
    "arm": 0.3,
    "g": 9.81,
    "drag": 0.25,
    "Ixx": 0.0212,
    "Iyy": 0.0212,
    "Izz": 0.0392,
    "kT": 1.29e-5,
    "b_tau": 0.0245,
    "inputs": "wrench",
    # process noise (discrete white-acceleration model, see default_Q)
    "q_accel": 0.2,  # m/s^2, std of the linear acceleration disturbance
    "q_angacc": 1.0,  # rad/s^2, std of the angular acceleration disturbance
}


class Quadcopter(Model):
    name = "quadcopter"
    model_id = QUADCOPTER_ID
    state_names = ("x", "y", "z", "vx", "vy", "vz", "roll", "pitch", "yaw", "p", "q", "r")
    input_names = _WRENCH_INPUTS
    groups = {
        "accel": GroupSpec(
            "accel",
            0,
            ("ax", "ay", "az"),
            (0.1, 0.1, 0.1),
            (-160.0,) * 3,
            (160.0,) * 3,
            ("m/s^2",) * 3,
        ),
        "gyro": GroupSpec(
            "gyro",
            1,
            ("gx", "gy", "gz"),
            (0.01, 0.01, 0.01),
            (-35.0,) * 3,
            (35.0,) * 3,
            ("rad/s",) * 3,
            direct_states=(9, 10, 11),
        ),
        "position": GroupSpec(
            "position",
            2,
            ("px", "py", "pz"),
            (0.5, 0.5, 0.5),
            (-1e5,) * 3,
            (1e5,) * 3,
            ("m",) * 3,
            direct_states=(0, 1, 2),
        ),
        "attitude": GroupSpec(
            "attitude",
            3,
            ("roll", "pitch", "yaw"),
            (0.02, 0.02, 0.02),
            (-3.2, -1.6, -6.4),
            (3.2, 1.6, 6.4),
            ("rad",) * 3,
            wrap=(True, True, True),
            direct_states=(6, 7, 8),
        ),
    }

    def __init__(self, params: dict | None = None):
        super().__init__(params)
        self.p = self._merge_params(DEFAULTS)
        mode = self.p["inputs"]
        if mode not in ("wrench", "motors"):
            raise ModelError(f"quadcopter: inputs = {mode!r} is not known", hint='use "wrench" or "motors"')
        self._check_signs(
            positive=("mass", "arm", "Ixx", "Iyy", "Izz", "kT", "b_tau"),
            non_negative=("g", "drag", "q_accel", "q_angacc"),
        )
        self.input_names = _MOTOR_INPUTS if mode == "motors" else _WRENCH_INPUTS
        self._pvec = np.array(
            [
                self.p["mass"],
                self.p["g"],
                self.p["drag"],
                self.p["Ixx"],
                self.p["Iyy"],
                self.p["Izz"],
                self.p["arm"],
                self.p["kT"],
                self.p["b_tau"],
                1.0 if mode == "motors" else 0.0,
            ],
            dtype=np.float64,
        )

    def param_vector(self, dt: float | None = None) -> np.ndarray:
        return self._pvec.copy()

    def default_Q(self, dt: float) -> np.ndarray:
        """Discrete white-acceleration noise per axis: for (position, velocity) and for
        (angle, rate), Q_axis = sigma^2 [[dt^4/4, dt^3/2], [dt^3/2, dt^2]], plus 1e-12 on the
        diagonal to keep Q positive definite. A simulator adds w ~ N(0, Q) per step."""
        Q = np.zeros((12, 12))
        for pos, vel, sigma in (
            *((i, i + 3, self.p["q_accel"]) for i in range(3)),
            *((i, i + 3, self.p["q_angacc"]) for i in range(6, 9)),
        ):
            s2 = sigma * sigma
            Q[pos, pos] = s2 * dt**4 / 4.0
            Q[pos, vel] = Q[vel, pos] = s2 * dt**3 / 2.0
            Q[vel, vel] = s2 * dt**2
        return Q + 1e-12 * np.eye(12)

    def state_scale(self) -> np.ndarray:
        return np.array([5.0, 5.0, 5.0, 1.0, 1.0, 1.0, 0.2, 0.2, 0.2, 0.2, 0.2, 0.2])

    def hover_input(self) -> np.ndarray:
        """Input that holds a level hover (thrust m g, zero torques; or the equal motor speeds)."""
        thrust = self.p["mass"] * self.p["g"]
        if self.p["inputs"] == "motors":
            return np.full(4, math.sqrt(thrust / (4.0 * self.p["kT"])))
        return np.array([thrust, 0.0, 0.0, 0.0])

    # --- mixer (for the simulator's controller and actuator faults) ---------------------------
    def actuators(self) -> Actuators:
        """motor1..motor4: their thrusts through the mixer (wrench inputs), or their speeds
        themselves (inputs = "motors")."""
        names = ("motor1", "motor2", "motor3", "motor4")
        M = np.eye(4) if self.p["inputs"] == "motors" else self.mixer_matrix()
        return Actuators(names, M, np.zeros(4))

    def mixer_matrix(self) -> np.ndarray:
        """M with [T, tau_x, tau_y, tau_z] = M @ [T1, T2, T3, T4] (motor thrusts, N).

        Plus configuration: motor i sits on the arm at (i-1) * 90 deg from body +x;
        tau_x = L (T2 - T4), tau_y = L (T3 - T1), tau_z = b (T1 - T2 + T3 - T4)."""
        L, b = self.p["arm"], self.p["b_tau"]
        return np.array([[1.0, 1.0, 1.0, 1.0], [0.0, L, 0.0, -L], [-L, 0.0, L, 0.0], [b, -b, b, -b]])

    def motors_to_wrench(self, omega: np.ndarray) -> np.ndarray:
        """Motor speeds (..., 4) rad/s -> [thrust, tau_x, tau_y, tau_z] (..., 4), T_i = kT w_i^2."""
        thrusts = self.p["kT"] * np.square(np.asarray(omega, dtype=np.float64))
        return thrusts @ self.mixer_matrix().T

    def wrench_to_motors(self, wrench: np.ndarray) -> np.ndarray:
        """Allocation: [thrust, tau_x, tau_y, tau_z] (..., 4) -> motor speeds (..., 4) rad/s;
        motor thrusts below zero are clipped to zero (a motor cannot push down)."""
        thrusts = np.asarray(wrench, dtype=np.float64) @ np.linalg.inv(self.mixer_matrix()).T
        return np.sqrt(np.clip(thrusts, 0.0, None) / self.p["kT"])
