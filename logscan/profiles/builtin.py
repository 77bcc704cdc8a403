"""Built-in profiles: a log that embeds none and names itself gets one built from what it holds.

A PX4 ULog (its info ``sys_name`` is "PX4") gets the `px4` profile of the IMU-driven `ins` model,
built from the topics present (`px4_profile`):

 - inputs: the IMU of ``sensor_combined`` (gyro_rad, accelerometer_m_s2), or ``vehicle_imu``'s
   increments per second when it is the only IMU or logged faster (`_imu`), the grid at its rate;
   an IMU logged below MIN_IMU_HZ is refused (the strapdown prediction would not hold);
 - ``gnss_position`` from ``vehicle_gps_position`` or ``sensor_gps`` (integer 1e-7 deg / mm, or
   degrees and metres), converted to local NED about the first fix; ``gnss_velocity`` from their
   vel_n/e/d_m_s; without GNSS, PX4's own local position (x, y, z) stands in as the position;
 - ``baro`` from ``vehicle_air_data`` (older logs: ``sensor_combined.baro_alt_meter``);
 - ``attitude`` from PX4's own estimate, ``vehicle_attitude.q``;
 - ``[mode]`` from ``vehicle_status.nav_state`` (the flight mode: KGN's steady gate);
 - ``[alarms]``: nothing judged in the first IGNORE_START_S (the filter converging), on the ground
   (``vehicle_land_detected.landed``), in the 5 s after each take-off or in the BEFORE_LANDING_S
   before each landing; a landing shorter than PX4's own confirmation time (LAND_TRIGGER_S) is a
   blip, flight; the health and PX4 estimator checks are judged on the whole log;
 - noise from the log's own EKF2 parameters where it has them (EKF2_GPS_P_NOISE, EKF2_GPS_V_NOISE,
   EKF2_BARO_NOISE, EKF2_ACC_NOISE, EKF2_GYR_NOISE, EKF2_ACC_B_NOISE, EKF2_GYR_B_NOISE): the
   values PX4 flew with; the GNSS and baro noise from the scatter of PX4's own innovations
   (`logscan.profiles.px4_noise`), never from the receiver's reported accuracy (eph, epv,
   s_variance_m_s: a sensor does not vouch for itself); the GNSS and baro latency (``delay_s``) from
   EKF2_GPS_DELAY and EKF2_BARO_DELAY.

A group whose topic the log lacks is left out, with one info line (`BuiltProfile.notes`).
GNSS samples count only with a 3D fix (``gate`` on fix_type >= 3), the origin too.

A ROS log (a ROS 2 MCAP, a ROS 1 bag, a rosbag2 database or directory: a topic of a ROS message
type ``pkg/msg/Type``) gets the `ros` or `ros_wheeled` profile of `logscan.profiles.ros`.
"""

from __future__ import annotations

import json

import numpy as np

from logscan.docs import doc_url
from logscan.errors import InputError
from logscan.profiles.built import BuiltProfile, nice_rate, rate_hz, toml_list
from logscan.profiles.px4_noise import NOISE_TOPICS, px4_noise
from logscan.profiles.ros import is_ros_topic
from logscan.profiles.schema import MAX_DELAY_S
from logscan.readers import read_log

ROS_FORMATS = ("mcap", "ros1bag", "rosbag2")  # the formats a ROS log comes in (`logscan.profiles.ros`)
MIN_IMU_HZ = 50.0  # the ins model holds one IMU sample over a grid period: slower is not an INS
# candidate topics (ULog `topic_instance` names) the px4 profile may use
PX4_TOPICS = (
    "sensor_combined_0",
    "vehicle_imu_0",
    "vehicle_gps_position_0",
    "sensor_gps_0",
    "vehicle_air_data_0",
    "vehicle_attitude_0",
    "vehicle_local_position_0",
    "vehicle_status_0",
    "vehicle_land_detected_0",
    *NOISE_TOPICS,  # PX4's own innovations: the measurement noise (logscan.profiles.px4_noise)
)
IGNORE_START_S = 5.0  # the ins filter's convergence from its first samples: not judged
BEFORE_LANDING_S = 3.0  # PX4's land detector confirms a touchdown about 2 s late: its transient lies before
# PX4's land detector says "landed" only once the landing conditions held for its trigger time
# (LNDMC_TRIG_TIME, multicopters and VTOL; LNDFW_TRIG_TIME, fixed-wing = MAV_TYPE 1; the defaults
# are PX4's): a shorter stay on the ground in flight is a blip (a bounce, an impact), judged as flight
LAND_TRIGGER_S = {"LNDMC_TRIG_TIME": 1.0, "LNDFW_TRIG_TIME": 2.0}
MAV_TYPE_FIXED_WING = 1
GPS_P_NOISE_M = 0.5  # PX4's default EKF2_GPS_P_NOISE: the GNSS (or local) position noise
_IMU = "sensor_combined_0"
_FULL_IMU = "vehicle_imu_0"  # the IMU's integrated increments at the full sensor rate


def identify(log) -> str | None:
    """The built-in profile a log asks for (``"px4"``, ``"ros"``: `logscan.profiles.ros`), else None."""
    info = log.source.metadata.get("ulog.info", {})
    if log.source.format == "ulog" and info.get("sys_name", "").strip().upper() == "PX4":
        return "px4"
    if log.source.format == "csv-dir" and is_ulog2csv_px4(log.source.topics):
        return "px4"
    if log.source.format in ROS_FORMATS and any(
        is_ros_topic(t.encoding, t.schema) for t in getattr(log.source, "topics", {}).values()
    ):
        return "ros"
    return None


def is_ulog2csv_px4(topics) -> bool:
    """A directory of CSVs (its topics: name -> `logscan.log.TopicInfo`) that pyulog's ``ulog2csv``
    wrote from a PX4 log: PX4's IMU topic among its ``<log>_<topic>_<n>.csv`` pieces. The export
    holds no info, parameters or logged messages: the topics' names are what says PX4."""
    return any(name in (_IMU, _FULL_IMU) and info.schema == "ulog2csv" for name, info in topics.items())


def topic_schemas(path, fmt: str) -> dict[str, tuple[str, str]]:
    """Topic -> (message encoding, schema name) of a log, without decoding its messages: an MCAP's
    summary section when it has one (its Channel and Schema records), else a read that decodes
    nothing (`read_log` with no topic wanted: a scan of an MCAP, a bag's connections)."""
    if fmt == "mcap":
        summarised = _mcap_summary_schemas(path)
        if summarised:
            return summarised
    log = read_log(path, topics=())
    return {name: (t.encoding, t.schema) for name, t in log.source.topics.items()}


def _mcap_summary_schemas(path) -> dict[str, tuple[str, str]] | None:
    """`topic_schemas` from an MCAP's summary section; None without one (or a damaged one)."""
    try:
        from mcap.reader import make_reader

        with open(path, "rb") as fh:
            summary = make_reader(fh).get_summary()
    except Exception:  # noqa: BLE001 - a damaged or summary-less MCAP: the scan says what is wrong
        return None
    if summary is None or not summary.channels:
        return None
    out: dict[str, tuple[str, str]] = {}
    for channel in summary.channels.values():
        schema = summary.schemas.get(channel.schema_id)
        out.setdefault(channel.topic, (channel.message_encoding, schema.name if schema else ""))
    return out


def _delay_line(params: dict, name: str, default_ms: float) -> str:
    """``delay_s = ...`` from PX4's sensor delay parameter (ms), clipped to what a profile takes."""
    delay = min(max(_param(params, name, default_ms), 0.0) / 1000.0, MAX_DELAY_S)
    return f"delay_s = {delay:.3g}  # {name}: the sensor's latency PX4 flew with"


def _param(params: dict, name: str, default: float) -> float:
    try:
        value = float(params[name])
    except (KeyError, TypeError, ValueError):
        return default
    return value if np.isfinite(value) and value > 0 else default


def _land_trigger_line(params: dict) -> str:
    """``min_ground_s = ...``: the log's land detector trigger time (LAND_TRIGGER_S)."""
    fixed_wing = _param(params, "MAV_TYPE", 0.0) == MAV_TYPE_FIXED_WING
    name = "LNDFW_TRIG_TIME" if fixed_wing else "LNDMC_TRIG_TIME"
    seconds = _param(params, name, LAND_TRIGGER_S[name])
    logged = "" if name in params else ", not logged: PX4's default"
    return f"min_ground_s = {seconds:.3g}  # {name}{logged}: a shorter landing in flight is a blip, judged as flight"


def _noise_std_line(noise) -> str:
    """``noise_std = [...]`` of a group's `logscan.profiles.px4_noise.Noise`, commented."""
    return f"noise_std = [{', '.join(f'{v:.3g}' for v in noise.std)}]  # {noise.comment()}"


def _channels(topic: str, fields) -> list[str]:
    return [f"/{topic}/{f}" for f in fields]


def _imu(channels, has):
    """(topic, gyro channels, accel channels, per-second scale or None, rate) of the IMU to use:
    ``sensor_combined`` (rates in rad/s and m/s^2), or ``vehicle_imu`` when it is the only IMU or
    logged faster (PX4 logs it at the full sensor rate on high-rate profiles). ``vehicle_imu`` holds
    integrated increments: delta_angle (rad) and delta_velocity (m/s) over delta_*_dt microseconds.
    Simplified: they are divided by the median integration period of the log (a scale), not each
    sample's own; PX4 integrates over a fixed number of sensor samples, so the period varies by
    well under 1 % on a healthy log."""
    combined = (
        _channels(_IMU, ("gyro_rad[0]", "gyro_rad[1]", "gyro_rad[2]")),
        _channels(_IMU, ("accelerometer_m_s2[0]", "accelerometer_m_s2[1]", "accelerometer_m_s2[2]")),
    )
    full = (
        _channels(_FULL_IMU, ("delta_angle[0]", "delta_angle[1]", "delta_angle[2]")),
        _channels(_FULL_IMU, ("delta_velocity[0]", "delta_velocity[1]", "delta_velocity[2]")),
    )
    period = f"/{_FULL_IMU}/delta_angle_dt"
    found = []
    if all(has(ch) for ch in combined[0] + combined[1]):
        found.append(("sensor_combined", *combined, None, rate_hz(channels[combined[0][0]].t)))
    if all(has(ch) for ch in full[0] + full[1]) and has(period):
        dt_us = np.asarray(channels[period].values, dtype=float)
        dt_us = dt_us[np.isfinite(dt_us) & (dt_us > 0)]
        if dt_us.size:
            found.append(("vehicle_imu", *full, 1e6 / float(np.median(dt_us)), rate_hz(channels[full[0][0]].t)))
    if len(found) == 2 and found[1][4] > 1.2 * found[0][4]:  # within 20 %: the same samples, logged twice
        return found[1]
    return found[0] if found else None


def _imu_lines(topic: str, gyro: list[str], accel: list[str], per_second: float | None) -> list[str]:
    if per_second is None:
        return [f"gyro = {toml_list(gyro)}", f"accel = {toml_list(accel)}"]
    note = f"  # {topic}'s increments per second: 1 / its median delta_angle_dt"
    return [
        f"gyro = {{ channels = {toml_list(gyro)}, scale = {per_second:.8g} }}{note}",
        f"accel = {{ channels = {toml_list(accel)}, scale = {per_second:.8g} }}",
    ]


def px4_profile(log) -> BuiltProfile:
    """The `px4` profile of a PX4 ULog read with (at least) PX4_TOPICS; see the module docstring."""
    channels = log.channels
    params = log.source.metadata.get("ulog.parameters", {})
    has = lambda name: name in channels and len(channels[name]) > 0  # noqa: E731
    notes: list[str] = []
    if log.source.format == "csv-dir":  # PX4's ulog2csv export: the topics alone
        notes.append(
            "a ulog2csv export holds no parameters: the noise, delays and limits are PX4's defaults (EKF2_*, "
            "BAT*...), not the values this vehicle flew with (analyse the .ulg for those)"
        )
    imu = _imu(channels, has)
    if imu is None:
        raise InputError(
            "a PX4 log without an IMU topic (sensor_combined or vehicle_imu): the built-in px4 profile needs one",
            path=log.source.path,
            hint=f"pass --profile ({doc_url('profiles.md')}; examples in {doc_url('examples')})",
        )
    topic, *_, imu_hz = imu
    # an IMU too slow for the ins model: the filter-free checks still run, on a grid of MIN_IMU_HZ
    model_not_run = slow_imu_reason(topic, imu_hz) if imu_hz < MIN_IMU_HZ else ""
    lines = _head_lines(log, params, imu, model_not_run)
    noise = _group_noise(channels, params)
    lines += _gnss_lines(channels, has, params, noise, notes)
    lines += _baro_lines(channels, has, params, noise, notes)
    lines += _attitude_lines(channels, has, notes)
    lines += _tail_lines(has, params, model_not_run)
    return BuiltProfile("px4", "\n".join(lines), notes, model_not_run)


def _head_lines(log, params: dict, imu, model_not_run: str) -> list[str]:
    """The profile's comment, name, ``[vehicle]`` (rate and PX4's EKF2 IMU noise) and ``[inputs]``
    (the IMU of `_imu`)."""
    topic, gyro, accel, per_second, imu_hz = imu
    rate = nice_rate(max(imu_hz, MIN_IMU_HZ))
    return [
        "# logscan built-in profile `px4`: the IMU-driven ins model on a PX4 flight log, built from the",
        f"# topics of {log.source.path}. Edit and pass it with --profile ({doc_url('profiles.md')}).",
        *([f"# The ins model is not run: {model_not_run}. Only the filter-free checks."] * bool(model_not_run)),
        'name = "px4"',
        f'description = "built-in: ins model on {topic}, GNSS, barometer and PX4\'s attitude"',
        "",
        "[vehicle]",
        'model = "ins"',
        *_vehicle_id_line(log),
        f"rate_hz = {rate:g}  # the IMU's rate in this log" + (f" (at least {MIN_IMU_HZ:g})" if model_not_run else ""),
        "",
        "[vehicle.params]  # PX4's EKF2 noise parameters of this log where it has them",
        f"accel_noise = {_param(params, 'EKF2_ACC_NOISE', 0.35):.6g}",
        f"gyro_noise = {_param(params, 'EKF2_GYR_NOISE', 0.015):.6g}",
        f"accel_bias_rw = {_param(params, 'EKF2_ACC_B_NOISE', 3e-3):.6g}",
        f"gyro_bias_rw = {_param(params, 'EKF2_GYR_B_NOISE', 1e-3):.6g}",
        "",
        "[inputs]",
        *_imu_lines(topic, gyro, accel, per_second),
        f"stale_s = {max(2.5 / imu_hz, 0.05):.3g}  # an IMU gap longer than this is a dropout",
    ]


def _group_noise(channels, params: dict) -> dict:
    """Each group's noise (`logscan.profiles.px4_noise.Noise`) from the scatter of PX4's own
    innovations, PX4's configured noise the ceiling; never the receiver's reported accuracy (a sensor
    does not vouch for itself)."""
    gps_p = _param(params, "EKF2_GPS_P_NOISE", GPS_P_NOISE_M)
    gps_v = _param(params, "EKF2_GPS_V_NOISE", 0.3)
    return px4_noise(
        channels,
        lambda name, default: _param(params, name, default),
        {
            "gnss_position": ((gps_p, gps_p, 1.5 * gps_p), "EKF2_GPS_P_NOISE (x 1.5 vertical)"),
            "gnss_velocity": ((gps_v, gps_v, 1.5 * gps_v), "EKF2_GPS_V_NOISE (x 1.5 vertical)"),
            "baro": ((_param(params, "EKF2_BARO_NOISE", 3.5),), "EKF2_BARO_NOISE"),
        },
    )


def _gnss_lines(channels, has, params: dict, noise: dict, notes: list[str]) -> list[str]:
    """``[measurements.gnss_position]`` and ``gnss_velocity`` from the log's GNSS (`_gnss`), else
    PX4's own local position as the position; none without either (a note says so)."""
    gnss = _gnss(channels, has)
    if gnss is None:
        return _local_position_lines(channels, has, params, notes)
    topic, pos, scale, vel = gnss
    # the receiver's latency PX4 flew with (ms; its default 110): a fix describes the vehicle then
    gps_delay = _delay_line(params, "EKF2_GPS_DELAY", 110.0)
    hz = rate_hz(channels[pos[0]].t)
    lines = ["", "[measurements.gnss_position]", f"channels = {toml_list(pos)}"]
    if scale:
        lines.append("scale = [1e-7, 1e-7, 1e-3]  # PX4 logs degrees x 1e7 and millimetres")
    lines += [
        'from = "geodetic"  # local NED about the first fix',
        f"rate_hz = {hz:.3g}",
        _noise_std_line(noise["gnss_position"]),
    ]
    fix = f"/{topic}/fix_type"
    gate = f'gate = {{ channel = "{fix}", min = 3 }}  # only 3D fixes' if has(fix) else None
    if gate:
        lines.append(gate)
    lines.append(gps_delay)
    if all(has(ch) for ch in vel):
        lines += [
            "",
            "[measurements.gnss_velocity]",
            f"channels = {toml_list(vel)}",
            f"rate_hz = {hz:.3g}",
            _noise_std_line(noise["gnss_velocity"]),
        ]
        if gate:
            lines.append(gate)
        lines.append(gps_delay)
    else:
        notes.append(f"optional gnss_velocity: {topic} has no vel_n_m_s/vel_e_m_s/vel_d_m_s: left out")
    return lines


def _local_position_lines(channels, has, params: dict, notes: list[str]) -> list[str]:
    """Without GNSS: ``[measurements.gnss_position]`` from PX4's own local position (x, y, z)."""
    local = _channels("vehicle_local_position_0", ("x", "y", "z"))
    if not all(has(ch) for ch in local):
        notes.append("optional gnss_position, gnss_velocity: no vehicle_gps_position or sensor_gps: left out")
        return []
    hz = rate_hz(channels[local[0]].t)
    notes.append("no GNSS topic: PX4's own local position (vehicle_local_position x, y, z) is the position")
    return [
        "",
        "[measurements.gnss_position]  # no GNSS in this log: PX4's own local position estimate",
        f"channels = {toml_list(local)}",
        f"rate_hz = {hz:.3g}",
        f"noise_std = {_param(params, 'EKF2_GPS_P_NOISE', GPS_P_NOISE_M):.3g}",
    ]


def _baro_lines(channels, has, params: dict, noise: dict, notes: list[str]) -> list[str]:
    """``[measurements.baro]`` from ``vehicle_air_data`` (older logs: ``sensor_combined``)."""
    baro = next(
        (ch for ch in ("/vehicle_air_data_0/baro_alt_meter", f"/{_IMU}/baro_alt_meter") if has(ch)),
        None,
    )
    if baro is None:
        notes.append("optional baro: no vehicle_air_data: left out")
        return []
    hz = rate_hz(channels[baro].t)
    return [
        "",
        "[measurements.baro]",
        f'channels = ["{baro}"]',
        f"rate_hz = {hz:.3g}",
        _noise_std_line(noise["baro"]),
        _delay_line(params, "EKF2_BARO_DELAY", 0.0),
    ]


def _attitude_lines(channels, has, notes: list[str]) -> list[str]:
    """``[measurements.attitude]`` from PX4's own estimate, ``vehicle_attitude.q``."""
    quaternion = _channels("vehicle_attitude_0", ("q[0]", "q[1]", "q[2]", "q[3]"))
    if not all(has(ch) for ch in quaternion):
        notes.append("optional attitude: no vehicle_attitude: left out")
        return []
    hz = rate_hz(channels[quaternion[0]].t)
    return [
        "",
        "[measurements.attitude]  # PX4's own attitude estimate, checked against the IMU and GNSS",
        f"channels = {toml_list(quaternion)}",
        'from = "quaternion"',
        f"rate_hz = {hz:.3g}",
        "noise_std = 0.05",
    ]


def _tail_lines(has, params: dict, model_not_run: str) -> list[str]:
    """``[mode]`` (PX4's flight mode), ``[alarms]`` (the convergence, the ground and its transients
    not judged) and the detectors."""
    lines = []
    if has("/vehicle_status_0/nav_state"):
        lines += [
            "",
            "[mode]  # PX4's flight mode",
            'channel = "/vehicle_status_0/nav_state"',
            "stale_s = inf  # logged on change",
        ]
    lines += [
        "",
        "[alarms]",
        f"ignore_start_s = {IGNORE_START_S:g}  # the filter converging from the first samples: not judged",
    ]
    if has("/vehicle_land_detected_0/landed"):
        lines += [
            'ground_channel = "/vehicle_land_detected_0/landed"  # not judged on the ground ...',
            "after_ground_s = 5  # ... nor during the take-off transient ...",
            f"before_ground_s = {BEFORE_LANDING_S:g}  # ... nor before a landing (PX4 confirms touchdown late)",
            _land_trigger_line(params),
        ]
    lines += ["", "[detectors.nis]  # logscan's filter: NIS per group"] if not model_not_run else []
    lines += [
        "",
        "[detectors.px4_estimator]  # PX4's own EKF2 innovation test ratios: the baseline",
        "",
        "[detectors.health]  # plausibility: battery, GNSS fix, motors, IMU clipping, logged errors, timeouts",
        "",
    ]
    return lines


def _vehicle_id_line(log) -> list[str]:
    """``id = "..."``: which vehicle flew, from the ULog's info and parameters (the board ver_hw,
    its unique sys_uuid where logged, the airframe SYS_AUTOSTART); none when the log says none (a
    ulog2csv export). Trained tables are refused on another vehicle's flights (`logscan.training.train`)."""
    info = log.source.metadata.get("ulog.info", {}) or {}
    airframe = (log.source.metadata.get("ulog.parameters", {}) or {}).get("SYS_AUTOSTART")
    parts = [str(info.get(key, "")).strip() for key in ("ver_hw", "sys_uuid")]
    if airframe is not None:
        parts.append(f"airframe {int(airframe)}")
    text = " ".join(part for part in parts if part)
    return [f"id = {json.dumps(text)}  # board, unique id, airframe: trained tables are for this vehicle"] * bool(text)


def slow_imu_reason(topic: str, imu_hz: float) -> str:
    """Why the ins model cannot run on an IMU logged at ``imu_hz`` (below MIN_IMU_HZ)."""
    return (
        f"{topic} is logged at {imu_hz:.3g} Hz: the ins model needs the IMU at {MIN_IMU_HZ:g} Hz or more (it "
        "holds one IMU sample per step; PX4: log at a higher rate, SDLOG_PROFILE with 'high rate')"
    )


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
