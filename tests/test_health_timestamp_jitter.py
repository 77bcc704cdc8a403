"""A timestamp jitter is not a stop (`health` timeouts, docs/algorithms.md 3c): on a real PX4 flight
whose IMU timestamps were moved, a gap after which the sample count catches up is no timeout; a
silence that lost its samples still says the topic stopped."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import need_testdata
from pyulog import ULog
from ulog_edit import edit_ulog

EVENTS = "px4-ulog/sample_px4_events.ulg"  # SITL quadcopter, 31 s, sensor_combined at 250 Hz
IMU = "sensor_combined"
TIMEOUT = "health.timeout.sensor_combined_0"


def _health(cli, path, tmp_path) -> tuple[list[dict], list[str]]:
    out = tmp_path / f"{path.name}.json"
    cli("analyze", str(path), "--no-report", "--json", str(out))
    log = json.loads(out.read_text())["logs"][0]
    health = next(d for d in log["detectors"] if d["detector"] == "health")
    return health["alarms"], health["warnings"]


def _stamped_late(data) -> None:
    """Every 500th sample and the five after it stamped just before the sixth after it (as a busy
    scheduler stamps a backlog): a 7-period gap, then six samples bunched, none lost."""
    t = data["timestamp"].astype(np.int64)
    for j in range(300, t.size - 10, 500):
        t[j : j + 6] = t[j + 6] - np.arange(6, 0, -1) * 10
    data["timestamp"][:] = t.astype(np.uint64)


def _jittered(data) -> None:
    """Each timestamp moved by up to 6 periods either way (out of the log's order)."""
    t = data["timestamp"].astype(np.int64)
    period = np.median(np.diff(t))
    data["timestamp"][:] = (t + np.random.default_rng(1).uniform(-6.0, 6.0, t.size) * period).astype(np.uint64)


@pytest.mark.testdata(EVENTS)
@pytest.mark.parametrize("edit", [_stamped_late, _jittered], ids=["late_bursts", "jitter_6_periods"])
def test_an_imu_timestamp_jitter_is_not_read_as_a_stopped_topic(cli, tmp_path, edit):
    path = edit_ulog(need_testdata(EVENTS), tmp_path / f"{edit.__name__}.ulg", {IMU: edit})
    alarms, warnings = _health(cli, path, tmp_path)
    assert not [a for a in alarms if a["signal"] == TIMEOUT], alarms
    if edit is _stamped_late:  # gaps over the limit that lost nothing: said to be a jitter
        assert any("sensor_combined_0's timestamps jitter" in w for w in warnings), warnings


@pytest.mark.testdata(EVENTS)
def test_an_imu_silence_that_lost_its_samples_still_says_stopped(cli, tmp_path):
    source = need_testdata(EVENTS)
    start_us = ULog(str(source), [IMU]).start_timestamp

    def stopped(data) -> None:  # every sample after 20 s stamped 2 s later: a 2-s silence, 2 s lost
        t = data["timestamp"].astype(np.int64)
        t[t >= start_us + 20_000_000] += 2_000_000
        data["timestamp"][:] = t.astype(np.uint64)

    path = edit_ulog(source, tmp_path / "stopped.ulg", {IMU: stopped})
    alarms, _ = _health(cli, path, tmp_path)
    timeouts = [a for a in alarms if a["signal"] == TIMEOUT]
    assert len(timeouts) == 1 and 20.0 <= timeouts[0]["start"] <= 20.1, timeouts
