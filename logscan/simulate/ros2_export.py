"""A ROS 2 MCAP (CDR, standard message types, REP 103 frames) of a `logscan simulate ins` run.

`write_ros2_mcap(sim, path)` writes what a ROS 2 robot would have recorded of the simulated flight:

 - ``/imu/data`` ``sensor_msgs/msg/Imu`` at the simulator's IMU rate (250 Hz): the logged IMU
   (``sim.u_cmd``: gyro then accelerometer, body FRD, faults included) turned into body FLU
   (y and z negated); ``orientation`` the true attitude as a body-FLU-to-world-ENU quaternion;
   covariances: the model's gyro / accelerometer noise squared on the diagonals;
 - ``/gps/fix`` ``sensor_msgs/msg/NavSatFix`` at the GNSS rate (10 Hz): the simulated NED position
   fixes (``sim.z``'s ``gnss_position``, noise and faults included) as WGS-84 latitude, longitude
   and ellipsoidal altitude about ``origin`` (exactly: local tangent plane -> ECEF -> geodetic),
   ``position_covariance`` the group's noise (ENU, diagonal known);
 - ``/odom`` ``nav_msgs/msg/Odometry`` at 50 Hz from the truth: ``pose.pose.position`` in ENU
   about the origin, ``pose.pose.orientation`` the attitude plus N(0, ODOM_ATTITUDE_STD) on roll,
   pitch and yaw (ENU/FLU quaternion), ``twist.twist.linear`` the body velocity in FLU plus
   N(0, ODOM_VELOCITY_STD), ``twist.twist.angular`` the true body rate (FLU); covariances the
   noise added.

Header stamps equal the MCAP log times: START_NS plus the simulation time. The ground truth (the
fault events, as `logscan simulate` records them) is embedded as the metadata record
``logscan.truth``; no profile is: the log gets the built-in ``ros2`` profile
(`logscan.profiles.builtin`), as a real ROS 2 recording does. `write_sample` writes the shipped
sample (sample_logs/ros2_ins.mcap; sample_logs/make_samples.py calls it).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from logscan.conversions import (
    WGS84_A,
    WGS84_E2,
    euler_matrix,
    euler_to_quaternion,
    geodetic_to_ecef,
    quaternion_enu_flu_to_ned_frd,
)

#: PX4's default SITL home: latitude deg, longitude deg, altitude m (WGS-84 ellipsoid)
ORIGIN = (47.397742, 8.545594, 488.0)
START_NS = 1_700_000_000 * 1_000_000_000  # the header stamp of simulation time 0
IMU_TOPIC = "/imu/data"
GNSS_TOPIC = "/gps/fix"
ODOM_TOPIC = "/odom"
ODOM_HZ = 50.0
ODOM_VELOCITY_STD = 0.1  # m/s per body axis (the ins model's odometry default)
ODOM_ATTITUDE_STD = 0.02  # rad on roll, pitch and yaw (the ins model's attitude default)
ODOM_POSITION_STD = 0.05  # m per ENU axis (not used by the ros2 profile)
IMU_ORIENTATION_STD = 0.01  # rad, the reported orientation covariance (the orientation is the truth)
SAMPLE_SEED = 21
SAMPLE_DURATION_S = 35.0

_SEP = "=" * 80
_HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
_TIME = "int32 sec\nuint32 nanosec\n"
_VECTOR3 = "float64 x\nfloat64 y\nfloat64 z\n"
_QUATERNION = "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n"


def _msgdef(main: str, deps: dict[str, str]) -> str:
    """A ROS 2 concatenated message definition: the main text, then each dependency after a
    ``====`` line and ``MSG: pkg/Type``."""
    return main + "".join(f"{_SEP}\nMSG: {name}\n{text}" for name, text in deps.items())


IMU_MSGDEF = _msgdef(
    "std_msgs/Header header\n"
    "geometry_msgs/Quaternion orientation\n"
    "float64[9] orientation_covariance\n"
    "geometry_msgs/Vector3 angular_velocity\n"
    "float64[9] angular_velocity_covariance\n"
    "geometry_msgs/Vector3 linear_acceleration\n"
    "float64[9] linear_acceleration_covariance\n",
    {
        "std_msgs/Header": _HEADER,
        "builtin_interfaces/Time": _TIME,
        "geometry_msgs/Quaternion": _QUATERNION,
        "geometry_msgs/Vector3": _VECTOR3,
    },
)
NAVSATFIX_MSGDEF = _msgdef(
    "uint8 COVARIANCE_TYPE_UNKNOWN=0\n"
    "uint8 COVARIANCE_TYPE_APPROXIMATED=1\n"
    "uint8 COVARIANCE_TYPE_DIAGONAL_KNOWN=2\n"
    "uint8 COVARIANCE_TYPE_KNOWN=3\n"
    "std_msgs/Header header\n"
    "sensor_msgs/NavSatStatus status\n"
    "float64 latitude\n"
    "float64 longitude\n"
    "float64 altitude\n"
    "float64[9] position_covariance\n"
    "uint8 position_covariance_type\n",
    {
        "std_msgs/Header": _HEADER,
        "builtin_interfaces/Time": _TIME,
        "sensor_msgs/NavSatStatus": (
            "int8 STATUS_NO_FIX=-1\nint8 STATUS_FIX=0\nint8 STATUS_SBAS_FIX=1\nint8 STATUS_GBAS_FIX=2\n"
            "int8 status\n"
            "uint16 SERVICE_GPS=1\nuint16 SERVICE_GLONASS=2\nuint16 SERVICE_COMPASS=4\nuint16 SERVICE_GALILEO=8\n"
            "uint16 service\n"
        ),
    },
)
ODOMETRY_MSGDEF = _msgdef(
    "std_msgs/Header header\n"
    "string child_frame_id\n"
    "geometry_msgs/PoseWithCovariance pose\n"
    "geometry_msgs/TwistWithCovariance twist\n",
    {
        "std_msgs/Header": _HEADER,
        "builtin_interfaces/Time": _TIME,
        "geometry_msgs/PoseWithCovariance": "geometry_msgs/Pose pose\nfloat64[36] covariance\n",
        "geometry_msgs/Pose": "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
        "geometry_msgs/Point": _VECTOR3,
        "geometry_msgs/Quaternion": _QUATERNION,
        "geometry_msgs/TwistWithCovariance": "geometry_msgs/Twist twist\nfloat64[36] covariance\n",
        "geometry_msgs/Twist": "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n",
        "geometry_msgs/Vector3": _VECTOR3,
    },
)


def local_to_geodetic(ned: np.ndarray, origin=ORIGIN) -> np.ndarray:
    """WGS-84 (latitude deg, longitude deg, ellipsoidal altitude m), (N, 3), of local NED points
    (N, 3) about ``origin``: the exact inverse of `logscan.conversions.geodetic_to_local`
    (tangent plane -> ECEF, then latitude by fixed-point iteration to below 1e-12 rad)."""
    ned = np.asarray(ned, dtype=np.float64).reshape(-1, 3)
    o = np.asarray(origin, dtype=np.float64).reshape(1, 3)
    lat0, lon0 = np.radians(o[0, 0]), np.radians(o[0, 1])
    sl, cl, so, co = np.sin(lat0), np.cos(lat0), np.sin(lon0), np.cos(lon0)
    east, north, up = ned[:, 1], ned[:, 0], -ned[:, 2]
    ecef = geodetic_to_ecef(o) + np.stack(
        [
            -so * east - sl * co * north + cl * co * up,
            co * east - sl * so * north + cl * so * up,
            cl * north + sl * up,
        ],
        axis=1,
    )
    x, y, z = ecef.T
    lon = np.arctan2(y, x)
    p = np.hypot(x, y)
    lat = np.arctan2(z, p * (1.0 - WGS84_E2))
    h = np.zeros_like(lat)
    for _ in range(20):
        n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
        h = p / np.cos(lat) - n
        new = np.arctan2(z, p * (1.0 - WGS84_E2 * n / (n + h)))
        done = np.max(np.abs(new - lat)) < 1e-12
        lat = new
        if done:
            break
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    h = p / np.cos(lat) - n
    return np.stack([np.degrees(lat), np.degrees(lon), h], axis=1)


def ros_quaternion(euler: np.ndarray) -> np.ndarray:
    """ROS orientations (N, 4) = (w, x, y, z), body FLU to world ENU, of NED/FRD ZYX Euler angles
    (N, 3): q_enu_flu = q_T * q_ned_frd * q_B (T and B are their own inverses, so the conversion
    `quaternion_enu_flu_to_ned_frd` is its own inverse up to the sign of q)."""
    return quaternion_enu_flu_to_ned_frd(euler_to_quaternion(euler))


def _stamp(t_ns: int) -> dict:
    return {"sec": int(t_ns // 1_000_000_000), "nanosec": int(t_ns % 1_000_000_000)}


def _vector(v) -> dict:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def _quaternion(q) -> dict:
    return {"x": float(q[1]), "y": float(q[2]), "z": float(q[3]), "w": float(q[0])}


def _diag(values, size: int) -> list[float]:
    """A row-major size x size covariance with ``values`` on its diagonal (the rest 0)."""
    out = np.zeros((size, size))
    out[np.arange(len(values)), np.arange(len(values))] = values
    return [float(v) for v in out.ravel()]


def ros2_truth(sim, origin=ORIGIN) -> dict:
    """The simulation's ground-truth document for its ROS 2 log: fault events and transients as
    `logscan simulate` records them; the true states are not in the log (no truth topic)."""
    truth = dict(sim.truth())
    truth.pop("true_state_topic", None)
    truth.pop("true_state_fields", None)
    truth["generator"] = "logscan.simulate.ros2_export"
    truth["imu_topic"] = IMU_TOPIC
    gyro, accel = float(sim.scenario.model.p["gyro_noise"]), float(sim.scenario.model.p["accel_noise"])
    truth["imu_noise_std"] = {
        **{f"{IMU_TOPIC}/angular_velocity.{a}": gyro for a in "xyz"},
        **{f"{IMU_TOPIC}/linear_acceleration.{a}": accel for a in "xyz"},
    }
    truth["origin"] = [float(v) for v in origin]
    return truth


def write_ros2_mcap(
    sim, path: str | os.PathLike, origin=ORIGIN, *, start_ns: int = START_NS, truth: bool = True
) -> Path:
    """Write the ROS 2 MCAP of ``sim`` (a `Simulation` of the ``ins`` model) to ``path`` (see the
    module docstring), with its ground truth embedded unless ``truth`` is False; the same
    simulation gives the same bytes (the odometry noise is seeded by its seed). Returns the path."""
    from mcap_ros2.writer import Writer

    sc = sim.scenario
    if sc.model.name != "ins":
        raise ValueError(f"write_ros2_mcap needs a simulation of the ins model, got {sc.model.name!r}")
    path = Path(path)
    t_ns = start_ns + np.round(np.arange(sim.n_steps) * sim.dt * 1e9).astype(np.int64)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        writer = Writer(fh)
        if truth:
            writer.add_metadata("logscan.truth", {"json": json.dumps(ros2_truth(sim, origin), indent=2) + "\n"})
        imu_schema = writer.register_msgdef("sensor_msgs/msg/Imu", IMU_MSGDEF)
        fix_schema = writer.register_msgdef("sensor_msgs/msg/NavSatFix", NAVSATFIX_MSGDEF)
        odom_schema = writer.register_msgdef("nav_msgs/msg/Odometry", ODOMETRY_MSGDEF)
        # (t_ns, order, topic, schema, message)
        messages = [
            *_imu_messages(sim, t_ns, imu_schema),
            *_gnss_messages(sim, t_ns, fix_schema, origin),
            *_odometry_messages(sim, t_ns, odom_schema),
        ]
        messages.sort(key=lambda m: (m[0], m[1]))
        for t, _, topic, schema, message in messages:
            writer.write_message(topic, schema, message, log_time=t, publish_time=t)
        writer.finish()
    os.replace(tmp, path)
    return path


_Message = tuple[int, int, str, object, dict]  # (t_ns, order at equal times, topic, schema, message)
_FLU = np.array([1.0, -1.0, -1.0])  # FRD -> FLU, per axis


def _imu_messages(sim, t_ns: np.ndarray, imu_schema) -> list[_Message]:
    """IMU: every simulator step, FRD -> FLU, the true attitude as its orientation."""
    sc, flu = sim.scenario, _FLU
    gyro_std, accel_std = float(sc.model.p["gyro_noise"]), float(sc.model.p["accel_noise"])
    euler = sim.x_true[:, 6:9]
    messages: list[_Message] = []
    gyro = sim.u_cmd[:, 0:3] * flu
    accel = sim.u_cmd[:, 3:6] * flu
    q_imu = ros_quaternion(euler)
    imu_cov = (
        _diag([IMU_ORIENTATION_STD**2] * 3, 3),
        _diag([gyro_std**2] * 3, 3),
        _diag([accel_std**2] * 3, 3),
    )
    for k in range(sim.n_steps):
        messages.append(
            (
                int(t_ns[k]),
                0,
                IMU_TOPIC,
                imu_schema,
                {
                    "header": {"stamp": _stamp(t_ns[k]), "frame_id": "imu_link"},
                    "orientation": _quaternion(q_imu[k]),
                    "orientation_covariance": imu_cov[0],
                    "angular_velocity": _vector(gyro[k]),
                    "angular_velocity_covariance": imu_cov[1],
                    "linear_acceleration": _vector(accel[k]),
                    "linear_acceleration_covariance": imu_cov[2],
                },
            )
        )
    return messages


def _gnss_messages(sim, t_ns: np.ndarray, fix_schema, origin) -> list[_Message]:
    """GNSS: the simulated NED fixes (noise and faults included) as latitude, longitude, altitude;
    a run without GNSS: the truth at 10 Hz."""
    sc, n, dt = sim.scenario, sim.n_steps, sim.dt
    ned = sim.x_true[:, 0:3]
    messages: list[_Message] = []
    groups = {g.name: g for g in sc.groups}
    gnss = groups.get("gnss_position")
    if gnss is not None:
        cols = sim.group_slices()["gnss_position"]
        steps = np.arange(0, n, gnss.ratio)
        fixes = sim.z[steps, cols]
        std = np.asarray(gnss.noise_std, dtype=np.float64)  # north, east, down
    else:  # a run without GNSS: the truth at 10 Hz
        steps = np.arange(0, n, max(1, int(round(0.1 / dt))))
        fixes, std = ned[steps], np.array([0.5, 0.5, 1.0])
    lla = local_to_geodetic(fixes, origin)
    fix_cov = _diag([std[1] ** 2, std[0] ** 2, std[2] ** 2], 3)  # ENU
    for k, row in zip(steps, lla):
        messages.append(
            (
                int(t_ns[k]),
                1,
                GNSS_TOPIC,
                fix_schema,
                {
                    "header": {"stamp": _stamp(t_ns[k]), "frame_id": "gps_link"},
                    "status": {"status": 0, "service": 1},
                    "latitude": float(row[0]),
                    "longitude": float(row[1]),
                    "altitude": float(row[2]),
                    "position_covariance": fix_cov,
                    "position_covariance_type": 2,
                },
            )
        )
    return messages


def _odometry_messages(sim, t_ns: np.ndarray, odom_schema) -> list[_Message]:
    """Odometry at ODOM_HZ from the truth, with noise seeded by the simulation's seed."""
    sc, n, dt, flu = sim.scenario, sim.n_steps, sim.dt, _FLU
    gyro_std = float(sc.model.p["gyro_noise"])
    euler, ned, v_ned = sim.x_true[:, 6:9], sim.x_true[:, 0:3], sim.x_true[:, 3:6]
    rng = np.random.default_rng([sim.seed, 2103])  # the odometry's noise
    messages: list[_Message] = []
    steps = np.arange(0, n, max(1, int(round(1.0 / (ODOM_HZ * dt)))))
    m = steps.size
    R = euler_matrix(euler[steps])
    v_body = np.einsum("kji,kj->ki", R, v_ned[steps])  # R^T v, FRD
    v_body += rng.standard_normal((m, 3)) * ODOM_VELOCITY_STD
    q_odom = ros_quaternion(euler[steps] + rng.standard_normal((m, 3)) * ODOM_ATTITUDE_STD)
    enu = ned[steps][:, [1, 0, 2]] * np.array([1.0, 1.0, -1.0]) + rng.standard_normal((m, 3)) * ODOM_POSITION_STD
    rate = sim.u_act[steps, 0:3] * flu
    pose_cov = _diag([ODOM_POSITION_STD**2] * 3 + [ODOM_ATTITUDE_STD**2] * 3, 6)
    twist_cov = _diag([ODOM_VELOCITY_STD**2] * 3 + [gyro_std**2] * 3, 6)
    for j, k in enumerate(steps):
        messages.append(
            (
                int(t_ns[k]),
                2,
                ODOM_TOPIC,
                odom_schema,
                {
                    "header": {"stamp": _stamp(t_ns[k]), "frame_id": "odom"},
                    "child_frame_id": "base_link",
                    "pose": {
                        "pose": {"position": _vector(enu[j]), "orientation": _quaternion(q_odom[j])},
                        "covariance": pose_cov,
                    },
                    "twist": {
                        "twist": {"linear": _vector(v_body[j] * flu), "angular": _vector(rate[j])},
                        "covariance": twist_cov,
                    },
                },
            )
        )
    return messages


def write_sample(path: str | os.PathLike, faults=(), *, duration: float = SAMPLE_DURATION_S, seed: int = SAMPLE_SEED):
    """Simulate the ``ins`` model (``faults``: `FaultSpec`s or ``--fault`` texts) and write its
    ROS 2 MCAP to ``path``: sample_logs/ros2_ins.mcap is ``write_sample(path)``."""
    from logscan.simulate import parse_fault, simulate

    specs = [parse_fault(f) if isinstance(f, str) else f for f in faults]
    return write_ros2_mcap(simulate("ins", specs, duration=duration, seed=seed), path)
