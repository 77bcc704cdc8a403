"""A profile's sections as TOML-ready data (`Profile.to_dict`): a measurement group, a [redundant]
group and the [alarms] policy, each with its defaults written out as the checker reads them back."""

from __future__ import annotations

from typing import Any

# The specs are read by attribute only: importing logscan.profiles.schema here, even for the type
# checker, would close an import cycle (schema's Profile.to_dict calls these).


def group_table(g: Any) -> dict[str, Any]:
    """A measurement group as TOML-ready data."""
    table: dict[str, Any] = {"channels": g.channels, "rate_hz": g.rate_hz, "stale_s": g.stale_s}
    for key in ("noise_std", "range_lo", "range_hi", "scale", "offset"):
        if getattr(g, key) is not None:
            table[key] = getattr(g, key)
    if g.source is not None:
        table["from"] = g.source
    if g.source == "geodetic" or g.frame != "ned":
        table["frame"] = g.frame
    if g.origin is not None:
        table["origin"] = g.origin
    if g.noise_channels is not None:
        table["noise_channels"] = g.noise_channels
        if g.noise_channels_scale != 1.0:
            table["noise_channels_scale"] = g.noise_channels_scale
    if g.gate_channel is not None:
        table["gate"] = {"channel": g.gate_channel, "min": g.gate_min}
    if g.delay_s:
        table["delay_s"] = g.delay_s
    if g.fresh != "on_sample":  # written only when set: default profiles' TOML is unchanged
        table["fresh"] = g.fresh
    return table


def redundant_table(r: Any) -> dict[str, Any]:
    """A [redundant] group as TOML-ready data."""
    sensors = {
        s.name: ({"channel": s.channel, "poly": s.poly} if s.poly is not None else s.channel)
        for s in r.sensors.values()
    }
    table: dict[str, Any] = {"sensors": sensors}
    if r.rate_hz is not None:
        table["rate_hz"] = r.rate_hz
    if r.stale_s is not None:
        table["stale_s"] = r.stale_s
    return table


def alarms_table(policy: Any) -> dict[str, Any]:
    """The [alarms] policy as TOML-ready data."""
    table: dict[str, Any] = {
        "n_persist": policy.n_persist,
        "min_duration_s": policy.min_duration_s,
        "merge_gap_s": policy.merge_gap_s,
    }
    if policy.ground_channel:
        table["ground_channel"] = policy.ground_channel
        table["after_ground_s"] = policy.after_ground_s
        if policy.before_ground_s:
            table["before_ground_s"] = policy.before_ground_s
        if policy.min_ground_s:
            table["min_ground_s"] = policy.min_ground_s
    if policy.ignore_start_s:
        table["ignore_start_s"] = policy.ignore_start_s
    return table
