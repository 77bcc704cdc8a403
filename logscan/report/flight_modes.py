"""Names of the flight modes a mode channel takes: PX4's ``vehicle_status.nav_state``.

A ULog carries the mode as a number only (its format message gives field names and types, not the
``NAVIGATION_STATE_*`` constants), so the names come from PX4's ``msg/VehicleStatus.msg``. PX4
reused some numbers across versions: in its older enum 6 to 9 were AUTO_RCRECOVER, AUTO_RTGS,
AUTO_LANDENGFAIL and AUTO_LANDGPSFAIL and 16 RATTITUDE; today's file has POSITION_SLOW or free slots
there, and 11 is free. Those values stay numbers ("7"), whatever the log's version (its ``ver_sw``
is a git hash and ``ver_sw_release`` a release number, and where each slot changed is not pinned
here); every other value names the same mode in both enums (ORBIT and AUTO_VTOL_TAKEOFF were added
later, at numbers unused before).

Any profile's ``[mode]`` may name its values (`logscan.profiles.schema.ModeSpec.labels`): the
built-in ROS profiles name a NavSatFix's ``status.status`` by sensor_msgs/NavSatStatus.msg's
``STATUS_*`` constants; a profile's names come before PX4's.
"""

from __future__ import annotations

from collections.abc import Mapping

# PX4 msg/VehicleStatus.msg, NAVIGATION_STATE_*: the numbers whose meaning never changed
PX4_NAV_STATES = {
    0: "MANUAL",
    1: "ALTCTL",
    2: "POSCTL",
    3: "AUTO_MISSION",
    4: "AUTO_LOITER",
    5: "AUTO_RTL",
    10: "ACRO",
    12: "DESCEND",
    13: "TERMINATION",
    14: "OFFBOARD",
    15: "STAB",
    17: "AUTO_TAKEOFF",
    18: "AUTO_LAND",
    19: "AUTO_FOLLOW_TARGET",
    20: "AUTO_PRECLAND",
    21: "ORBIT",
    22: "AUTO_VTOL_TAKEOFF",
}
NAV_STATE_FIELD = "nav_state"
PX4_STATUS_TOPIC = "vehicle_status"


def is_px4_nav_state(channel: str) -> bool:
    """Whether ``channel`` is PX4's ``vehicle_status[_N]/nav_state`` (a ULog or ulog2csv channel)."""
    parts = channel.strip("/").split("/")
    if len(parts) < 2 or parts[-1] != NAV_STATE_FIELD:
        return False
    topic = parts[-2]
    base, _, instance = topic.rpartition("_")
    return topic == PX4_STATUS_TOPIC or (base == PX4_STATUS_TOPIC and instance.isdigit())


def mode_name(channel: str, value: float, labels: Mapping[float, str] | None = None) -> str:
    """``value`` of the mode ``channel`` as the report shows it: "FIX (0)" for a value the profile's
    ``labels`` name, "AUTO_LOITER (4)" for a PX4 nav_state it can name, the number otherwise."""
    number = f"{value:g}"
    if labels and float(value) in labels:
        return f"{labels[float(value)]} ({number})"
    if is_px4_nav_state(channel) and float(value).is_integer() and int(value) in PX4_NAV_STATES:
        return f"{PX4_NAV_STATES[int(value)]} ({number})"
    return number


def has_names(channel: str, labels: Mapping[float, str] | None = None) -> bool:
    """Whether :func:`mode_name` names any value of ``channel``."""
    return bool(labels) or is_px4_nav_state(channel)
