"""Profiles: the TOML that maps a log's channels to a vehicle model, sensors and detectors.

A profile is parsed with tomllib, checked section by section (`parse`: every problem is collected,
then raised as one ProfileError naming the file, the first problem and how many more), bound to the
vehicle model's input and measurement-group names through the model registry (`bind`), and written
back with `Profile.to_toml()` (`toml_writer`; the simulator embeds that text in MCAP metadata
`logscan.profile`). The dataclasses are in `schema`, documented in docs/profiles.md.
"""

from logscan.profiles.parse import load_profile, parse_profile, resolve_profile, validate
from logscan.profiles.schema import (
    GROUP_STALE_PERIODS,
    INPUT_STALE_STEPS,
    MODE_STALE_S,
    ONBOARD_STALE_S,
    DetectorSpec,
    InputSpec,
    MeasurementSpec,
    ModelFacts,
    ModeSpec,
    OnboardSpec,
    Profile,
    RedundantSpec,
    SensorSpec,
    VehicleSpec,
    channels_under,
)
from logscan.profiles.toml_writer import dumps_toml

__all__ = [
    "GROUP_STALE_PERIODS",
    "INPUT_STALE_STEPS",
    "MODE_STALE_S",
    "ONBOARD_STALE_S",
    "DetectorSpec",
    "InputSpec",
    "MeasurementSpec",
    "ModeSpec",
    "ModelFacts",
    "OnboardSpec",
    "Profile",
    "RedundantSpec",
    "SensorSpec",
    "VehicleSpec",
    "channels_under",
    "dumps_toml",
    "load_profile",
    "parse_profile",
    "resolve_profile",
    "validate",
]
