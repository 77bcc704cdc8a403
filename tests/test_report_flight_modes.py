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
