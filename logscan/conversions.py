"""Channel conversions of a measurement group (a profile's ``from`` key), vectorised over samples.

- ``from = "quaternion"``: channels (w, x, y, z), a Hamilton unit quaternion, scalar first, rotating
  body vectors into the world frame (PX4: body FRD -> world NED) -> ZYX Euler angles (roll, pitch,
  yaw) in radians of that body-to-world rotation, R = Rz(yaw) Ry(pitch) Rx(roll).
- ``from = "geodetic"``: channels (latitude deg, longitude deg, altitude m positive up) on the
  WGS-84 ellipsoid -> metres in the local tangent frame at an origin: (north, east, down) or
  (east, north, up), or the horizontal pair only (``frame`` "ne" / "en").
- ``frame`` of a 3-vector group without ``from`` (`vector_to_frd_ned`): "flu" (a body vector
  forward, left, up -> forward, right, down) or "enu" (a world vector east, north, up -> north,
  east, down); "frd" / "ned" leave it as it is. ``frame = "enu_flu"`` of a quaternion group
  (`quaternion_enu_flu_to_ned_frd`): a ROS orientation (body FLU to world ENU, REP 103) turned
  into the body FRD to world NED attitude before the Euler angles.

Pure numpy, no per-sample Python loops; invalid samples become NaN rows (never an exception), and
the filter skips a NaN measurement as invalid. Documented for profiles in docs/profiles.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: A held quaternion whose norm lies outside these bounds is not an attitude (a corrupt or
#: uninitialised message) and converts to NaN instead of being silently normalised.
QUATERNION_NORM_LIMITS = (0.5, 1.5)

WGS84_A = 6378137.0  # semi-major axis, m
WGS84_F = 1.0 / 298.257223563  # flattening
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)  # first eccentricity squared

# of a geodetic group's output: 3-D, or horizontal only ("ne", "en": a ground vehicle's planar model,
# whose altitude follows terrain it does not know)
FRAMES = ("ned", "enu", "ne", "en")
_GEODETIC_OUTPUTS = {
    "ned": ("north", "east", "down"),
    "enu": ("east", "north", "up"),
    "ne": ("north", "east"),
    "en": ("east", "north"),
}
#: ``frame`` of a quaternion group: "ned" (body FRD to world NED, as PX4) or "enu_flu" (ROS).
QUATERNION_FRAMES = ("ned", "enu_flu")
#: ``frame`` of a 3-vector group without ``from``: the identity frames, then the converted ones.
VECTOR_FRAMES = ("frd", "ned", "flu", "enu")
#: the outputs of a converted 3-vector frame
VECTOR_FRAME_OUTPUTS = {"flu": ("forward", "right", "down"), "enu": ("north", "east", "down")}
#: ``frame`` values a group may have, by its ``from`` (None: without ``from``)
GROUP_FRAMES = {None: VECTOR_FRAMES, "quaternion": QUATERNION_FRAMES, "geodetic": FRAMES}


@dataclass(frozen=True)
class Conversion:
    """A ``from`` conversion: the channels it reads, in order, and the outputs it gives."""

    name: str
    inputs: tuple[str, ...]  # what each channel must be, in the profile's order
    outputs: tuple[str, ...]  # the converted values, one column each

    def output_names(self, frame: str = "ned") -> tuple[str, ...]:
        if self.name == "geodetic":
            return _GEODETIC_OUTPUTS.get(frame, self.outputs)
        return self.outputs


CONVERSIONS = {
    "quaternion": Conversion("quaternion", ("w", "x", "y", "z"), ("roll", "pitch", "yaw")),
    "geodetic": Conversion(
        "geodetic", ("latitude (deg)", "longitude (deg)", "altitude (m, up)"), ("north", "east", "down")
    ),
}


def quaternion_to_euler(q: np.ndarray) -> np.ndarray:
    """ZYX Euler angles (roll, pitch, yaw) in rad, (N, 3), of the quaternions ``q`` (N, 4) = (w, x, y, z).

    Each quaternion is normalised first, then::

        roll  = atan2(2 (w x + y z), 1 - 2 (x^2 + y^2))
        pitch = asin(clip(2 (w y - z x), -1, 1))
        yaw   = atan2(2 (w z + x y), 1 - 2 (y^2 + z^2))

    q and -q give the same angles. A row with a NaN component, or whose norm lies outside
    `QUATERNION_NORM_LIMITS`, is NaN in all three columns.
    """
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    norm = np.sqrt(np.einsum("ij,ij->i", q, q))
    lo, hi = QUATERNION_NORM_LIMITS
    valid = (norm >= lo) & (norm <= hi)  # False for NaN
    with np.errstate(invalid="ignore", divide="ignore"):
        u = q / np.where(valid, norm, np.nan)[:, None]
    w, x, y, z = u.T
    out = np.empty((q.shape[0], 3))
    out[:, 0] = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    out[:, 1] = np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    out[:, 2] = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return out


def invalid_quaternions(q: np.ndarray) -> np.ndarray:
    """(N,) bool: rows of ``q`` (N, 4) with every component finite but a norm outside
    `QUATERNION_NORM_LIMITS` (the rows `quaternion_to_euler` makes NaN although they were held)."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    finite = np.isfinite(q).all(axis=1)
    norm = np.sqrt(np.einsum("ij,ij->i", np.where(finite[:, None], q, 0.0), np.where(finite[:, None], q, 0.0)))
    lo, hi = QUATERNION_NORM_LIMITS
    return finite & ~((norm >= lo) & (norm <= hi))


def euler_to_quaternion(euler: np.ndarray) -> np.ndarray:
    """Unit quaternions (w, x, y, z), (N, 4), of ZYX Euler angles (roll, pitch, yaw) (N, 3) in rad:
    q = qz(yaw) * qy(pitch) * qx(roll) (Hamilton product); the inverse of `quaternion_to_euler`
    for pitch within (-pi/2, pi/2)."""
    e = np.asarray(euler, dtype=np.float64).reshape(-1, 3)
    cr, sr = np.cos(e[:, 0] / 2), np.sin(e[:, 0] / 2)
    cp, sp = np.cos(e[:, 1] / 2), np.sin(e[:, 1] / 2)
    cy, sy = np.cos(e[:, 2] / 2), np.sin(e[:, 2] / 2)
    return np.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ],
        axis=1,
    )


def quaternion_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) of the quaternions ``q`` (N, 4) = (w, x, y, z), normalised first:
    v_world = R v_body."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    w, x, y, z = (q / np.linalg.norm(q, axis=1)[:, None]).T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1),
        ],
        axis=1,
    )


def euler_matrix(euler: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) R = Rz(yaw) Ry(pitch) Rx(roll) of ZYX Euler angles (N, 3) in rad."""
    e = np.asarray(euler, dtype=np.float64).reshape(-1, 3)
    cr, sr = np.cos(e[:, 0]), np.sin(e[:, 0])
    cp, sp = np.cos(e[:, 1]), np.sin(e[:, 1])
    cy, sy = np.cos(e[:, 2]), np.sin(e[:, 2])
    return np.stack(
        [
            np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], axis=1),
            np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], axis=1),
            np.stack([-sp, cp * sr, cp * cr], axis=1),
        ],
        axis=1,
    )


def valid_geodetic(lla: np.ndarray) -> np.ndarray:
    """(N,) bool: latitude within [-90, 90] deg, longitude within [-180, 180] deg, altitude finite."""
    lla = np.asarray(lla, dtype=np.float64).reshape(-1, 3)
    with np.errstate(invalid="ignore"):
        return (np.abs(lla[:, 0]) <= 90.0) & (np.abs(lla[:, 1]) <= 180.0) & np.isfinite(lla[:, 2])


def geodetic_to_ecef(lla: np.ndarray) -> np.ndarray:
    """Earth-centred, Earth-fixed coordinates (N, 3) in m of WGS-84 geodetic (lat deg, lon deg, h m)::

        N(lat) = a / sqrt(1 - e^2 sin^2 lat)
        X = (N + h) cos lat cos lon
        Y = (N + h) cos lat sin lon
        Z = (N (1 - e^2) + h) sin lat

    with a = 6378137.0 m, f = 1/298.257223563, e^2 = f (2 - f).
    """
    lla = np.asarray(lla, dtype=np.float64).reshape(-1, 3)
    lat, lon, h = np.radians(lla[:, 0]), np.radians(lla[:, 1]), lla[:, 2]
    s, c = np.sin(lat), np.cos(lat)
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * s * s)
    return np.stack([(n + h) * c * np.cos(lon), (n + h) * c * np.sin(lon), (n * (1.0 - WGS84_E2) + h) * s], axis=1)


def geodetic_to_local(lla: np.ndarray, origin, frame: str = "ned") -> np.ndarray:
    """Local tangent-plane coordinates (N, 3) in m of geodetic ``lla`` (N, 3) about ``origin``
    (lat deg, lon deg, h m), exactly (no flat-Earth approximation): d = ECEF(p) - ECEF(origin), then::

        east  = -sin lon0 dX + cos lon0 dY
        north = -sin lat0 cos lon0 dX - sin lat0 sin lon0 dY + cos lat0 dZ
        up    =  cos lat0 cos lon0 dX + cos lat0 sin lon0 dY + sin lat0 dZ

    ``frame`` "ned": columns (north, east, down = -up); "enu": (east, north, up); "ne" / "en": the
    horizontal pair only, (N, 2). Rows outside the valid latitude / longitude range
    (`valid_geodetic`) are NaN.
    """
    if frame not in FRAMES:
        raise ValueError(f"frame must be one of {FRAMES}, got {frame!r}")
    lla = np.asarray(lla, dtype=np.float64).reshape(-1, 3)
    o = np.asarray(origin, dtype=np.float64).reshape(1, 3)
    d = geodetic_to_ecef(lla) - geodetic_to_ecef(o)
    lat0, lon0 = np.radians(o[0, 0]), np.radians(o[0, 1])
    sl, cl = np.sin(lat0), np.cos(lat0)
    so, co = np.sin(lon0), np.cos(lon0)
    east = -so * d[:, 0] + co * d[:, 1]
    north = -sl * co * d[:, 0] - sl * so * d[:, 1] + cl * d[:, 2]
    up = cl * co * d[:, 0] + cl * so * d[:, 1] + sl * d[:, 2]
    columns = {"north": north, "east": east, "down": -up, "up": up}
    out = np.stack([columns[name] for name in _GEODETIC_OUTPUTS[frame]], axis=1)
    out[~valid_geodetic(lla)] = np.nan
    return out


def flu_to_frd(v: np.ndarray) -> np.ndarray:
    """Body vectors (N, 3) given forward, left, up (ROS, REP 103) -> forward, right, down: (x, -y, -z)."""
    v = np.asarray(v, dtype=np.float64).reshape(-1, 3)
    return v * np.array([1.0, -1.0, -1.0])


def enu_to_ned(v: np.ndarray) -> np.ndarray:
    """World vectors (N, 3) given east, north, up -> north, east, down: (y, x, -z)."""
    v = np.asarray(v, dtype=np.float64).reshape(-1, 3)
    return np.stack([v[:, 1], v[:, 0], -v[:, 2]], axis=1)


def vector_to_frd_ned(v: np.ndarray, frame: str) -> np.ndarray:
    """The ``frame`` conversion of a 3-vector group without ``from``: "flu" -> FRD
    (`flu_to_frd`), "enu" -> NED (`enu_to_ned`), "frd" / "ned": unchanged (a copy)."""
    if frame == "flu":
        return flu_to_frd(v)
    if frame == "enu":
        return enu_to_ned(v)
    if frame in ("frd", "ned"):
        return np.array(v, dtype=np.float64).reshape(-1, 3)
    raise ValueError(f"frame must be one of {VECTOR_FRAMES}, got {frame!r}")


def quaternion_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products a * b of quaternions (w, x, y, z), broadcast over rows ((N, 4) or (4,))."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


_S = np.sqrt(0.5)
#: the rotation T taking ENU vectors to NED, (y, x, -z): 180 deg about (1, 1, 0) / sqrt 2
Q_ENU_TO_NED = np.array([0.0, _S, _S, 0.0])
#: the rotation B taking FRD body vectors to FLU (and back), diag(1, -1, -1): 180 deg about x
Q_FLU_TO_FRD = np.array([0.0, 1.0, 0.0, 0.0])


def quaternion_enu_flu_to_ned_frd(q: np.ndarray) -> np.ndarray:
    """Quaternions (N, 4) = (w, x, y, z) rotating body FLU into world ENU (a ROS orientation) ->
    the same attitude rotating body FRD into world NED: q_T * q * q_B, i.e. R_ned_frd = T R B with
    T = [[0, 1, 0], [1, 0, 0], [0, 0, -1]] and B = diag(1, -1, -1). The norm is kept (a NaN row
    stays NaN), so the validity check of `quaternion_to_euler` applies unchanged."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    return quaternion_multiply(quaternion_multiply(Q_ENU_TO_NED, q), Q_FLU_TO_FRD)


def convert(source: str, values: np.ndarray, *, origin=None, frame: str = "ned") -> np.ndarray:
    """The ``from = source`` conversion of held channel values (N, channels) -> (N, 3); ``frame``
    "enu_flu" of a quaternion turns a ROS orientation into the FRD-to-NED attitude first."""
    if source == "quaternion":
        if frame == "enu_flu":
            values = quaternion_enu_flu_to_ned_frd(values)
        return quaternion_to_euler(values)
    if source == "geodetic":
        return geodetic_to_local(values, origin, frame)
    raise ValueError(f"unknown conversion {source!r} (choices: {', '.join(CONVERSIONS)})")
