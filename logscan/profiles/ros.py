"""The built-in profiles of ROS logs (a ROS 2 MCAP, a ROS 1 bag, a rosbag2 database or directory).

Topics are chosen by message type, never by name (the first topic of each type, in the file's
order), in ROS frames (REP 103: world ENU, body FLU), and the model by what the robot is:

 - ``ros_wheeled``, the `wheeled` model, for a ground robot: its ``nav_msgs/Odometry`` twist is
   planar (linear y, z and angular x, y identically 0: what a 2-D drive controller publishes), or
   without odometry its ``geometry_msgs/Twist`` / ``TwistStamped`` velocity commands are (`Wheels`).
   Inputs: the forward speed (twist.linear.x, measured or commanded) and the yaw rate: the IMU's
   gyro about the axis gravity shows is up (`imu_up_axis`), confirmed against the wheels' yaw rate,
   else the wheels' own; ``position`` from ``sensor_msgs/NavSatFix`` in the local east-north plane
   (a ground robot's altitude follows terrain the model does not know: not checked, and said so);
   ``wheel_yaw_rate``, the odometry's yaw rate against the gyro's. ``sensor_msgs/JointState`` wheel
   speeds are not used: turning them into a speed needs the wheel radius and track (a note says so).
 - ``ros``, the IMU-driven `ins` model, for anything else with an IMU (MIN_IMU_HZ or faster; a
   warning below INS_NOMINAL_IMU_HZ, the grid follows the IMU) and a position or velocity source:
   ``gnss_position`` from NavSatFix, ``odometry`` from Odometry's twist.twist.linear (body FLU),
   ``attitude`` from its pose.pose.orientation.

Noise from the messages' covariances with ROS's conventions (`covariance_std`): -1, 0 or a value
of UNKNOWN_COVARIANCE or more on a diagonal is "unknown" (REP 145; drivers put 1e6 or 1e9 there):
the model's default is used and the profile says so. A stand-alone receiver's reported position
covariance (position_covariance_type below DIAGONAL_KNOWN) is its guess from the satellite
geometry, not an error bound, and a GNSS error wanders slowly: the `wheeled` model carries it as a
Gauss-Markov state of GPS_SPS_SIGMA_M (the GPS Standard Positioning Service's accuracy standard)
unless the receiver says it knows its covariance.

What cannot be decided (no IMU nor odometry, nothing to check the IMU against) still gives a
profile: commented, with ``BuiltProfile.model_not_run`` saying why, so `init-profile` writes
something to edit and `analyze` says "not checked" instead of guessing.

The topics and their covariances are found by `logscan.profiles.ros_topics` (`Found`, `Wheels`,
`covariance_std`); the ``ros_wheeled`` profile is built by `logscan.profiles.ros_wheeled` (with
`imu_up_axis` and GPS_SPS_SIGMA_M), the ``ros`` profile here.
"""

from __future__ import annotations

import re

import numpy as np

from logscan.docs import doc_url
from logscan.models import get_model
from logscan.profiles.built import BuiltProfile, nice_rate, toml_list
from logscan.profiles.ros_topics import (
    AXES,
    DIAGONAL3,
    MIN_IMU_HZ,
    ROS_ENCODINGS,
    ROS_IMU,
    ROS_NAVSATFIX,
    ROS_ODOMETRY,
    ROS_TYPES,
    Found,
    covariance_std,
    fix_gate_lines,
    fix_status_mode_lines,
    noise_line,
    undecided,
)
from logscan.profiles.ros_wheeled import wheeled_profile

INS_NOMINAL_IMU_HZ = 50.0  # the ins model's design rate (PX4 logs 100-250 Hz): slower is coarser, said so
_ROS_SCHEMA = re.compile(r"^[A-Za-z][\w]*/msg/[A-Za-z]\w*$")


def is_ros_topic(encoding: str, schema: str) -> bool:
    """A ROS topic: CDR (ROS 2) or ROS 1 messages of a ROS message type ``pkg/msg/Type``."""
    return encoding in ROS_ENCODINGS and bool(_ROS_SCHEMA.match(schema or ""))


def ros_candidate_topics(schemas: dict[str, tuple[str, str]]) -> list[str]:
    """The topics of ROS_TYPES in ``schemas`` (topic -> (encoding, schema)): what `ros_profile` reads."""
    return [topic for topic, (encoding, schema) in schemas.items() if encoding in ROS_ENCODINGS and schema in ROS_TYPES]


def _inline_input(channels: list[str]) -> str:
    return f'{{ channels = {toml_list(channels)}, frame = "flu" }}'


def ros_profile(log) -> BuiltProfile:
    """The built-in profile of a ROS log read with (at least) its topics of ROS_TYPES: ``ros_wheeled``
    for a ground robot, ``ros`` (the ins model) otherwise; see the module docstring."""
    found = Found(log)
    wheels = found.wheels()
    if wheels is not None:
        return wheeled_profile(log, found, wheels)
    return _ins_profile(log, found)


def _ins_profile(log, found: Found) -> BuiltProfile:
    """The ``ros`` profile: the ins model on the IMU, NavSatFix and odometry (module docstring)."""
    model = get_model("ins", {})
    group_noise = {name: spec.noise_std for name, spec in model.groups.items()}
    if not found.imus:
        why = f"no {ROS_IMU} topic with angular_velocity and linear_acceleration, and no planar odometry"
        return undecided("ros", log, found, why, ['name = "ros"', "", "[vehicle]", '# model = "..."'])
    imu = found.imus[0]
    imu_hz = found.rate(f"{imu}/angular_velocity.{AXES[0]}")
    if imu_hz < MIN_IMU_HZ:
        why = f"{imu} is logged at {imu_hz:.3g} Hz: the ins model needs the IMU at {MIN_IMU_HZ:g} Hz or more"
        return undecided("ros", log, found, why, ['name = "ros"', "", "[vehicle]", '# model = "..."'])
    if imu_hz < INS_NOMINAL_IMU_HZ:
        found.notes.append(
            f"{imu} is logged at {imu_hz:.3g} Hz, below the ins model's {INS_NOMINAL_IMU_HZ:g} Hz: the grid "
            "follows it, each sample held over a longer step (coarser checks)"
        )
    lines = _ins_head_lines(log, found, dict(model.p), imu, imu_hz)
    lines += _gnss_position_lines(found, group_noise["gnss_position"])
    velocity, quaternion = _odometry_channels(found)
    lines += _odometry_lines(found, velocity, group_noise["odometry"])
    lines += _attitude_lines(found, quaternion, group_noise["attitude"])
    if not found.fixes and velocity is None and quaternion is None:
        why = f"an IMU but nothing to check it against: no {ROS_NAVSATFIX} or {ROS_ODOMETRY} topic"
        return undecided("ros", log, found, why, lines[3:])
    lines += fix_status_mode_lines(found)
    lines += ["", "[detectors.nis]  # logscan's filter: NIS per group", ""]
    return BuiltProfile("ros", "\n".join(lines), found.notes)


def _ins_head_lines(log, found: Found, defaults: dict, imu: str, imu_hz: float) -> list[str]:
    """The profile's comment, name, ``[vehicle]`` (the IMU's rate, its noise from its covariances)
    and ``[inputs]`` (the IMU, body FLU)."""
    channels = found.channels
    gyro = [f"{imu}/angular_velocity.{a}" for a in AXES]
    accel = [f"{imu}/linear_acceleration.{a}" for a in AXES]
    gyro_std = covariance_std(channels, [f"{imu}/angular_velocity_covariance[{i}]" for i in DIAGONAL3])
    accel_std = covariance_std(channels, [f"{imu}/linear_acceleration_covariance[{i}]" for i in DIAGONAL3])
    gyro_noise, gyro_from = _pooled(gyro_std, defaults["gyro_noise"])
    accel_noise, accel_from = _pooled(accel_std, defaults["accel_noise"])
    return [
        "# logscan built-in profile `ros`: the IMU-driven ins model on a ROS log (ENU world, FLU body,",
        f"# REP 103), its topics chosen by message type from {log.source.path}.",
        f"# Edit and pass it with --profile ({doc_url('profiles.md')}).",
        'name = "ros"',
        'description = "built-in: ins model on a ROS IMU, NavSatFix and odometry"',
        "",
        "[vehicle]",
        'model = "ins"',
        f"rate_hz = {nice_rate(imu_hz):g}  # the IMU's rate in this log",
        "",
        "[vehicle.params]",
        f"gyro_noise = {gyro_noise:.6g}  # rad/s, {gyro_from}",
        f"accel_noise = {accel_noise:.6g}  # m/s^2, {accel_from}",
        "",
        f"[inputs]  # {imu} ({ROS_IMU}): body FLU -> FRD",
        f"gyro = {_inline_input(gyro)}",
        f"accel = {_inline_input(accel)}",
        f"stale_s = {max(2.5 / imu_hz, 0.05):.3g}  # an IMU gap longer than this is a dropout",
    ]


def _pooled(stds: list[float | None], default) -> tuple[float, str]:
    """(one noise std for the three axes, where it comes from): the median of the known ones."""
    known = [s for s in stds if s is not None]
    return (float(np.median(known)), "its covariance") if known else (float(default), "the model's default")


def _gnss_position_lines(found: Found, default_noise) -> list[str]:
    """``[measurements.gnss_position]`` from the first NavSatFix, in local NED about its first fix."""
    if not found.fixes:
        found.notes.append(f"optional gnss_position: no {ROS_NAVSATFIX} topic: left out")
        return []
    topic = found.fixes[0]
    lla = [f"{topic}/{f}" for f in ("latitude", "longitude", "altitude")]
    east, north, up = covariance_std(found.channels, [f"{topic}/position_covariance[{i}]" for i in DIAGONAL3])
    return [
        "",
        f"[measurements.gnss_position]  # {topic} ({ROS_NAVSATFIX})",
        f"channels = {toml_list(lla)}",
        'from = "geodetic"  # local NED about the first fix',
        'frame = "ned"',
        f"rate_hz = {found.rate(lla[0]):.3g}",
        noise_line([north, east, up], default_noise, "position"),
        *fix_gate_lines(found),
    ]


def _odometry_channels(found: Found) -> tuple[list[str] | None, list[str] | None]:
    """(twist.twist.linear, pose.pose.orientation) channels of the first Odometry topic, each None
    when the log lacks one of them."""
    if not found.odoms:
        return None, None
    topic = found.odoms[0]
    velocity = [f"{topic}/twist.twist.linear.{a}" for a in AXES]
    quaternion = [f"{topic}/pose.pose.orientation.{c}" for c in ("w", "x", "y", "z")]
    return (
        velocity if all(found.has(ch) for ch in velocity) else None,
        quaternion if all(found.has(ch) for ch in quaternion) else None,
    )


def _odometry_lines(found: Found, velocity: list[str] | None, default_noise) -> list[str]:
    """``[measurements.odometry]``: the odometry's twist, the body velocity (FLU)."""
    if velocity is None:
        found.notes.append(f"optional odometry: no {ROS_ODOMETRY} topic with twist.twist.linear: left out")
        return []
    stds = covariance_std(found.channels, [f"{found.odoms[0]}/twist.covariance[{i}]" for i in (0, 7, 14)])
    return [
        "",
        f"[measurements.odometry]  # {found.odoms[0]} ({ROS_ODOMETRY}) twist: the body velocity, FLU -> FRD",
        f"channels = {toml_list(velocity)}",
        'frame = "flu"',
        f"rate_hz = {found.rate(velocity[0]):.3g}",
        noise_line(stds, default_noise, "twist"),
    ]


def _attitude_lines(found: Found, quaternion: list[str] | None, default_noise) -> list[str]:
    """``[measurements.attitude]``: the odometry's orientation, body FLU to world ENU."""
    if quaternion is None:
        found.notes.append(f"optional attitude: no {ROS_ODOMETRY} topic with pose.pose.orientation: left out")
        return []
    stds = covariance_std(found.channels, [f"{found.odoms[0]}/pose.covariance[{i}]" for i in (21, 28, 35)])
    return [
        "",
        f"[measurements.attitude]  # {found.odoms[0]} ({ROS_ODOMETRY}) orientation: body FLU to world ENU",
        f"channels = {toml_list(quaternion)}  # w, x, y, z",
        'from = "quaternion"',
        'frame = "enu_flu"',
        f"rate_hz = {found.rate(quaternion[0]):.3g}",
        noise_line(stds, default_noise, "orientation"),
    ]
