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
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from logscan.docs import doc_url
from logscan.models import get_model
from logscan.profiles.built import BuiltProfile, nice_rate, rate_hz, toml_list

MIN_IMU_HZ = 20.0  # slower, one held IMU sample no longer stands for the motion between grid steps
INS_NOMINAL_IMU_HZ = 50.0  # the ins model's design rate (PX4 logs 100-250 Hz): slower is coarser, said so
UNKNOWN_COVARIANCE = 1e3  # ROS drivers mark an unknown covariance with -1 or a huge value (1e6, 1e9)
# GPS SPS Performance Standard (5th ed., 2020, section 3.8): <= 9 m horizontal error, 95 %, global
# average. A 2-D circular normal error has R95 = 2.4477 sigma: sigma per axis 9 / 2.4477 = 3.68 m.
GPS_SPS_SIGMA_M = 9.0 / 2.4477
COVARIANCE_TYPE_DIAGONAL_KNOWN = 2  # sensor_msgs/NavSatFix position_covariance_type
# an IMU's mean specific force this close to one of its axes (deg) says the axis is up
MOUNT_AXIS_TOLERANCE_DEG = 15.0
MIN_YAW_RATE_AGREEMENT = 0.5  # the gyro's up axis against the odometry's yaw rate: correlation

ROS_IMU = "sensor_msgs/msg/Imu"
ROS_NAVSATFIX = "sensor_msgs/msg/NavSatFix"
ROS_ODOMETRY = "nav_msgs/msg/Odometry"
# velocity commands (cmd_vel): the field prefix of their twist
ROS_COMMANDS = {"geometry_msgs/msg/Twist": "", "geometry_msgs/msg/TwistStamped": "twist."}
ROS_JOINT_STATE = "sensor_msgs/msg/JointState"
ROS_TYPES = (ROS_IMU, ROS_NAVSATFIX, ROS_ODOMETRY, *ROS_COMMANDS, ROS_JOINT_STATE)
ROS_ENCODINGS = ("cdr", "ros1")  # ROS 2 (MCAP, rosbag2) and ROS 1 bags; schemas in ROS 2 form pkg/msg/Type
_ROS_SCHEMA = re.compile(r"^[A-Za-z][\w]*/msg/[A-Za-z]\w*$")
_AXES = ("x", "y", "z")
_DIAGONAL3 = (0, 4, 8)
# twist components a 2-D drive controller never sets
_PLANAR_ZERO = ("linear.y", "linear.z", "angular.x", "angular.y")


def is_ros_topic(encoding: str, schema: str) -> bool:
    """A ROS topic: CDR (ROS 2) or ROS 1 messages of a ROS message type ``pkg/msg/Type``."""
    return encoding in ROS_ENCODINGS and bool(_ROS_SCHEMA.match(schema or ""))


def ros_candidate_topics(schemas: dict[str, tuple[str, str]]) -> list[str]:
    """The topics of ROS_TYPES in ``schemas`` (topic -> (encoding, schema)): what `ros_profile` reads."""
    return [topic for topic, (encoding, schema) in schemas.items() if encoding in ROS_ENCODINGS and schema in ROS_TYPES]


def covariance_std(channels, names: list[str]) -> list[float | None]:
    """Per channel of ``names`` (covariance diagonal entries): the square root of the median of its
    known samples, None when none is known. Unknown, by ROS's conventions: -1 ("not given"), 0
    (a zero matrix: not filled in), UNKNOWN_COVARIANCE or more (drivers' 1e6, 1e9), NaN."""
    out: list[float | None] = []
    for name in names:
        ch = channels.get(name)
        values = np.asarray(ch.values if ch is not None else [], dtype=np.float64)
        values = values[np.isfinite(values) & (values > 0) & (values < UNKNOWN_COVARIANCE)]
        out.append(float(np.sqrt(np.median(values))) if values.size else None)
    return out


def _noise_line(stds: list[float | None], defaults, what: str) -> str:
    """``noise_std = [...]``: the covariance's where known, the model's default elsewhere, commented."""
    values = [s if s is not None else float(d) for s, d in zip(stds, defaults)]
    known = sum(s is not None for s in stds)
    source = (
        f"sqrt of the median {what} covariance"
        if known == len(stds)
        else f"the model's defaults: the {what} covariance is unknown (-1, 0 or >= {UNKNOWN_COVARIANCE:g})"
        if not known
        else f"sqrt of the median {what} covariance, the model's default where it is unknown"
    )
    return f"noise_std = [{', '.join(f'{v:.4g}' for v in values)}]  # {source}"


def _inline_input(channels: list[str]) -> str:
    return f'{{ channels = {toml_list(channels)}, frame = "flu" }}'


def _topics_of_type(log, schema: str) -> list[str]:
    """The log's topics of message type ``schema`` with messages, in the file's order."""
    return [
        name
        for name, info in log.source.topics.items()
        if info.schema == schema and info.encoding in ROS_ENCODINGS and info.message_count > 0
    ]


@dataclass(frozen=True)
class Wheels:
    """Where a ground robot's speed and yaw rate come from: its wheel odometry (nav_msgs/Odometry,
    measured) or, without one, its velocity commands (geometry_msgs/Twist*, commanded)."""

    topic: str
    prefix: str  # of the twist's fields: "twist.twist." (Odometry), "twist." (TwistStamped), ""
    commanded: bool

    def field(self, name: str) -> str:
        return f"{self.topic}/{self.prefix}{name}"

    def covariance(self, index: int) -> str | None:
        """The twist covariance's entry ``index`` (Odometry only: a command has none)."""
        return None if self.commanded else f"{self.topic}/twist.covariance[{index}]"

    @property
    def what(self) -> str:
        return f"{self.topic}'s commands" if self.commanded else f"{self.topic}'s wheel odometry"


class _Found:
    """The standard topics a ROS log holds, each checked for the fields the profiles read."""

    def __init__(self, log):
        channels = log.channels
        self.channels = channels
        self.has = lambda name: name in channels and len(channels[name]) > 0  # noqa: E731
        self.notes: list[str] = []
        self.imus = [
            t
            for t in _topics_of_type(log, ROS_IMU)
            if all(self.has(f"{t}/{f}.{a}") for f in ("angular_velocity", "linear_acceleration") for a in _AXES)
        ]
        self.fixes = [
            t
            for t in _topics_of_type(log, ROS_NAVSATFIX)
            if all(self.has(f"{t}/{f}") for f in ("latitude", "longitude", "altitude"))
        ]
        self.odoms = [t for t in _topics_of_type(log, ROS_ODOMETRY) if self.has(f"{t}/twist.twist.linear.x")]
        self.commands = [
            Wheels(t, prefix, commanded=True)
            for schema, prefix in ROS_COMMANDS.items()
            for t in _topics_of_type(log, schema)
            if self.has(f"{t}/{prefix}linear.x")
        ]
        if any(_topics_of_type(log, ROS_JOINT_STATE)):
            self.notes.append(
                f"{ROS_JOINT_STATE}: wheel joint speeds need the wheel radius and track, which the log does not "
                "hold: not used (give them as inputs with a scale)"
            )
        if len(self.imus) > 1:
            unused = ", ".join(self.imus[1:])
            self.notes.append(f"{len(self.imus)} {ROS_IMU} topics: {self.imus[0]} is the IMU, {unused} unused")

    def rate(self, name: str) -> float:
        return rate_hz(self.channels[name].t)

    def wheels(self) -> Wheels | None:
        """A ground robot's wheels: the first Odometry topic whose twist is planar (`_PLANAR_ZERO`
        all exactly 0: what a 2-D drive controller publishes), else the first such velocity
        command topic; None for anything else."""
        candidates = [Wheels(t, "twist.twist.", commanded=False) for t in self.odoms] + self.commands
        for wheels in candidates:
            names = [wheels.field(c) for c in _PLANAR_ZERO]
            if all(self.has(n) and not np.any(np.asarray(self.channels[n].values)) for n in names):
                return wheels
        return None


def imu_up_axis(channels, imu: str) -> tuple[int, float] | None:
    """(axis index, sign) of the IMU axis that points up, from gravity: the mean specific force of a
    ground vehicle over a drive is gravity, up (its accelerations average out between rests). None
    when the mean is not within MOUNT_AXIS_TOLERANCE_DEG of an axis (a tilted mount) or is not
    gravity's size (within 20 %)."""
    mean = np.array([np.nanmean(np.asarray(channels[f"{imu}/linear_acceleration.{a}"].values)) for a in _AXES])
    norm = float(np.linalg.norm(mean))
    if not (np.isfinite(norm) and 0.8 * 9.80665 <= norm <= 1.2 * 9.80665):
        return None
    axis = int(np.argmax(np.abs(mean)))
    angle = np.degrees(np.arccos(min(abs(mean[axis]) / norm, 1.0)))
    if angle > MOUNT_AXIS_TOLERANCE_DEG:
        return None
    return axis, float(np.sign(mean[axis]))


def yaw_rate_agreement(channels, gyro: str, sign: float, odom_rate: str) -> float:
    """Correlation of the gyro's yaw rate (``sign`` x ``gyro``) with the odometry's, on the odometry's times."""
    g, o = channels[gyro], channels[odom_rate]
    t_o = np.asarray(o.t, dtype=np.float64)
    w_g = sign * np.interp(t_o, np.asarray(g.t, dtype=np.float64), np.asarray(g.values, dtype=np.float64))
    w_o = np.asarray(o.values, dtype=np.float64)
    ok = np.isfinite(w_g) & np.isfinite(w_o)
    if ok.sum() < 10 or np.std(w_o[ok]) == 0 or np.std(w_g[ok]) == 0:
        return 0.0
    return float(np.corrcoef(w_g[ok], w_o[ok])[0, 1])


def ros_profile(log) -> BuiltProfile:
    """The built-in profile of a ROS log read with (at least) its topics of ROS_TYPES: ``ros_wheeled``
    for a ground robot, ``ros`` (the ins model) otherwise; see the module docstring."""
    found = _Found(log)
    wheels = found.wheels()
    if wheels is not None:
        return _wheeled_profile(log, found, wheels)
    return _ins_profile(log, found)


def _undecided(name: str, log, found: _Found, why: str, lines: list[str]) -> BuiltProfile:
    """A profile the log's topics cannot complete: its text to edit, the model not run."""
    text = [
        f"# logscan built-in profile `{name}` of {log.source.path}: INCOMPLETE, {why}.",
        f"# Complete the commented parts and pass it with --profile ({doc_url('profiles.md')}).",
        *lines,
    ]
    return BuiltProfile(name, "\n".join(text) + "\n", found.notes, model_not_run=why)


def _wheeled_profile(log, found: _Found, wheels: Wheels) -> BuiltProfile:
    channels, notes = found.channels, found.notes

    model = get_model("wheeled", {})
    defaults = model.p
    speed = wheels.field("linear.x")
    odom = wheels.topic
    odom_hz = found.rate(speed)
    (speed_std,) = covariance_std(channels, [wheels.covariance(0) or ""])
    yaw, yaw_std, yaw_hz, yaw_why, from_gyro = _yaw_rate(found, wheels)
    imu_hz = yaw_hz if from_gyro else 0.0
    rate = nice_rate(max(imu_hz, odom_hz))
    header = [
        "# logscan built-in profile `ros_wheeled`: the `wheeled` model of a ground robot (its twist is",
        f"# planar: {wheels.what}) from the ROS topics of {log.source.path}, chosen by message type.",
        f"# Edit and pass it with --profile ({doc_url('profiles.md')}).",
        'name = "ros_wheeled"',
        f'description = "built-in: wheeled model on {odom}{" and " + found.imus[0] if imu_hz else ""}"',
        "",
        "[vehicle]",
        'model = "wheeled"',
        f"rate_hz = {rate:g}  # the fastest input's rate in this log",
        "",
        "[vehicle.params]",
        _param_line(
            "speed_noise",
            speed_std,
            defaults["speed_noise"],
            "m/s",
            "a command's covariance (it has none)" if wheels.commanded else f"{odom} twist.covariance[0]",
        ),
        f"speed_rate_hz = {odom_hz:.4g}",
        _param_line("yaw_rate_noise", yaw_std, defaults["yaw_rate_noise"], "rad/s", "the yaw rate's covariance"),
        f"yaw_rate_hz = {yaw_hz:.4g}",
    ]
    inputs = [
        "",
        f"[inputs]  # the forward speed: {wheels.what}; the yaw rate: {yaw_why}",
        f'v = "{speed}"',
        f"w = {yaw}",
        f"stale_s = {2.5 / min(odom_hz, yaw_hz):.3g}  # an input older than this is a dropout",
    ]
    if wheels.commanded:  # a command acts from its stamp on; it is republished while it holds
        inputs.append('stamp = "start"  # a command acts from its stamp on')
    groups: list[str] = []
    odom_rate = wheels.field("angular.z")
    if imu_hz and found.has(odom_rate) and not wheels.commanded:  # the wheels' yaw rate against the gyro's
        (std,) = covariance_std(channels, [wheels.covariance(35) or ""])
        groups += [
            "",
            f"[measurements.wheel_yaw_rate]  # {odom}'s yaw rate against the gyro's (a skid steer's ratio is a state)",
            f'channels = ["{odom_rate}"]',
            f"rate_hz = {odom_hz:.3g}",
            _noise_line([std], model.groups["wheel_yaw_rate"].noise_std, "yaw rate"),
        ]
    wander: list[str] = []
    if found.fixes:
        fix = found.fixes[0]
        lla = [f"{fix}/{f}" for f in ("latitude", "longitude", "altitude")]
        east, north = covariance_std(channels, [f"{fix}/position_covariance[{i}]" for i in (0, 4)])
        white = [s for s in (east, north) if s is not None]
        kind = channels.get(f"{fix}/position_covariance_type")
        kinds = np.asarray(kind.values if kind is not None else [], dtype=np.float64)
        known = bool(white) and kinds.size > 0 and float(np.median(kinds)) >= COVARIANCE_TYPE_DIAGONAL_KNOWN
        wander = [
            f"gnss_error_std = {float(np.mean(white)):.4g}  # m: {fix} reports its covariance as known"
            if known
            else f"gnss_error_std = {GPS_SPS_SIGMA_M:.3g}  # m: the GPS SPS accuracy standard (9 m 95 % "
            f"horizontal); {fix}'s covariance is approximated or unknown"
        ]
        notes.append(
            f"{fix} altitude not checked: the wheeled model is planar (a ground robot's altitude follows terrain)"
        )
        groups += [
            "",
            f"[measurements.position]  # {fix} ({ROS_NAVSATFIX}): east, north about the first fix",
            f"channels = {toml_list(lla)}",
            'from = "geodetic"',
            'frame = "en"  # horizontal only: the altitude is not checked',
            f"rate_hz = {found.rate(lla[0]):.3g}",
            _noise_line([east, north], model.groups["position"].noise_std, "position"),
        ]
    elif groups:
        notes.append(f"no {ROS_NAVSATFIX} topic: the wheels' speed and the position are not checked, only the yaw rate")
    if not groups:
        why = (
            f"no {ROS_NAVSATFIX} topic and no gyro to check the wheels' yaw rate against: nothing independent "
            "of the wheels to check them against"
        )
        body = header + inputs + ["", "# [measurements.position]  # a position source: a GNSS fix", "#   ..."]
        return _undecided("ros_wheeled", log, found, why, body)
    lines = header + wander + inputs + groups
    lines += [
        "",
        "[detectors.nis]  # logscan's filter: NIS per group",
        "",
        "[detectors.cusum]  # slow drifts and small biases of each whitened innovation",
        "",
        "[detectors.frozen]  # a stuck sensor (not judged while the wheels stand still)",
        "",
    ]
    return BuiltProfile("ros_wheeled", "\n".join(lines), notes)


def _param_line(name: str, std: float | None, default: float, unit: str, source: str) -> str:
    if std is None:
        return f"{name} = {default:.4g}  # {unit}, the model's default: {source} is unknown"
    return f"{name} = {std:.4g}  # {unit}, sqrt of {source}"


def _yaw_rate(found: _Found, wheels: Wheels) -> tuple[str, float | None, float, str, bool]:
    """(the ``w`` input's TOML value, its noise std or None, its rate, why, from a gyro?): the IMU's
    gyro about up when gravity shows the axis and the wheels' yaw rate agrees, else the wheels' own."""
    channels = found.channels
    odom_rate = wheels.field("angular.z")
    odom_hz = found.rate(wheels.field("linear.x"))
    fallback_why = (
        "the commanded one"
        if wheels.commanded
        else "the odometry's (a skid-steer's slips in turns: its bias is a state)"
    )
    if found.imus:
        imu = found.imus[0]
        imu_hz = found.rate(f"{imu}/angular_velocity.x")
        up = imu_up_axis(channels, imu)
        if up is None:
            found.notes.append(
                f"{imu}: gravity is not along one of its axes (a tilted mount): its yaw rate is not used; give "
                "the mount as the w input's channels and scale"
            )
        elif imu_hz < MIN_IMU_HZ:
            found.notes.append(f"{imu} is logged at {imu_hz:.3g} Hz, below {MIN_IMU_HZ:g} Hz: its yaw rate is not used")
        else:
            axis, sign = up
            gyro = f"{imu}/angular_velocity.{_AXES[axis]}"
            agreement = yaw_rate_agreement(channels, gyro, sign, odom_rate) if found.has(odom_rate) else 1.0
            if agreement >= MIN_YAW_RATE_AGREEMENT:
                (std,) = covariance_std(channels, [f"{imu}/angular_velocity_covariance[{4 * axis}]"])
                value = f'{{ channels = ["{gyro}"], scale = [{sign:g}] }}'
                why = f"the IMU's {_AXES[axis]} axis, up by gravity (agrees with the odometry's: r = {agreement:.2f})"
                return value, std, imu_hz, why, True
            found.notes.append(
                f"{imu}: its up axis disagrees with the odometry's yaw rate (r = {agreement:.2f}): not used"
            )
    (std,) = covariance_std(channels, [wheels.covariance(35) or ""])
    return f'"{odom_rate}"', std, odom_hz, fallback_why, False


def _ins_profile(log, found: _Found) -> BuiltProfile:
    """The ``ros`` profile: the ins model on the IMU, NavSatFix and odometry (module docstring)."""
    model = get_model("ins", {})
    defaults = dict(model.p)
    group_noise = {name: spec.noise_std for name, spec in model.groups.items()}
    channels, notes = found.channels, found.notes
    path = log.source.path
    if not found.imus:
        why = f"no {ROS_IMU} topic with angular_velocity and linear_acceleration, and no planar odometry"
        return _undecided("ros", log, found, why, ['name = "ros"', "", "[vehicle]", '# model = "..."'])
    imu = found.imus[0]
    gyro = [f"{imu}/angular_velocity.{a}" for a in _AXES]
    accel = [f"{imu}/linear_acceleration.{a}" for a in _AXES]
    imu_hz = found.rate(gyro[0])
    if imu_hz < MIN_IMU_HZ:
        why = f"{imu} is logged at {imu_hz:.3g} Hz: the ins model needs the IMU at {MIN_IMU_HZ:g} Hz or more"
        return _undecided("ros", log, found, why, ['name = "ros"', "", "[vehicle]", '# model = "..."'])
    if imu_hz < INS_NOMINAL_IMU_HZ:
        notes.append(
            f"{imu} is logged at {imu_hz:.3g} Hz, below the ins model's {INS_NOMINAL_IMU_HZ:g} Hz: the grid "
            "follows it, each sample held over a longer step (coarser checks)"
        )
    gyro_std = covariance_std(channels, [f"{imu}/angular_velocity_covariance[{i}]" for i in _DIAGONAL3])
    accel_std = covariance_std(channels, [f"{imu}/linear_acceleration_covariance[{i}]" for i in _DIAGONAL3])

    def pooled(stds, default):
        known = [s for s in stds if s is not None]
        return (float(np.median(known)), "its covariance") if known else (float(default), "the model's default")

    gyro_noise, gyro_from = pooled(gyro_std, defaults["gyro_noise"])
    accel_noise, accel_from = pooled(accel_std, defaults["accel_noise"])
    lines = [
        "# logscan built-in profile `ros`: the IMU-driven ins model on a ROS log (ENU world, FLU body,",
        f"# REP 103), its topics chosen by message type from {path}.",
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
    if found.fixes:
        topic = found.fixes[0]
        lla = [f"{topic}/{f}" for f in ("latitude", "longitude", "altitude")]
        east, north, up = covariance_std(channels, [f"{topic}/position_covariance[{i}]" for i in _DIAGONAL3])
        lines += [
            "",
            f"[measurements.gnss_position]  # {topic} ({ROS_NAVSATFIX})",
            f"channels = {toml_list(lla)}",
            'from = "geodetic"  # local NED about the first fix',
            'frame = "ned"',
            f"rate_hz = {found.rate(lla[0]):.3g}",
            _noise_line([north, east, up], group_noise["gnss_position"], "position"),
        ]
    else:
        notes.append(f"optional gnss_position: no {ROS_NAVSATFIX} topic: left out")
    velocity = quaternion = None
    if found.odoms:
        topic = found.odoms[0]
        velocity = [f"{topic}/twist.twist.linear.{a}" for a in _AXES]
        quaternion = [f"{topic}/pose.pose.orientation.{c}" for c in ("w", "x", "y", "z")]
        velocity = velocity if all(found.has(ch) for ch in velocity) else None
        quaternion = quaternion if all(found.has(ch) for ch in quaternion) else None
    if velocity is not None:
        stds = covariance_std(channels, [f"{found.odoms[0]}/twist.covariance[{i}]" for i in (0, 7, 14)])
        lines += [
            "",
            f"[measurements.odometry]  # {found.odoms[0]} ({ROS_ODOMETRY}) twist: the body velocity, FLU -> FRD",
            f"channels = {toml_list(velocity)}",
            'frame = "flu"',
            f"rate_hz = {found.rate(velocity[0]):.3g}",
            _noise_line(stds, group_noise["odometry"], "twist"),
        ]
    else:
        notes.append(f"optional odometry: no {ROS_ODOMETRY} topic with twist.twist.linear: left out")
    if quaternion is not None:
        stds = covariance_std(channels, [f"{found.odoms[0]}/pose.covariance[{i}]" for i in (21, 28, 35)])
        lines += [
            "",
            f"[measurements.attitude]  # {found.odoms[0]} ({ROS_ODOMETRY}) orientation: body FLU to world ENU",
            f"channels = {toml_list(quaternion)}  # w, x, y, z",
            'from = "quaternion"',
            'frame = "enu_flu"',
            f"rate_hz = {found.rate(quaternion[0]):.3g}",
            _noise_line(stds, group_noise["attitude"], "orientation"),
        ]
    else:
        notes.append(f"optional attitude: no {ROS_ODOMETRY} topic with pose.pose.orientation: left out")
    if not found.fixes and velocity is None and quaternion is None:
        why = f"an IMU but nothing to check it against: no {ROS_NAVSATFIX} or {ROS_ODOMETRY} topic"
        return _undecided("ros", log, found, why, lines[3:])
    lines += ["", "[detectors.nis]  # logscan's filter: NIS per group", ""]
    return BuiltProfile("ros", "\n".join(lines), notes)
