"""Anomalies from a detector's alarms (specific: the group its statistic names; generic otherwise)
and from the ground truth (the oracle used for evaluation)."""

from __future__ import annotations

import math

import pytest
from recovery_linear import make_loop

from logscan.alarms import AlarmInterval
from logscan.recovery import Anomaly, anomalies_from_alarms, anomalies_from_truth
from logscan.results import FaultEvent


def alarm(start, end, signal):
    return AlarmInterval(start, end, start, start, 10.0, 1.0, 10.0, "upper", 3, signal=signal, detector="any")


@pytest.fixture(scope="module")
def loops():
    return [make_loop("outer", N=100, seed=0)[0], make_loop("left", N=100, seed=1)[0]]


def test_an_alarm_naming_a_group_flags_it_and_overlapping_alarms_join(loops):
    alarms = {"outer": [alarm(2.0, 3.0, "nis.gps"), alarm(2.5, 4.0, "nis.odo")], "left": [alarm(6.0, 7.0, "nis.gps")]}
    found = anomalies_from_alarms(alarms, loops)
    assert found == [
        Anomaly(2.0, 4.0, {"outer": ("gps", "odo")}, {"outer": 4.0}),
        Anomaly(6.0, 7.0, {"left": ("gps",)}, {"left": 7.0}),
    ]
    # loops that share a group name stay apart; alarms of two loops that overlap join
    both = anomalies_from_alarms({"outer": [alarm(2.0, 3.0, "nis.gps")], "left": [alarm(2.9, 3.5, "nis.gps")]}, loops)
    assert both == [Anomaly(2.0, 3.5, {"outer": ("gps",), "left": ("gps",)}, {"outer": 3.0, "left": 3.5})]
    assert both[0].last_seen("outer") == 3.0  # each loop until its own alarm ended


def test_an_alarm_naming_no_group_or_a_generic_detector_makes_a_generic_anomaly(loops):
    mixed = anomalies_from_alarms({"outer": [alarm(2.0, 3.0, "nis.gps"), alarm(2.8, 3.2, "nis.all")]}, loops)
    assert mixed == [Anomaly(2.0, 3.2, None, {"outer": 3.2})]
    generic = anomalies_from_alarms({"outer": [alarm(2.0, 3.0, "nis.gps")]}, loops, specific=False)
    assert generic == [Anomaly(2.0, 3.0, None, {"outer": 3.0})] and not generic[0].specific
    gap = anomalies_from_alarms(
        {"outer": [alarm(2.0, 3.0, "nis.gps"), alarm(3.4, 4.0, "nis.gps")]}, loops, merge_gap_s=0.5
    )
    assert gap == [Anomaly(2.0, 4.0, {"outer": ("gps",)}, {"outer": 4.0})]
    with pytest.raises(ValueError, match="unknown loop"):
        anomalies_from_alarms({"right": []}, loops)


def test_the_truth_oracle_detects_each_fault_after_the_detection_time(loops):
    events = [
        FaultEvent(2.0, 4.0, "bias", "gps.x"),  # the simulator's group.output: every loop with gps
        FaultEvent(5.0, 6.0, "bias", "left.odo.v"),  # qualified by its loop
        FaultEvent(7.0, None, "actuator-offset", "motor"),  # no sensor: generic, until the log's end
    ]
    found = anomalies_from_truth(events, 0.5, loops)
    assert found[0] == Anomaly(2.5, 4.0, {"outer": ("gps",), "left": ("gps",)})
    assert found[1] == Anomaly(5.5, 6.0, {"left": ("odo",)})
    assert found[2].t_detect == 7.5 and found[2].targets is None and math.isclose(found[2].t_end, 9.9)
    with pytest.raises(ValueError, match="detection_time_s"):
        anomalies_from_truth(events, -1.0, loops)


def test_the_truth_oracle_matches_a_faults_log_channels():
    loops = [make_loop("outer", N=50, seed=0)[0], make_loop("left", N=50, seed=1)[0]]
    loops[1].run.groups["odo"].channels = ["/left/encoder/v"]
    found = anomalies_from_truth([FaultEvent(1.0, 2.0, "bias", "encoder", channels=("/left/encoder/v",))], 0.0, loops)
    assert found == [Anomaly(1.0, 2.0, {"left": ("odo",)})]
