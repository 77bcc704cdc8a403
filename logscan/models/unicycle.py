"""The unicycle (differential-drive robot seen from above) of the checkpointing / roll-forward-
recovery paper's ground robot: its outer, trajectory loop (section 6.3, appendix A.6.1).

States [x, y, theta]: position (m) in a fixed plane frame and heading (rad, counter-clockwise from
+x, not wrapped: it grows by 2 pi per turn). Inputs [v, w]: forward speed (m/s) and yaw rate
(rad/s). Discrete model (eq. 23, with the "x_k +" its print omits), an Euler step:
    x_{k+1} = x_k + [v cos theta, v sin theta, w]^T dt
with Jacobian F = I + A dt, A of eq. 36. One measurement group `mocap` (motion capture, eq. 24)
measuring (x, y, theta) directly; theta's innovation is wrapped to (-pi, pi], so a mocap that
reports the heading wrapped (as `logscan simulate ground_robot` logs it) and an unwrapped state
agree.

Process noise: the paper's Q = 0.1^2 I per outer step (10 Hz) as a white-noise density q per
state, Q(dt) = q dt I (q_xy, q_theta = 0.1^2 / 0.1 s = 0.1 m^2/s, rad^2/s): at 10 Hz the
per-step Q is exactly 0.1^2 I, and it scales with the grid period on other grids.
Measurement noise: the paper's R = 0.1^2 I (noise_std 0.1 m, 0.1 m, 0.1 rad).
"""

from __future__ import annotations

import numpy as np

from logscan.models.base import GroupSpec, Model
from logscan.models.dispatch import UNICYCLE_ID

DEFAULTS = {
    "q_xy": 0.1,  # m^2/s: white-noise density of x and y (0.1^2 per 0.1 s step)
    "q_theta": 0.1,  # rad^2/s: of theta
}


class Unicycle(Model):
    name = "unicycle"
    model_id = UNICYCLE_ID
    state_names = ("x", "y", "theta")
    input_names = ("v", "w")
    groups = {
        "mocap": GroupSpec(
            "mocap",
            0,
            ("x", "y", "theta"),
            (0.1, 0.1, 0.1),
            (-1e5, -1e5, -6.4),
            (1e5, 1e5, 6.4),
            ("m", "m", "rad"),
            wrap=(False, False, True),
            direct_states=(0, 1, 2),
        ),
        # the same sensor as two groups, so a detector can flag its position alone (the paper's
        # attack moves x and y, G = [1, 1, 0]) and recovery keeps using its heading
        "position": GroupSpec(
            "position", 1, ("x", "y"), (0.1, 0.1), (-1e5, -1e5), (1e5, 1e5), ("m", "m"), direct_states=(0, 1)
        ),
        "heading": GroupSpec(
            "heading", 2, ("theta",), (0.1,), (-6.4,), (6.4,), ("rad",), wrap=(True,), direct_states=(2,)
        ),
    }

    def __init__(self, params: dict | None = None):
        super().__init__(params)
        self.p = self._merge_params(DEFAULTS)
        self._check_signs(non_negative=("q_xy", "q_theta"))

    def param_vector(self, dt: float | None = None) -> np.ndarray:
        return np.zeros(1)  # the Euler step reads no parameter

    def default_Q(self, dt: float) -> np.ndarray:
        """Q = diag(q_xy, q_xy, q_theta) dt (the paper's 0.1^2 I at its 10 Hz outer loop); 1e-12
        on the diagonal keeps it positive definite when a density is 0."""
        return np.diag([self.p["q_xy"], self.p["q_xy"], self.p["q_theta"]]) * dt + 1e-12 * np.eye(3)

    def state_scale(self) -> np.ndarray:
        return np.array([1.0, 1.0, 0.5])
