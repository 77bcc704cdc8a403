"""The steer-by-wire front-wheel subsystem with the single-track vehicle (encoded-EKF paper
section V.B, parameters of section VI).

States [delta_f, delta_f_dot, beta, gamma]: front-wheel steering angle (rad) and rate, side-slip
angle (rad), yaw rate (rad/s). Input [tau_eq]: steering-motor torque at the front wheels (N m).
    Jeq delta_f'' + Beq delta_f' + Fs sgn(delta_f') + tau_e = tau_eq,
    tau_e = Cf (lc + lp) (delta_f - beta - lf gamma / V)   (self-aligning torque)
    [beta', gamma'] from the paper's bicycle model.
The Coulomb term sgn() is smoothed to tanh(delta_f' / vs) (vs = 0.01 rad/s) so that f is
differentiable and F exact (the paper's Jacobian uses a Kronecker delta there). RK4 per grid step.
Parameters (section VI): Jeq 9.498, Beq 24.312, Fs 2.68, Cf = Cr = 45000, lf 1.2, lr 1.05,
lc 0.016, lp 0.023, M 2000, Iz 1300, V 10 m/s.
Measurement groups: `steering_angle` (pinion angle sensor -> delta_f), `yaw_rate` (gamma),
`lateral_accel` (a_y = V (beta' + gamma), linear in the state).
"""

from __future__ import annotations

import numpy as np

from logscan.models.base import Actuators, GroupSpec, Model
from logscan.models.dispatch import STEER_BY_WIRE_ID

DEFAULTS = {
    "Jeq": 9.498,
    "Beq": 24.312,
    "Fs": 2.68,
    "Cf": 45000.0,
    "Cr": 45000.0,
    "lf": 1.2,
    "lr": 1.05,
    "lc": 0.016,
    "lp": 0.023,
    "M": 2000.0,
    "Iz": 1300.0,
    "V": 10.0,
    "vs": 0.01,  # rad/s, smoothing of the Coulomb friction sign
    "q_torque": 2.0,  # N m, std of the white torque disturbance on the steering
    "q_beta": 0.002,  # rad/s, white disturbance on beta'
    "q_gamma": 0.01,  # rad/s^2, white disturbance on gamma'
}
_ORDER = ("Jeq", "Beq", "Fs", "Cf", "Cr", "lf", "lr", "lc", "lp", "M", "Iz", "V", "vs")


class SteerByWire(Model):
    name = "steer_by_wire"
    model_id = STEER_BY_WIRE_ID
    state_names = ("delta_f", "delta_f_dot", "beta", "gamma")
    input_names = ("tau_eq",)
    groups = {
        "steering_angle": GroupSpec(
            "steering_angle",
            0,
            ("delta_f",),
            (0.002,),
            (-1.0,),
            (1.0,),
            ("rad",),
            direct_states=(0,),
        ),
        "yaw_rate": GroupSpec(
            "yaw_rate",
            1,
            ("gamma",),
            (0.005,),
            (-3.0,),
            (3.0,),
            ("rad/s",),
            direct_states=(3,),
        ),
        "lateral_accel": GroupSpec(
            "lateral_accel",
            2,
            ("a_y",),
            (0.05,),
            (-30.0,),
            (30.0,),
            ("m/s^2",),
        ),
    }

    def __init__(self, params: dict | None = None):
        super().__init__(params)
        self.p = self._merge_params(DEFAULTS)
        non_negative = ("lc", "lp", "Fs", "q_torque", "q_beta", "q_gamma")
        self._check_signs(positive=[k for k in _ORDER if k not in non_negative], non_negative=non_negative)
        self._pvec = np.array([self.p[k] for k in _ORDER], dtype=np.float64)

    def param_vector(self, dt: float | None = None) -> np.ndarray:
        return self._pvec.copy()

    def default_Q(self, dt: float) -> np.ndarray:
        """White torque disturbance on (delta_f, delta_f_dot) as a discrete white-acceleration
        block sigma^2 [[dt^4/4, dt^3/2], [dt^3/2, dt^2]] with sigma = q_torque / Jeq; beta and
        gamma get q^2 dt; 1e-12 on the diagonal keeps Q positive definite."""
        s2 = (self.p["q_torque"] / self.p["Jeq"]) ** 2
        Q = np.zeros((4, 4))
        Q[0, 0] = s2 * dt**4 / 4.0
        Q[0, 1] = Q[1, 0] = s2 * dt**3 / 2.0
        Q[1, 1] = s2 * dt**2
        Q[2, 2] = self.p["q_beta"] ** 2 * dt
        Q[3, 3] = self.p["q_gamma"] ** 2 * dt
        return Q + 1e-12 * np.eye(4)

    def state_scale(self) -> np.ndarray:
        return np.array([0.05, 0.1, 0.01, 0.05])

    def actuators(self) -> Actuators:
        """The steering motor, whose torque is the input."""
        return Actuators(("steering_motor",), np.eye(1), np.zeros(1))
