"""`wheeled`: a planar wheeled ground robot (differential or skid steer) whose wheels slip.

A real skid-steer robot's wheel odometry is wrong in a way a unicycle cannot hold: the wheels slip
(in turns by design: a skid-steer turns by skidding), so the distance they report is off by a
factor that drifts with the terrain, and the yaw rate they imply is off by more. This model takes
the yaw rate from a gyro where there is one (or the odometry's where not) and carries the two
errors as states, so a healthy drive is consistent and a sensor that departs from it is not.

States (8): x, y (m, a local east-north plane about the first position: ROS's REP 103 ENU), psi
(yaw, rad, counter-clockwise from east, not wrapped), b_w (rad/s, the yaw-rate input's bias), s
(the wheels' speed scale: 1 when the wheel odometry is exact, below 1 when they slip), g_x, g_y
(m, the GNSS receiver's error, below) and c (the ratio of the yaw rate the wheels imply to the
true one: 1 for a differential drive, above 1 for a skid steer that skids in turns).
Inputs (2): v (m/s, the wheels' forward speed: nav_msgs/Odometry twist.linear.x) and w (rad/s,
the yaw rate about up: a gyro's, or the odometry's twist.angular.z).
Discrete model (Euler step, `wheeled_predict_into`):
    x += s v cos(psi) dt,  y += s v sin(psi) dt,  psi += (w - b_w) dt,  b_w and s random walks.
Groups: `position` (x + g_x, y + g_y: a GNSS fix in the local east-north frame, `from =
"geodetic"` with `frame = "en"`), `heading` (psi: an absolute heading, e.g. a compass) and `wheel_yaw_rate` (the
odometry's own yaw rate, c (w - b_w), when w is a gyro's: the wheels checked against the gyro,
what a robot without GNSS can still be checked by).

The GNSS error g (2 states) is a first-order Gauss-Markov process, g_{k+1} = exp(-dt/tau) g_k +
w: a stand-alone receiver's error is mostly a slow wander (atmosphere, multipath, satellite
geometry) whose std it reports (NavSatFix position_covariance), not white noise; treated as white
it makes every window of innovations look inconsistent on a healthy drive. Its std
``gnss_error_std`` is the receiver's reported one in the built-in profile; ``gnss_error_tau``
300 s is the order of the satellite-geometry change that drives it. A jump or a ramp faster than
that is still a fault.

Process noise, as white-noise densities (Q(dt) = diag(q) dt):
 - ``speed_noise`` (m/s over ``speed_rate_hz``): the wheel speed's per-sample noise; position
   density q_xy = speed_noise^2 / speed_rate_hz (a white speed error integrated into position);
 - ``yaw_rate_noise`` (rad/s over ``yaw_rate_hz``): the yaw-rate input's per-sample noise; q_psi =
   yaw_rate_noise^2 / yaw_rate_hz;
 - ``gyro_bias_rw`` (rad/s/sqrt(s)): the bias's random walk (the ins model's default, PX4's
   EKF2_GYR_B_NOISE);
 - ``slip_rw`` (1/sqrt(s)): how fast the speed scale may change: 0.01 lets it move by 10 % in
   100 s, the change skid-steer slip shows between surfaces (grass, asphalt) and turns.
Initial state: position 0 +- 1 km (the first fix is the geodetic origin), heading unknown (P0 psi
= pi^2) until the robot moves, b_w 0 +- 0.02 rad/s, s 1 +- 0.2.
"""

from __future__ import annotations

import numpy as np

from logscan.models.base import GroupSpec, Model
from logscan.models.dispatch import WHEELED_ID

# |v| at or below this (m/s) is a robot at rest: a parked robot's wheel odometry, or a zero
# command, reads exactly 0; 1 mm/s is far below any drive and above float noise
REST_SPEED = 1e-3

DEFAULTS = {
    "speed_noise": 0.1,  # m/s, one wheel-speed sample's noise
    "speed_rate_hz": 10.0,  # Hz, the wheel odometry's rate
    "yaw_rate_noise": 0.02,  # rad/s, one yaw-rate sample's noise
    "yaw_rate_hz": 50.0,  # Hz, the yaw-rate input's rate
    "gyro_bias_rw": 1e-3,  # rad/s/sqrt(s)
    "slip_rw": 0.01,  # 1/sqrt(s)
    "gnss_error_std": 1.0,  # m, the steady-state std of the receiver's slowly wandering error
    "gnss_error_tau": 300.0,  # s, its correlation time
}


class Wheeled(Model):
    name = "wheeled"
    model_id = WHEELED_ID
    state_names = (
        "x",
        "y",
        "psi",
        "yaw_rate_bias",
        "speed_scale",
        "gnss_error_x",
        "gnss_error_y",
        "yaw_rate_ratio",
    )
    input_names = ("v", "w")
    rest_inputs = (0,)  # `at_rest` reads the wheel speed v
    motion_inputs = (1,)  # the yaw rate w shakes while the robot drives (a gyro's)
    motion_group = "position"  # and the GNSS moves
    inputs_are_sensors = True  # wheel odometry and a gyro: readings, not commands
    groups = {
        # not direct: the receiver's error adds to x, y; gated: that error is a wander of tau_g
        "position": GroupSpec("position", 0, ("x", "y"), (1.0, 1.0), (-1e6, -1e6), (1e6, 1e6), ("m", "m"), gated=True),
        "heading": GroupSpec(
            "heading", 1, ("psi",), (0.1,), (-6.4,), (6.4,), ("rad",), wrap=(True,), direct_states=(2,)
        ),
        # the wheels' own yaw rate (odometry twist.angular.z) against the gyro's: c (w - b_w)
        "wheel_yaw_rate": GroupSpec(
            "wheel_yaw_rate", 2, ("yaw_rate",), (0.05,), (-20.0,), (20.0,), ("rad/s",), steady=True
        ),
    }

    def __init__(self, params: dict | None = None):
        super().__init__(params)
        self.p = self._merge_params(DEFAULTS)
        self._check_signs(
            positive=("speed_noise", "speed_rate_hz", "yaw_rate_noise", "yaw_rate_hz", "gnss_error_tau"),
            non_negative=("gyro_bias_rw", "slip_rw", "gnss_error_std"),
        )

    def param_vector(self, dt: float | None = None) -> np.ndarray:
        return np.array([self.p["gnss_error_tau"]])

    def default_x0(self) -> np.ndarray:
        return np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0])

    def state_scale(self) -> np.ndarray:
        # P0 = diag(state_scale^2): position anywhere within 1 km of the origin (a geodetic group's
        # origin is the first fix), heading unknown, the receiver's error at its steady state
        g = max(self.p["gnss_error_std"], 1e-6)
        return np.array([1e3, 1e3, np.pi, 0.02, 0.2, g, g, 0.5])

    def at_rest(self, u: np.ndarray) -> np.ndarray:
        """The steps whose wheel speed v (measured or commanded) is at most REST_SPEED (`rest_inputs`)."""
        return np.abs(np.asarray(u, dtype=np.float64)[:, 0]) <= REST_SPEED

    def rest_position_var(self, duration_s: float) -> float:
        """The Gauss-Markov GNSS error's change over ``duration_s``: 2 g^2 (1 - exp(-T / tau_g))."""
        return 2.0 * self.p["gnss_error_std"] ** 2 * -np.expm1(-duration_s / self.p["gnss_error_tau"])

    def default_Q(self, dt: float) -> np.ndarray:
        """Q = diag(q_xy, q_xy, q_psi, gyro_bias_rw^2, slip_rw^2, ., ., slip_rw^2) dt (module docstring), and the
        Gauss-Markov GNSS error's exact step variance sigma_g^2 (1 - exp(-2 dt / tau_g)); 1e-12
        on the diagonal keeps it positive definite when a density is 0."""
        p = self.p
        q_xy = p["speed_noise"] ** 2 / p["speed_rate_hz"]
        q_psi = p["yaw_rate_noise"] ** 2 / p["yaw_rate_hz"]
        q = np.array([q_xy, q_xy, q_psi, p["gyro_bias_rw"] ** 2, p["slip_rw"] ** 2]) * dt
        g = p["gnss_error_std"] ** 2 * -np.expm1(-2.0 * dt / p["gnss_error_tau"])
        c = p["slip_rw"] ** 2 * dt  # the turning slip changes with the ground as the speed scale does
        return np.diag(np.concatenate([q, [g, g, c]])) + 1e-12 * np.eye(8)
