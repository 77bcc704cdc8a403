"""The built-in ``ros_wheeled`` profile: the `wheeled` model of a ground robot from its ROS topics,
its yaw rate from the gyro axis gravity shows is up (`logscan.profiles.ros` says what it reads)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from logscan.docs import doc_url
from logscan.models import get_model
from logscan.profiles.built import BuiltProfile, nice_rate, toml_list
from logscan.profiles.ros_topics import (
    AXES,
    MIN_IMU_HZ,
    ROS_NAVSATFIX,
    Found,
    Wheels,
    covariance_std,
    fix_gate_lines,
    fix_status_mode_lines,
    noise_line,
    undecided,
)

# GPS SPS Performance Standard (5th ed., 2020, section 3.8): <= 9 m horizontal error, 95 %, global
# average. A 2-D circular normal error has R95 = 2.4477 sigma: sigma per axis 9 / 2.4477 = 3.68 m.
GPS_SPS_SIGMA_M = 9.0 / 2.4477
COVARIANCE_TYPE_DIAGONAL_KNOWN = 2  # sensor_msgs/NavSatFix position_covariance_type
# an IMU's mean specific force this close to one of its axes (deg) says the axis is up
MOUNT_AXIS_TOLERANCE_DEG = 15.0
MIN_YAW_RATE_AGREEMENT = 0.5  # the gyro's up axis against the odometry's yaw rate: correlation
AGREEMENT_WINDOW_S = 20.0  # stretches over which that agreement is judged again, when the whole log's is low


class YawRate(NamedTuple):
    """The ``w`` input (`_yaw_rate`)."""

    value: str  # its TOML value
    std: float | None  # its noise std (None: unknown)
    hz: float
    why: str  # where it comes from, for the [inputs] comment
    from_gyro: bool


def imu_up_axis(channels, imu: str) -> tuple[int, float] | None:
    """(axis index, sign) of the IMU axis that points up, from gravity: the mean specific force of a
    ground vehicle over a drive is gravity, up (its accelerations average out between rests). None
    when the mean is not within MOUNT_AXIS_TOLERANCE_DEG of an axis (a tilted mount) or is not
    gravity's size (within 20 %)."""
    mean = np.array([np.nanmean(np.asarray(channels[f"{imu}/linear_acceleration.{a}"].values)) for a in AXES])
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
    t_o, w_g, w_o = _yaw_rates(channels, gyro, sign, odom_rate)
    return _correlation(w_g, w_o)


def agreeing_stretches(channels, gyro: str, sign: float, odom_rate: str) -> tuple[list[float], list[float]]:
    """(starts of the AGREEMENT_WINDOW_S stretches where the two yaw rates agree, r >= the minimum;
    starts of those where they are opposite, r <= -the minimum), seconds since the odometry's first
    sample. A wrong axis or sign convention disagrees all along; a yaw rate that goes wrong during
    the log (a sign flip, a stuck sensor) agrees before: the log's own change, for the detectors."""
    t_o, w_g, w_o = _yaw_rates(channels, gyro, sign, odom_rate)
    if t_o.size == 0:
        return [], []
    stretch = np.floor((t_o - t_o[0]) / 1e9 / AGREEMENT_WINDOW_S).astype(np.int64)
    bounds = np.flatnonzero(np.diff(stretch)) + 1
    r = [_correlation(g, o) for g, o in zip(np.split(w_g, bounds), np.split(w_o, bounds))]
    starts = np.unique(stretch) * AGREEMENT_WINDOW_S
    agree = [float(s) for s, c in zip(starts, r) if c >= MIN_YAW_RATE_AGREEMENT]
    opposite = [float(s) for s, c in zip(starts, r) if c <= -MIN_YAW_RATE_AGREEMENT]
    return agree, opposite


def _yaw_rates(channels, gyro: str, sign: float, odom_rate: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(the odometry's times in ns, the gyro's yaw rate there, the odometry's)."""
    g, o = channels[gyro], channels[odom_rate]
    t_o = np.asarray(o.t, dtype=np.float64)
    w_g = sign * np.interp(t_o, np.asarray(g.t, dtype=np.float64), np.asarray(g.values, dtype=np.float64))
    return t_o, w_g, np.asarray(o.values, dtype=np.float64)


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 10 or np.std(a[ok]) == 0 or np.std(b[ok]) == 0:
        return 0.0
    return float(np.corrcoef(a[ok], b[ok])[0, 1])


def _changed(found: Found, imu: str, gyro: str, sign: float, odom_rate: str) -> str:
    """Why the gyro is used although the whole log's yaw rates disagree, when they agree over some
    stretches (the odometry's or the gyro's yaw rate changed during the log: a fault the detectors
    are to judge, not a mounting a faulty sensor may overrule); "" when they agree nowhere."""
    agree, opposite = agreeing_stretches(found.channels, gyro, sign, odom_rate)
    if not agree:
        return ""
    where = f" and are opposite over {len(opposite)} (from {opposite[0]:g} s)" if opposite else ""
    found.notes.append(
        f"{imu}: its up axis and the odometry's yaw rate agree over {len(agree)} stretches of "
        f"{AGREEMENT_WINDOW_S:g} s (from {agree[0]:g} s){where}, not over the whole log: one of them changed "
        "during it, so the gyro (up by gravity) is used and the detectors judge the odometry against it"
    )
    axis = gyro.rsplit(".", 1)[1]
    return f"the IMU's {axis} axis, up by gravity (agrees with the odometry's over {len(agree)} stretches)"


def wheeled_profile(log, found: Found, wheels: Wheels) -> BuiltProfile:
    """The ``ros_wheeled`` profile of a ground robot (``wheels``: `Found.wheels`): its speed and yaw
    rate the inputs, checked against the gyro and a NavSatFix (`logscan.profiles.ros`)."""
    model = get_model("wheeled", {})
    odom_hz = found.rate(wheels.field("linear.x"))
    yaw = _yaw_rate(found, wheels)
    header = _header_lines(log, found, wheels, model, odom_hz, yaw)
    inputs = [
        "",
        f"[inputs]  # the forward speed: {wheels.what}; the yaw rate: {yaw.why}",
        f'v = "{wheels.field("linear.x")}"',
        f"w = {yaw.value}",
        f"stale_s = {2.5 / min(odom_hz, yaw.hz):.3g}  # an input older than this is a dropout",
    ]
    if wheels.commanded:  # a command acts from its stamp on; it is republished while it holds
        inputs.append('stamp = "start"  # a command acts from its stamp on')
    groups: list[str] = []
    if yaw.from_gyro and found.has(wheels.field("angular.z")) and not wheels.commanded:
        groups += _wheel_yaw_rate_lines(found, wheels, model, odom_hz)  # the wheels' yaw rate against the gyro's
    wander: list[str] = []
    if found.fixes:
        wander, position = _position_lines(found, model)
        groups += position
    elif groups:
        found.notes.append(
            f"no {ROS_NAVSATFIX} topic: the wheels' speed and the position are not checked, only the yaw rate"
        )
    if not groups:
        why = (
            f"no {ROS_NAVSATFIX} topic and no gyro to check the wheels' yaw rate against: nothing independent "
            "of the wheels to check them against"
        )
        body = header + inputs + ["", "# [measurements.position]  # a position source: a GNSS fix", "#   ..."]
        return undecided("ros_wheeled", log, found, why, body)
    lines = header + wander + inputs + groups + fix_status_mode_lines(found)
    lines += [
        "",
        "[detectors.nis]  # logscan's filter: NIS per group",
        "",
        "[detectors.cusum]  # slow drifts and small biases of each whitened innovation",
        "",
        "[detectors.frozen]  # a stuck sensor (not judged while the wheels stand still)",
        "",
    ]
    return BuiltProfile("ros_wheeled", "\n".join(lines), found.notes)


def _header_lines(log, found: Found, wheels: Wheels, model, odom_hz: float, yaw: YawRate) -> list[str]:
    """The profile's comment, name and ``[vehicle]``: the grid at the fastest input's rate, the speed
    and yaw rate noise from their covariances."""
    odom = wheels.topic
    (speed_std,) = covariance_std(found.channels, [wheels.covariance(0) or ""])
    imu_hz = yaw.hz if yaw.from_gyro else 0.0
    rate = nice_rate(max(imu_hz, odom_hz))
    return [
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
            model.p["speed_noise"],
            "m/s",
            "a command's covariance (it has none)" if wheels.commanded else f"{odom} twist.covariance[0]",
        ),
        f"speed_rate_hz = {odom_hz:.4g}",
        _param_line("yaw_rate_noise", yaw.std, model.p["yaw_rate_noise"], "rad/s", "the yaw rate's covariance"),
        f"yaw_rate_hz = {yaw.hz:.4g}",
    ]


def _wheel_yaw_rate_lines(found: Found, wheels: Wheels, model, odom_hz: float) -> list[str]:
    """``[measurements.wheel_yaw_rate]``: the odometry's yaw rate, checked against the gyro's."""
    odom = wheels.topic
    (std,) = covariance_std(found.channels, [wheels.covariance(35) or ""])
    return [
        "",
        f"[measurements.wheel_yaw_rate]  # {odom}'s yaw rate against the gyro's (a skid steer's ratio is a state)",
        f'channels = ["{wheels.field("angular.z")}"]',
        f"rate_hz = {odom_hz:.3g}",
        noise_line([std], model.groups["wheel_yaw_rate"].noise_std, "yaw rate"),
    ]


def _position_lines(found: Found, model) -> tuple[list[str], list[str]]:
    """(the ``gnss_error_std`` line, ``[measurements.position]``) of the first NavSatFix: east and
    north about the first fix; its altitude is not checked (a note says so)."""
    channels, fix = found.channels, found.fixes[0]
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
    found.notes.append(
        f"{fix} altitude not checked: the wheeled model is planar (a ground robot's altitude follows terrain)"
    )
    return wander, [
        "",
        f"[measurements.position]  # {fix} ({ROS_NAVSATFIX}): east, north about the first fix",
        f"channels = {toml_list(lla)}",
        'from = "geodetic"',
        'frame = "en"  # horizontal only: the altitude is not checked',
        f"rate_hz = {found.rate(lla[0]):.3g}",
        noise_line([east, north], model.groups["position"].noise_std, "position"),
        *fix_gate_lines(found),
    ]


def _param_line(name: str, std: float | None, default: float, unit: str, source: str) -> str:
    if std is None:
        return f"{name} = {default:.4g}  # {unit}, the model's default: {source} is unknown"
    return f"{name} = {std:.4g}  # {unit}, sqrt of {source}"


def _yaw_rate(found: Found, wheels: Wheels) -> YawRate:
    """The ``w`` input (`YawRate`): the IMU's gyro about up when gravity shows the axis and the
    wheels' yaw rate agrees, else the wheels' own."""
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
            gyro = f"{imu}/angular_velocity.{AXES[axis]}"
            agreement = yaw_rate_agreement(channels, gyro, sign, odom_rate) if found.has(odom_rate) else 1.0
            changed = "" if agreement >= MIN_YAW_RATE_AGREEMENT else _changed(found, imu, gyro, sign, odom_rate)
            if agreement >= MIN_YAW_RATE_AGREEMENT or changed:
                (std,) = covariance_std(channels, [f"{imu}/angular_velocity_covariance[{4 * axis}]"])
                value = f'{{ channels = ["{gyro}"], scale = [{sign:g}] }}'
                why = f"the IMU's {AXES[axis]} axis, up by gravity (agrees with the odometry's: r = {agreement:.2f})"
                return YawRate(value, std, imu_hz, changed or why, True)
            found.notes.append(
                f"{imu}: its up axis disagrees with the odometry's yaw rate (r = {agreement:.2f}): not used"
            )
    (std,) = covariance_std(channels, [wheels.covariance(35) or ""])
    return YawRate(f'"{odom_rate}"', std, odom_hz, fallback_why, False)
