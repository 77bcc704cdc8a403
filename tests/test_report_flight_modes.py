"""The report's flight modes: PX4 nav_state values drawn with their names, other mode channels as numbers."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_report import array

from logscan.report.context_figures import mode_figure
from logscan.report.flight_modes import is_px4_nav_state, mode_name
from logscan.report.run_context import ModeTrack


@pytest.mark.parametrize(
    ("channel", "expected"),
    [
        ("/vehicle_status_0/nav_state", True),
        ("/vehicle_status/nav_state", True),
        ("vehicle_status_1/nav_state", True),
        ("/vehicle_status_0/nav_state_user_intention", False),
        ("/my_vehicle_status_0/nav_state", False),
        ("/flight_mode/mode", False),
    ],
)
def test_px4_nav_state_channels_are_recognised(channel, expected):
    assert is_px4_nav_state(channel) is expected


def test_nav_state_values_are_named_as_in_vehicle_status_msg():
    channel = "/vehicle_status_0/nav_state"
    assert mode_name(channel, 4.0) == "AUTO_LOITER (4)"
    assert mode_name(channel, 5.0) == "AUTO_RTL (5)"
    assert mode_name(channel, 17.0) == "AUTO_TAKEOFF (17)"
    assert mode_name(channel, 14.0) == "OFFBOARD (14)"
    # slots PX4 reused across versions stay numbers, as do values outside the enum
    assert [mode_name(channel, v) for v in (6.0, 7.0, 16.0, 99.0, 4.5)] == ["6", "7", "16", "99", "4.5"]
    assert mode_name("/flight_mode/mode", 4.0) == "4"


def _track(channel: str) -> ModeTrack:
    intervals = [(0.0, 10.0, 17.0), (10.0, 40.0, 4.0), (40.0, 60.0, 5.0)]
    return ModeTrack(channel, np.array([0.0, 10.0, 40.0, 60.0]), np.array([17.0, 4.0, 5.0, 5.0]), intervals, 2)


def test_the_mode_figure_names_px4_flight_modes():
    figure = json.loads(mode_figure(_track("/vehicle_status_0/nav_state"))["json"])
    bands = [trace["name"] for trace in figure["data"][:-1]]
    assert bands == ["AUTO_LOITER (4)", "AUTO_RTL (5)", "AUTO_TAKEOFF (17)"]
    axis = figure["layout"]["yaxis"]
    assert axis["tickvals"] == [0, 1, 2]  # one row per mode, evenly spaced, each named at its row
    assert [(note["text"], note["y"]) for note in figure["layout"]["annotations"]] == list(zip(bands, [0, 1, 2]))
    assert array(figure["data"][-1]["y"]).tolist() == [2, 0, 1, 1]
    assert figure["data"][-1]["text"][0] == "AUTO_TAKEOFF (17)"  # on hover


def test_a_mode_channel_without_names_keeps_its_numbers():
    figure = json.loads(mode_figure(_track("/flight_mode/mode"))["json"])
    assert [trace["name"] for trace in figure["data"][:-1]] == [f"/flight_mode/mode = {v}" for v in (4, 5, 17)]
    assert "annotations" not in figure["layout"]


def test_the_profiles_mode_labels_name_a_ros_channels_values():
    track = _track("/fix/status.status")
    track.intervals = [(0.0, 10.0, -1.0), (10.0, 40.0, 0.0), (40.0, 60.0, 2.0)]
    track.value = np.array([-1.0, 0.0, 2.0, 2.0])
    track.labels = {-1.0: "NO_FIX", 0.0: "FIX", 2.0: "GBAS_FIX"}
    spec = mode_figure(track)
    figure = json.loads(spec["json"])
    assert [trace["name"] for trace in figure["data"][:-1]] == ["NO_FIX (-1)", "FIX (0)", "GBAS_FIX (2)"]
    assert figure["data"][-1]["text"][-1] == "GBAS_FIX (2)"  # on hover
    assert "profile's [mode] labels" in spec["caption"] and "PX4" not in spec["caption"]
    # a label comes before PX4's name; a value the labels leave out stays a number (or PX4's name)
    assert mode_name("/vehicle_status/nav_state", 4.0, {4.0: "HOLD"}) == "HOLD (4)"
    assert mode_name("/fix/status.status", 1.0, track.labels) == "1"


def test_mode_labels_are_checked_each_problem_on_its_own_line():
    from test_profile import QUAD

    from logscan.errors import ProfileError
    from logscan.profiles import dumps_toml, parse_profile

    def profile(mode: dict) -> str:
        return dumps_toml({**QUAD, "mode": {"channel": "/fix/status.status", **mode}})

    assert parse_profile(profile({"labels": {"-1": "NO_FIX", "0": "FIX"}})).mode.labels == {-1.0: "NO_FIX", 0.0: "FIX"}
    with pytest.raises(ProfileError) as error:
        parse_profile(profile({"labels": {"fix": "FIX", "1": "", "1.0": 3}}))
    text = "\n".join(error.value.problems)  # every problem, each on its own line (the CLI lists them all)
    assert "[mode] labels: key 'fix' is not a number" in text
    assert "[mode] labels: the name of '1' must be a non-empty string" in text
    assert "[mode] labels: the name of '1.0' must be a non-empty string, not 3" in text
    with pytest.raises(ProfileError, match=r"\[mode\] labels: expected a table of value = name"):
        parse_profile(profile({"labels": ["FIX"]}))
