"""Plain words for measurement groups and sensors, shared by the detectors' statistic labels.

Each detector owns the words of its statistics (`Detector.signal_label`); what they have in common
is the sensor a statistic is about, named here once: a measurement group of the model ("accel" ->
"accelerometer"), else its name with spaces.
"""

from __future__ import annotations

import re

GROUP_WORDS = {
    "accel": "accelerometer",
    "gyro": "gyroscope",
    "baro": "barometer",
    "mag": "magnetometer",
    "gps": "GPS",
    "gps_speed": "GPS speed",
    "position": "position sensor",
    "velocity": "velocity sensor",
    "attitude": "attitude sensor",
    "encoder": "wheel encoders",
    "yaw_rate": "yaw-rate sensor",
    "steer_angle": "steering-angle sensor",
    "steering_angle": "steering-angle sensor",
    "lateral_accel": "lateral accelerometer",
    "current": "motor current sensor",
    "gnss_position": "GNSS position",
    "gnss_velocity": "GNSS velocity",
    "heading": "compass heading",
    "odometry": "odometry",
    "speed": "speed sensors",
    "left": "left wheel encoder",
    "right": "right wheel encoder",
}
_INDEX_RE = re.compile(r"^(?P<base>.+)\[(?P<index>\d+)\]$")


def group_words(name: str) -> str:
    """A measurement group or sensor in words: "accel" -> "accelerometer", "encoder[1]" -> "wheel
    encoders (channel 1)", an unknown "wheel_odo" -> "wheel odo"."""
    indexed = _INDEX_RE.match(name)
    if indexed:
        return f"{group_words(indexed.group('base'))} (channel {indexed.group('index')})"
    return GROUP_WORDS.get(name, name.replace("_", " "))
