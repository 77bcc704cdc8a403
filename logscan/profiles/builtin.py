"""Built-in profiles: a log that embeds none and names itself gets one built from what it holds.

A PX4 ULog (its info ``sys_name`` is "PX4") gets the `px4` profile of the IMU-driven `ins` model,
built from the topics present (`px4_profile`):

 - inputs: the IMU of ``sensor_combined`` (gyro_rad, accelerometer_m_s2), the grid at its rate;
   an IMU logged below MIN_IMU_HZ is refused (the strapdown prediction would not hold);
 - ``gnss_position`` from ``vehicle_gps_position`` or ``sensor_gps`` (integer 1e-7 deg / mm, or
   degrees and metres), converted to local NED about the first fix; ``gnss_velocity`` from their
   vel_n/e/d_m_s; without GNSS, PX4's own local position (x, y, z) stands in as the position;
 - ``baro`` from ``vehicle_air_data`` (older logs: ``sensor_combined.baro_alt_meter``);
 - ``attitude`` from PX4's own estimate, ``vehicle_attitude.q``;
 - ``[mode]`` from ``vehicle_status.nav_state`` (the flight mode: KGN's steady gate);
 - noise from the log's own EKF2 parameters where it has them (EKF2_GPS_P_NOISE, EKF2_GPS_V_NOISE,
   EKF2_BARO_NOISE, EKF2_ACC_NOISE, EKF2_GYR_NOISE, EKF2_ACC_B_NOISE, EKF2_GYR_B_NOISE): the
   values PX4 flew with.

A group whose topic the log lacks is left out, with one info line (`BuiltProfile.notes`).
Simplified: the GNSS noise is fixed (PX4's eph / epv per fix are not used as R) and fixes are not
gated on fix_type (a profile cannot mask one channel by another yet).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from logscan.errors import InputError

MIN_IMU_HZ = 50.0  # the ins model holds one IMU sample over a grid period: slower is not an INS
# candidate topics (ULog `topic_instance` names) the px4 profile may use
PX4_TOPICS = (
    "sensor_combined_0",
    "vehicle_gps_position_0",
    "sensor_gps_0",
    "vehicle_air_data_0",
    "vehicle_attitude_0",
    "vehicle_local_position_0",
    "vehicle_status_0",
)
_IMU = "sensor_combined_0"


@dataclass
class BuiltProfile:
    """A built-in profile: its name, TOML text (commented, to edit) and what was left out."""

    name: str
    text: str
    notes: list[str] = field(default_factory=list)


def identify(log) -> str | None:
    """The built-in profile a log asks for (``"px4"``), else None."""
    info = log.source.metadata.get("ulog.info", {})
    if log.source.format == "ulog" and info.get("sys_name", "").strip().upper() == "PX4":
        return "px4"
    return None


def rate_hz(t_ns: np.ndarray) -> float:
    """A channel's sample rate: 1 / the median interval between its samples (0 for fewer than 2)."""
    t = np.unique(np.asarray(t_ns, dtype=np.int64))
    if t.size < 2:
        return 0.0
    return float(1e9 / np.median(np.diff(t)))


def _param(params: dict, name: str, default: float) -> float:
    try:
        value = float(params[name])
    except (KeyError, TypeError, ValueError):
        return default
    return value if np.isfinite(value) and value > 0 else default


def _nice_rate(hz: float) -> float:
    """A grid rate near ``hz``: whole hertz (PX4 logs its IMU at 200, 250, ... Hz)."""
    return float(max(1, round(hz)))


def _channels(topic: str, fields) -> list[str]:
    return [f"/{topic}/{f}" for f in fields]


def px4_profile(log) -> BuiltProfile:
    """The `px4` profile of a PX4 ULog read with (at least) PX4_TOPICS; see the module docstring."""
    channels = log.channels
    params = log.source.metadata.get("ulog.parameters", {})
    path = log.source.path
    has = lambda name: name in channels and len(channels[name]) > 0  # noqa: E731

    gyro = _channels(_IMU, ("gyro_rad[0]", "gyro_rad[1]", "gyro_rad[2]"))
    accel = _channels(_IMU, ("accelerometer_m_s2[0]", "accelerometer_m_s2[1]", "accelerometer_m_s2[2]"))
    if not all(has(ch) for ch in gyro + accel):
        raise InputError(
            "a PX4 log without the IMU topic sensor_combined: the built-in px4 profile needs it",
            path=path,
            hint="pass --profile (docs/profiles.md; examples in docs/examples/)",
        )
    imu_hz = rate_hz(channels[gyro[0]].t)
    if imu_hz < MIN_IMU_HZ:
        raise InputError(
            f"sensor_combined is logged at {imu_hz:.3g} Hz: the ins model needs the IMU at {MIN_IMU_HZ:g} Hz "
            "or more (it holds one IMU sample per step)",
            path=path,
            hint="log at a higher rate (PX4: SDLOG_PROFILE with 'high rate'), or pass --profile with another model",
        )
    rate = _nice_rate(imu_hz)
    notes: list[str] = []
    lines = [
        "# logscan built-in profile `px4`: the IMU-driven ins model on a PX4 flight log, built from the",
        f"# topics of {path}. Edit and pass it with --profile (docs/profiles.md).",
        'name = "px4"',
        'description = "built-in: ins model on sensor_combined, GNSS, barometer and PX4\'s attitude"',
        "",
        "[vehicle]",
        'model = "ins"',
        f"rate_hz = {rate:g}  # the IMU's rate in this log",
        "",
        "[vehicle.params]  # PX4's EKF2 noise parameters of this log where it has them",
        f"accel_noise = {_param(params, 'EKF2_ACC_NOISE', 0.35):.6g}",
        f"gyro_noise = {_param(params, 'EKF2_GYR_NOISE', 0.015):.6g}",
        f"accel_bias_rw = {_param(params, 'EKF2_ACC_B_NOISE', 3e-3):.6g}",
        f"gyro_bias_rw = {_param(params, 'EKF2_GYR_B_NOISE', 1e-3):.6g}",
        "",
        "[inputs]",
        f"gyro = {_toml_list(gyro)}",
        f"accel = {_toml_list(accel)}",
        f"stale_s = {max(2.5 / imu_hz, 0.05):.3g}  # an IMU gap longer than this is a dropout",
    ]
    gps_p = _param(params, "EKF2_GPS_P_NOISE", 0.5)
    gps_v = _param(params, "EKF2_GPS_V_NOISE", 0.3)
    gnss = _gnss(channels, has)
    if gnss is not None:
        topic, pos, scale, vel = gnss
        hz = rate_hz(channels[pos[0]].t)
        lines += ["", "[measurements.gnss_position]", f"channels = {_toml_list(pos)}"]
        if scale:
            lines.append("scale = [1e-7, 1e-7, 1e-3]  # PX4 logs degrees x 1e7 and millimetres")
        lines += [
            'from = "geodetic"  # local NED about the first fix',
            f"rate_hz = {hz:.3g}",
            f"noise_std = [{gps_p:.3g}, {gps_p:.3g}, {1.5 * gps_p:.3g}]  # EKF2_GPS_P_NOISE (x 1.5 vertical)",
        ]
        if all(has(ch) for ch in vel):
            lines += [
                "",
                "[measurements.gnss_velocity]",
                f"channels = {_toml_list(vel)}",
                f"rate_hz = {hz:.3g}",
                f"noise_std = [{gps_v:.3g}, {gps_v:.3g}, {1.5 * gps_v:.3g}]  # EKF2_GPS_V_NOISE (x 1.5 vertical)",
            ]
        else:
            notes.append(f"optional gnss_velocity: {topic} has no vel_n_m_s/vel_e_m_s/vel_d_m_s: left out")
    else:
        local = _channels("vehicle_local_position_0", ("x", "y", "z"))
        if all(has(ch) for ch in local):
            hz = rate_hz(channels[local[0]].t)
            notes.append("no GNSS topic: PX4's own local position (vehicle_local_position x, y, z) is the position")
            lines += [
                "",
                "[measurements.gnss_position]  # no GNSS in this log: PX4's own local position estimate",
                f"channels = {_toml_list(local)}",
                f"rate_hz = {hz:.3g}",
                f"noise_std = {gps_p:.3g}",
            ]
        else:
            notes.append("optional gnss_position, gnss_velocity: no vehicle_gps_position or sensor_gps: left out")
    baro = next(
        (ch for ch in ("/vehicle_air_data_0/baro_alt_meter", f"/{_IMU}/baro_alt_meter") if has(ch)),
        None,
    )
    if baro is not None:
        hz = rate_hz(channels[baro].t)
        lines += [
            "",
            "[measurements.baro]",
            f'channels = ["{baro}"]',
            f"rate_hz = {hz:.3g}",
            f"noise_std = {_param(params, 'EKF2_BARO_NOISE', 3.5):.3g}  # EKF2_BARO_NOISE",
        ]
    else:
        notes.append("optional baro: no vehicle_air_data: left out")
    quaternion = _channels("vehicle_attitude_0", ("q[0]", "q[1]", "q[2]", "q[3]"))
    if all(has(ch) for ch in quaternion):
        hz = rate_hz(channels[quaternion[0]].t)
        lines += [
            "",
            "[measurements.attitude]  # PX4's own attitude estimate, checked against the IMU and GNSS",
            f"channels = {_toml_list(quaternion)}",
            'from = "quaternion"',
            f"rate_hz = {hz:.3g}",
            "noise_std = 0.05",
        ]
    else:
        notes.append("optional attitude: no vehicle_attitude: left out")
    if has("/vehicle_status_0/nav_state"):
        lines += [
            "",
            "[mode]  # PX4's flight mode",
            'channel = "/vehicle_status_0/nav_state"',
            "stale_s = inf  # logged on change",
        ]
    lines += [
        "",
        "[detectors.nis]  # logscan's filter: NIS per group",
        "",
        "[detectors.px4_estimator]  # PX4's own EKF2 innovation test ratios: the baseline",
        "",
    ]
    return BuiltProfile("px4", "\n".join(lines), notes)


def _gnss(channels, has):
    """(topic, position channels, integer scale?, velocity channels) of the log's GNSS, or None."""
    for topic in ("vehicle_gps_position_0", "sensor_gps_0"):
        vel = _channels(topic, ("vel_n_m_s", "vel_e_m_s", "vel_d_m_s"))
        floats = _channels(topic, ("latitude_deg", "longitude_deg", "altitude_msl_m"))
        if all(has(ch) for ch in floats):
            return topic, floats, False, vel
        ints = _channels(topic, ("lat", "lon", "alt"))
        if all(has(ch) for ch in ints):
            return topic, ints, True, vel
    return None


def _toml_list(items) -> str:
    return "[" + ", ".join(f'"{x}"' for x in items) + "]"
