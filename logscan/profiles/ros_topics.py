"""The standard topics of a ROS log, found by message type, and their covariances: what the ROS
profiles (`logscan.profiles.ros`, `logscan.profiles.ros_wheeled`) are built from."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from logscan.docs import doc_url
from logscan.profiles.built import BuiltProfile, rate_hz

MIN_IMU_HZ = 20.0  # slower, one held IMU sample no longer stands for the motion between grid steps
UNKNOWN_COVARIANCE = 1e3  # ROS drivers mark an unknown covariance with -1 or a huge value (1e6, 1e9)

ROS_IMU = "sensor_msgs/msg/Imu"
ROS_NAVSATFIX = "sensor_msgs/msg/NavSatFix"
ROS_ODOMETRY = "nav_msgs/msg/Odometry"
# velocity commands (cmd_vel): the field prefix of their twist
ROS_COMMANDS = {"geometry_msgs/msg/Twist": "", "geometry_msgs/msg/TwistStamped": "twist."}
ROS_JOINT_STATE = "sensor_msgs/msg/JointState"
ROS_TYPES = (ROS_IMU, ROS_NAVSATFIX, ROS_ODOMETRY, *ROS_COMMANDS, ROS_JOINT_STATE)
ROS_ENCODINGS = ("cdr", "ros1")  # ROS 2 (MCAP, rosbag2) and ROS 1 bags; schemas in ROS 2 form pkg/msg/Type
AXES = ("x", "y", "z")
DIAGONAL3 = (0, 4, 8)
# sensor_msgs/NavSatStatus.msg's STATUS_* constants (STATUS_UNKNOWN, -2, only in newer ROS 2): the
# names a ROS profile's [mode] gives a NavSatFix's status.status
NAVSAT_STATUS_LABELS = {-2: "UNKNOWN", -1: "NO_FIX", 0: "FIX", 1: "SBAS_FIX", 2: "GBAS_FIX"}
NAVSAT_STATUS_FIX = 0  # the lowest status.status that is a fix
HOLD_PERIODS = 2.5  # a held value older than this many of its periods is a dropout
# twist components a 2-D drive controller never sets
_PLANAR_ZERO = ("linear.y", "linear.z", "angular.x", "angular.y")


def fix_status_mode_lines(found: Found) -> list[str]:
    """``[mode]``: the first NavSatFix's ``status.status``, its values named by NavSatStatus.msg's
    constants (the report draws the fix's status by name on the time axis); [] without one."""
    channel = f"{found.fixes[0]}/status.status" if found.fixes else ""
    if not channel or not found.has(channel):
        return []
    labels = ", ".join(f'"{value}" = "{name}"' for value, name in NAVSAT_STATUS_LABELS.items())
    return [
        "",
        "[mode]  # the GNSS fix's status, named as sensor_msgs/NavSatStatus.msg names its values",
        f'channel = "{channel}"',
        f"stale_s = {HOLD_PERIODS / found.rate(channel):.3g}",
        f"labels = {{ {labels} }}",
    ]


def fix_gate_lines(found: Found) -> list[str]:
    """A NavSatFix group's ``gate``: a fix counts only where its ``status.status`` is STATUS_FIX (0) or
    better (NavSatStatus.msg: STATUS_NO_FIX = -1 means the position is not a fix; drivers still fill
    in the last or a default one); [] when the log has no status field."""
    channel = f"{found.fixes[0]}/status.status" if found.fixes else ""
    if not channel or not found.has(channel):
        return []
    return [f'gate = {{ channel = "{channel}", min = {NAVSAT_STATUS_FIX} }}  # STATUS_FIX and better, not NO_FIX']


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


def noise_line(stds: list[float | None], defaults, what: str) -> str:
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


def topics_of_type(log, schema: str) -> list[str]:
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


class Found:
    """The standard topics a ROS log holds, each checked for the fields the profiles read."""

    def __init__(self, log):
        channels = log.channels
        self.channels = channels
        self.has = lambda name: name in channels and len(channels[name]) > 0  # noqa: E731
        self.notes: list[str] = []
        self.imus = [
            t
            for t in topics_of_type(log, ROS_IMU)
            if all(self.has(f"{t}/{f}.{a}") for f in ("angular_velocity", "linear_acceleration") for a in AXES)
        ]
        self.fixes = [
            t
            for t in topics_of_type(log, ROS_NAVSATFIX)
            if all(self.has(f"{t}/{f}") for f in ("latitude", "longitude", "altitude"))
        ]
        self.odoms = [t for t in topics_of_type(log, ROS_ODOMETRY) if self.has(f"{t}/twist.twist.linear.x")]
        self.commands = [
            Wheels(t, prefix, commanded=True)
            for schema, prefix in ROS_COMMANDS.items()
            for t in topics_of_type(log, schema)
            if self.has(f"{t}/{prefix}linear.x")
        ]
        if any(topics_of_type(log, ROS_JOINT_STATE)):
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


def undecided(name: str, log, found: Found, why: str, lines: list[str]) -> BuiltProfile:
    """A profile the log's topics cannot complete: its text to edit, the model not run."""
    text = [
        f"# logscan built-in profile `{name}` of {log.source.path}: INCOMPLETE, {why}.",
        f"# Complete the commented parts and pass it with --profile ({doc_url('profiles.md')}).",
        *lines,
    ]
    return BuiltProfile(name, "\n".join(text) + "\n", found.notes, model_not_run=why)
