"""A log that ends with the vehicle in flight is not fully checked: its flight's end was not logged
(logscan/verdict/coverage.py `ends_in_flight`, docs/reading-the-report.md)."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import need_testdata
from ulog_edit import cut_ulog

from logscan.verdict.coverage import ends_in_flight

EVENTS = "px4-ulog/sample_px4_events.ulg"


@pytest.mark.testdata(EVENTS)
def test_a_px4_log_cut_cleanly_in_flight_says_its_flight_did_not_end_in_the_log(cli, tmp_path):
    """PX4's SITL flight cut at a message boundary 23.5 s in, armed and airborne (landed 0 since the
    take-off at 16.7 s, no disarm): nothing in the file is damaged, and the verdict said nothing of
    the flight's missing end."""
    cut = cut_ulog(need_testdata(EVENTS), tmp_path / "cut.ulg", 23.5)
    out = tmp_path / "s.json"
    result = cli("analyze", str(cut), "--no-report", "--json", str(out))
    (log,) = json.loads(out.read_text())["logs"]
    assert not any(u.startswith("the log was read only in part") for u in log["unchecked"])  # clean
    (line,) = [u for u in log["unchecked"] if u.startswith("the log ends in flight")]
    assert "/vehicle_land_detected_0/landed says airborne from 16.7 s" in line and "(23.5 s after" in line
    assert result.exit_code == 2 and "not fully checked" in log["verdict"]
    assert f"not checked: {line}" in result.stdout


def _run(ground, window=None):
    t = np.arange(len(ground)) * 0.5
    return SimpleNamespace(t=t, n_steps=t.size, ground=np.asarray(ground, dtype=float), window=window)


def test_only_a_ground_channel_saying_airborne_at_the_last_step_ends_in_flight():
    """The rule needs nothing of PX4: a ROS or CSV profile's [alarms] ground_channel is read the same."""
    policy = SimpleNamespace(ground_channel="/robot/on_ground")
    (line,) = ends_in_flight(_run([1, 1, 0, 0, 0]), policy)
    assert line.startswith("the log ends in flight: /robot/on_ground says airborne from 1.0 s to the last step (2.0 s")
    assert ends_in_flight(_run([1, 0, 0, 1]), policy) == []  # landed before the end
    assert ends_in_flight(_run([1, 0, np.nan]), policy) == []  # not known at the end
    assert ends_in_flight(_run([0, 0, 0]), policy)[0].startswith(
        "the log ends in flight: /robot/on_ground says airborne from 0.0 s"
    )
    assert ends_in_flight(_run([1, 0, 0], window=(None, 1.0)), policy) == []  # --end: the user's end
    assert ends_in_flight(_run([1, 0, 0], window=(0.5, None)), policy) != []  # --start only: the log's end
    assert ends_in_flight(_run([1, 0, 0]), SimpleNamespace(ground_channel=None)) == []
    assert ends_in_flight(_run([1, 0, 0]), None) == []
