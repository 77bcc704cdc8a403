"""The vehicle-agnostic IMU-driven inertial navigation model `ins` (docs/algorithms.md section 6.7).

No vehicle parameters: the IMU (angular rate and specific force, body FRD) is the model's input and
drives a strapdown prediction; the aiding sensors are the measurement groups. This is the structure
of the Kalman-gain-norm paper's estimator, and what lets every detector run on a real log that
carries no mass, inertia or mixer.

States (16): north, east, down position and velocity in a local NED frame, roll, pitch, yaw (ZYX,
body-to-NED), gyro biases, accelerometer biases, and the barometer's offset from the position's
down axis (a barometer reads altitude above sea level, the position is relative to an origin). The
covariance is over the error state with a body-frame attitude error, updated multiplicatively
(`boxplus`), so it stays well posed at any attitude (see logscan.models.ins_kernels).

Conventions: gravity g along +down, the Earth flat and not rotating (its 7.3e-5 rad/s rate is
below a MEMS gyro's bias instability, and the flights logged are short and local), no lever arms
(the GNSS antenna at the IMU), the IMU sample held over the grid period.

Noise defaults follow PX4's EKF2 defaults where it has one (accelerometer 0.35 m/s^2 and gyro
0.015 rad/s per sample, vibration included; bias random walks 3e-3 m/s^2/sqrt(s) and
1e-3 rad/s/sqrt(s); GNSS position 0.5 m, velocity 0.3 m/s).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from logscan.models.base import GroupSpec, Model
from logscan.models.dispatch import INS_ID
from logscan.models.ins_kernels import INS_N, ins_boxplus_into, so3_exp_jr_into
from logscan.models.quadcopter import Quadcopter

DEFAULTS = {
    "g": 9.80665,  # m/s^2, standard gravity
    "accel_noise": 0.35,  # m/s^2, std of one accelerometer sample (vibration included)
    "gyro_noise": 0.015,  # rad/s, std of one gyro sample
    "accel_bias_rw": 3e-3,  # m/s^2 / sqrt(s), accelerometer bias random walk
    "gyro_bias_rw": 1e-3,  # rad/s / sqrt(s), gyro bias random walk
    "baro_offset_rw": 0.05,  # m / sqrt(s), drift of the barometer's offset (weather, heating)
}

_ATT = ("roll", "pitch", "yaw")


class Ins(Model):
    name = "ins"
    model_id = INS_ID
    state_names = (
        "north",
        "east",
        "down",
        "v_north",
        "v_east",
        "v_down",
        *_ATT,
        "gyro_bias_x",
        "gyro_bias_y",
        "gyro_bias_z",
        "accel_bias_x",
        "accel_bias_y",
        "accel_bias_z",
        "baro_offset",
    )
    input_names = ("gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z")
    inputs_are_sensors = True  # the IMU: its faults are sensor faults (the KGN blindness probe tries them)
    # the GNSS velocity integrates to its position on each axis, and down to minus the barometer's altitude
    kinematic_pairs = tuple(("gnss_velocity", i, "gnss_position", i, 1.0) for i in range(3)) + (
        ("gnss_velocity", 2, "baro", 0, -1.0),
    )
    kinematic_inputs = (3, 4, 5)  # the accelerometer's specific force, integrated twice
    kinematic_witnesses = frozenset({"baro"})  # the GNSS position comes from the velocity's receiver
    kinematic_input_words = "IMU accelerometer"
    groups = {
        "gnss_position": GroupSpec(
            "gnss_position",
            0,
            ("north", "east", "down"),
            (0.5, 0.5, 1.0),
            (-1e7,) * 3,
            (1e7,) * 3,
            ("m",) * 3,
            direct_states=(0, 1, 2),
        ),
        "gnss_velocity": GroupSpec(
            "gnss_velocity",
            1,
            ("v_north", "v_east", "v_down"),
            (0.3, 0.3, 0.5),
            (-300.0,) * 3,
            (300.0,) * 3,
            ("m/s",) * 3,
            direct_states=(3, 4, 5),
        ),
        "baro": GroupSpec("baro", 2, ("altitude",), (1.0,), (-20000.0,), (20000.0,), ("m",)),
        "heading": GroupSpec(
            "heading",
            3,
            ("yaw",),
            (0.1,),
            (-6.4,),
            (6.4,),
            ("rad",),
            wrap=(True,),
            direct_states=(8,),
        ),
        # the quadcopter's (ZYX Euler angles, wrapped, observing roll, pitch, yaw directly)
        "attitude": replace(Quadcopter.groups["attitude"], group_id=4),
        "odometry": GroupSpec(
            "odometry",
            5,
            ("v_forward", "v_right", "v_down"),
            (0.1, 0.1, 0.1),
            (-100.0,) * 3,
            (100.0,) * 3,
            ("m/s",) * 3,
        ),
    }

    def __init__(self, params: dict | None = None):
        super().__init__(params)
        self.p = self._merge_params(DEFAULTS)
        self._check_signs(positive=("g", "accel_noise", "gyro_noise"), non_negative=tuple(DEFAULTS)[3:])

    def param_vector(self, dt: float | None = None) -> np.ndarray:
        return np.array([self.p["g"]], dtype=np.float64)

    def default_Q(self, dt: float) -> np.ndarray:
        """Discrete noise of one step of the error state: per axis, the accelerometer sample
        noise s_a into (position, velocity) as s_a^2 [[dt^4/4, dt^3/2], [dt^3/2, dt^2]]; the
        gyro's into the attitude error, (s_g dt)^2; random walks q into the biases and the
        barometer offset, q^2 dt; plus 1e-12 on the diagonal (positive definite)."""
        p = self.p
        Q = np.zeros((INS_N, INS_N))
        s2 = p["accel_noise"] ** 2
        for i in range(3):
            Q[i, i] = s2 * dt**4 / 4.0
            Q[i, 3 + i] = Q[3 + i, i] = s2 * dt**3 / 2.0
            Q[3 + i, 3 + i] = s2 * dt**2
            Q[6 + i, 6 + i] = (p["gyro_noise"] * dt) ** 2
            Q[9 + i, 9 + i] = p["gyro_bias_rw"] ** 2 * dt
            Q[12 + i, 12 + i] = p["accel_bias_rw"] ** 2 * dt
        Q[15, 15] = p["baro_offset_rw"] ** 2 * dt
        return Q + 1e-12 * np.eye(INS_N)

    def state_scale(self) -> np.ndarray:
        return np.array([10.0] * 3 + [2.0] * 3 + [0.2, 0.2, 0.5] + [0.02] * 3 + [0.3] * 3 + [10.0])

    def default_P0(self) -> np.ndarray:
        """diag(state_scale^2), except the barometer offset: 1 km (a barometer reads altitude
        above sea level, anywhere from the shore to the mountains)."""
        P0 = np.diag(np.square(self.state_scale()))
        P0[15, 15] = 1000.0**2
        return P0

    def hover_input(self) -> np.ndarray:
        """The IMU at rest, level: no rotation, specific force g up (-g along body down)."""
        return np.array([0.0, 0.0, 0.0, 0.0, 0.0, -self.p["g"]])

    # --- the error-state chart ------------------------------------------------------------------
    def boxplus(self, x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        out = np.empty(INS_N)
        ins_boxplus_into(self.param_vector(), _vec(x), _vec(dx), out, np.empty((3, 3)), np.empty((3, 3, 3)))
        return out

    def boxminus(self, x1: np.ndarray, x0: np.ndarray) -> np.ndarray:
        """dx with x0 (+) dx = x1: differences, the attitude's as Log(R0^T R1)."""
        x1, x0 = _vec(x1), _vec(x0)
        d = x1 - x0
        d[6:9] = so3_log(euler_rotation(*x0[6:9]).T @ euler_rotation(*x1[6:9]))
        return d


def euler_rotation(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Body-to-world R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def so3_exp(w: np.ndarray) -> np.ndarray:
    E, Jr = np.empty((3, 3)), np.empty((3, 3))
    so3_exp_jr_into(float(w[0]), float(w[1]), float(w[2]), E, Jr)
    return E


def so3_log(R: np.ndarray) -> np.ndarray:
    """The rotation vector w with Exp(w) = R (|w| < pi)."""
    c = np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)
    t = np.arccos(c)
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if t < 1e-6:
        return 0.5 * v
    return t / (2.0 * np.sin(t)) * v


def _vec(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).reshape(-1)
