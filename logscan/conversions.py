"""Channel conversions of a measurement group (a profile's ``from`` key), vectorised over samples.

- ``from = "quaternion"``: channels (w, x, y, z), a Hamilton unit quaternion, scalar first, rotating
  body vectors into the world frame (PX4: body FRD -> world NED) -> ZYX Euler angles (roll, pitch,
  yaw) in radians of that body-to-world rotation, R = Rz(yaw) Ry(pitch) Rx(roll).
- ``from = "geodetic"``: channels (latitude deg, longitude deg, altitude m positive up) on the
  WGS-84 ellipsoid -> metres in the local tangent frame at an origin: (north, east, down) or
  (east, north, up).

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

FRAMES = ("ned", "enu")


@dataclass(frozen=True)
class Conversion:
    """A ``from`` conversion: the channels it reads, in order, and the outputs it gives."""

    name: str
    inputs: tuple[str, ...]  # what each channel must be, in the profile's order
    outputs: tuple[str, ...]  # the converted values, one column each

    def output_names(self, frame: str = "ned") -> tuple[str, ...]:
        if self.name == "geodetic" and frame == "enu":
            return ("east", "north", "up")
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

    ``frame`` "ned": columns (north, east, down = -up); "enu": (east, north, up). Rows outside the
    valid latitude / longitude range (`valid_geodetic`) are NaN.
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
    out = np.stack([north, east, -up] if frame == "ned" else [east, north, up], axis=1)
    out[~valid_geodetic(lla)] = np.nan
    return out


def convert(source: str, values: np.ndarray, *, origin=None, frame: str = "ned") -> np.ndarray:
    """The ``from = source`` conversion of held channel values (N, channels) -> (N, 3)."""
    if source == "quaternion":
        return quaternion_to_euler(values)
    if source == "geodetic":
        return geodetic_to_local(values, origin, frame)
    raise ValueError(f"unknown conversion {source!r} (choices: {', '.join(CONVERSIONS)})")
