"""Scoring of alarm intervals against ground-truth events and transients (docs/algorithms.md section 7.1)."""

from __future__ import annotations

import json
import math

import pytest

from logscan.alarms import AlarmInterval
from logscan.errors import InputError
from logscan.results import FaultEvent, events_from_truth
from logscan.verdict.scoring import (
    AT_ONSET,
    DETECTION,
    FALSE_ALARM,
    RECOVERY,
    TRANSIENT,
    aggregate,
    classify_alarms,
    match_alarms,
    score_by_detector,
    score_log,
)

EV = FaultEvent(10.0, 12.0, "imu-bias", "accel.x")  # window [10, 13] with grace 1, recovery (13, 18]
GLITCH = FaultEvent(30.0, 30.01, "glitch", "accel.y")  # transient window [30, 31.01] with grace 1


def alarm(start, end, detector="d"):
    return AlarmInterval(start, end, start, start, 2.0, 1.0, 2.0, "upper", 1, "s", detector)


def test_alarm_inside_event_is_a_detection_with_latency():
    score = score_log([EV], [(10.25, 11.0)], duration_s=60)
    assert (score.tp, score.fn, score.fp) == (1, 0, 0)
    assert score.mean_latency_s == pytest.approx(0.25)
    assert score.precision == 1.0 and score.recall == 1.0 and score.f1 == 1.0


def test_alarm_starting_exactly_at_onset_is_a_detection_with_latency_zero():
    score = score_log([EV], [(10.0, 10.5)])
    assert (score.tp, score.at_onset, score.fp) == (1, 0, 0)
    assert score.latencies_s == [0.0]


def test_alarm_ending_exactly_at_onset_is_active_at_onset_not_a_detection():
    score = score_log([EV], [(9.0, 10.0)])
    assert (score.tp, score.fn, score.fp, score.at_onset) == (0, 1, 0, 1)
    assert score.matches[0].active_at_onset and score.matches[0].onset_alarm_indices == [0]


def test_alarm_ending_just_before_event_is_false_alarm():
    score = score_log([EV], [(9.0, 9.999)])
    assert (score.tp, score.fn, score.fp) == (0, 1, 1)


def test_alarm_within_grace_after_event_end_counts():
    assert score_log([EV], [(13.0, 13.5)]).tp == 1  # starts exactly at t_end + grace
    # just beyond: the event was not detected, so there is no recovery window either
    assert score_log([EV], [(13.0001, 13.5)]).fp == 1


def test_grace_is_configurable():
    assert score_log([EV], [(13.5, 14.0)], grace_s=2.0).tp == 1
    assert score_log([EV], [(12.5, 13.0)], grace_s=0.0).fp == 1


def test_alarm_on_before_the_onset_is_active_at_onset_neither_detection_nor_false_alarm():
    score = score_log([EV], [(8.0, 10.5)], duration_s=60)
    assert (score.tp, score.fn, score.fp, score.at_onset) == (0, 1, 0, 1)
    assert score.latencies_s == [] and score.recall == 0.0
    assert score.precision is None  # neither a detection nor a false alarm
    _, outcomes = classify_alarms([EV], [(8.0, 10.5)])
    assert outcomes == [(AT_ONSET, 0)]


def test_alarm_started_after_an_onset_alarm_makes_the_detection_and_sets_latency():
    score = score_log([EV], [(8.0, 10.5), (11.0, 11.5)])
    assert (score.tp, score.fp, score.at_onset) == (1, 0, 1)
    assert score.latencies_s == [pytest.approx(1.0)]
    match = score.matches[0]
    assert match.alarm_indices == [1] and match.onset_alarm_indices == [0]


def test_alarm_ending_just_before_the_onset_is_not_active_at_onset():
    score = score_log([EV], [(8.0, 9.999)])
    assert (score.at_onset, score.fp) == (0, 1)


def test_two_alarms_on_one_event_count_once_and_latency_uses_earliest():
    score = score_log([EV], [(11.0, 11.2), (10.5, 10.6)])
    assert (score.tp, score.fp, score.n_alarms) == (1, 0, 2)
    assert score.latencies_s == [pytest.approx(0.5)]
    assert score.matches[0].alarm_indices == [0, 1]


def test_one_alarm_spanning_two_events_detects_the_first_and_is_on_at_the_second_onset():
    second = FaultEvent(20.0, 21.0)
    score = score_log([second, EV], [(11.0, 20.5)])
    assert (score.tp, score.fn, score.fp, score.at_onset) == (1, 1, 0, 1)
    assert score.matches[1].detected and not score.matches[0].detected
    assert score.matches[0].active_at_onset and not score.matches[1].active_at_onset


def test_recovery_window_follows_the_grace_period_of_a_detected_fault():
    alarms = [(10.5, 11.0), (13.0001, 13.2), (18.0, 18.5), (18.0001, 19.0)]
    matches, outcomes = classify_alarms([EV], alarms, recovery_s=5.0)
    assert [o.kind for o in outcomes] == [DETECTION, RECOVERY, RECOVERY, FALSE_ALARM]
    assert matches[0].recovery_indices == [1, 2]
    score = score_log([EV], alarms, duration_s=60)
    assert (score.tp, score.fp, score.recovery_alarms, score.n_alarms) == (1, 1, 2, 4)
    assert score.precision == pytest.approx(0.5)


def test_recovery_window_is_configurable_and_zero_disables_it():
    alarms = [(10.5, 11.0), (20.0, 20.5)]
    assert score_log([EV], alarms, recovery_s=5.0).fp == 1
    assert score_log([EV], alarms, recovery_s=7.0).recovery_alarms == 1
    assert score_log([EV], alarms[:1] + [(13.5, 14.0)], recovery_s=0.0).fp == 1


def test_no_recovery_window_after_a_missed_fault():
    score = score_log([EV], [(14.0, 14.5)])
    assert (score.tp, score.fp, score.recovery_alarms) == (0, 1, 0)


def test_no_recovery_window_after_a_fault_detected_only_at_onset():
    score = score_log([EV], [(9.0, 11.0), (14.0, 14.5)])
    assert (score.at_onset, score.tp, score.fp, score.recovery_alarms) == (1, 0, 1, 0)


def test_alarm_overlapping_a_healthy_transient_is_a_transient_alarm():
    alarms = [(29.0, 30.0), (31.01, 31.5), (31.02, 31.5), (20.0, 29.999)]
    _, outcomes = classify_alarms([], alarms, transients=[GLITCH])
    assert outcomes == [(TRANSIENT, 0), (TRANSIENT, 0), (FALSE_ALARM, None), (FALSE_ALARM, None)]
    score = score_log([], alarms, duration_s=3600, transients=[GLITCH])
    assert (score.transient_alarms, score.fp, score.healthy_fp) == (2, 2, 2)
    assert score.false_alarms_per_hour_healthy == pytest.approx(2.0)


def test_transient_alarms_on_a_faulty_log_are_neither_detections_nor_false_alarms():
    score = score_log([EV], [(10.2, 10.4), (30.0, 30.1)], transients=[GLITCH])
    assert (score.tp, score.fp, score.transient_alarms) == (1, 0, 1)
    assert score.precision == 1.0


def test_recovery_and_onset_take_precedence_over_a_transient():
    glitch = FaultEvent(14.0, 14.0, "glitch")
    _, outcomes = classify_alarms([EV], [(10.5, 11.0), (14.0, 14.2)], transients=[glitch])
    assert outcomes[1] == (RECOVERY, 0)
    early = FaultEvent(9.0, 9.02, "glitch")
    _, outcomes = classify_alarms([EV], [(9.0, 10.2)], transients=[early])
    assert outcomes == [(AT_ONSET, 0)]


def test_match_alarms_reports_detections_only():
    matches, alarm_event = match_alarms([EV], [(8.0, 10.5), (11.0, 11.2), (14.0, 14.1), (50.0, 50.1)])
    assert alarm_event == [None, 0, None, None]
    assert matches[0].detected and matches[0].active_at_onset


def test_first_event_by_start_time_wins_when_windows_overlap():
    # alarm at 12.5 overlaps EV's grace window and a second event starting at 12.2
    other = FaultEvent(12.2, 15.0)
    _, alarm_event = match_alarms([other, EV], [(12.5, 12.6)])
    assert alarm_event == [1]


def test_open_ended_event_lasts_to_end_of_log():
    score = score_log([FaultEvent(5.0, None)], [(100.0, 101.0)])
    assert score.tp == 1 and score.latencies_s == [95.0]
    assert score_log([FaultEvent(5.0, None)], [(6.0, 7.0), (1e6, 1e6 + 1)]).fp == 0  # no recovery beyond


def test_no_alarms_no_events_gives_undefined_precision_recall_f1():
    score = score_log([], [], duration_s=3600)
    assert score.precision is None and score.recall is None and score.f1 is None
    assert score.false_alarms_per_hour == 0.0
    assert score.false_alarms_per_hour_healthy == 0.0


def test_missed_event_without_alarms_has_recall_zero_and_precision_undefined():
    score = score_log([EV], [])
    assert score.recall == 0.0 and score.precision is None and score.f1 is None
    assert score.mean_latency_s is None and score.max_latency_s is None


def test_all_false_alarms_gives_f1_zero():
    score = score_log([EV], [(0.0, 1.0)])
    assert score.precision == 0.0 and score.recall == 0.0 and score.f1 == 0.0


def test_false_alarms_per_hour_on_healthy_log():
    score = score_log([], [(1, 2), (5, 6), (9, 9)], duration_s=1800)
    assert score.fp == 3
    assert score.false_alarms_per_hour == pytest.approx(6.0)
    assert score.false_alarms_per_hour_healthy == pytest.approx(6.0)


def test_false_alarms_on_faulty_log_do_not_count_as_healthy():
    score = score_log([EV], [(0.0, 1.0)], duration_s=3600)
    assert score.false_alarms_per_hour == pytest.approx(1.0)
    assert score.false_alarms_per_hour_healthy is None


def test_aggregate_sums_counts_and_pools_latency():
    a = score_log([EV], [(10.2, 10.3)], duration_s=60, detector="d")
    b = score_log([EV, FaultEvent(30, 31)], [(10.6, 11), (14, 15), (29, 31), (40, 41)], duration_s=60, detector="d")
    c = score_log([], [(1, 2), (5, 5.1)], duration_s=1800, transients=[FaultEvent(5.0, 5.01)], detector="d")
    total = aggregate([a, b, c])
    assert (total.tp, total.fn, total.fp, total.n_logs) == (2, 1, 2, 3)
    assert (total.at_onset, total.recovery_alarms, total.transient_alarms, total.n_alarms) == (1, 1, 1, 7)
    assert total.precision == pytest.approx(2 / 4)
    assert total.recall == pytest.approx(2 / 3)
    assert sorted(total.latencies_s) == pytest.approx([0.2, 0.6])
    assert total.mean_latency_s == pytest.approx(0.4)
    assert total.max_latency_s == pytest.approx(0.6)
    assert total.duration_s == pytest.approx(1920)
    assert total.false_alarms_per_hour_healthy == pytest.approx(2.0)
    assert total.detector == "d"


def test_aggregate_duration_unknown_when_any_log_lacks_it():
    total = aggregate([score_log([], [], duration_s=10), score_log([], [])])
    assert total.duration_s is None and total.false_alarms_per_hour is None


def test_score_by_detector_passes_recovery_and_transients_to_every_detector():
    alarms = [alarm(10.1, 10.2, "nis"), alarm(15.0, 15.1, "nis"), alarm(30.0, 30.1, "enc")]
    scores = score_by_detector([EV], alarms, duration_s=60, transients=[GLITCH], recovery_s=5.0)
    assert (scores["nis"].tp, scores["nis"].recovery_alarms, scores["nis"].fp) == (1, 1, 0)
    assert (scores["enc"].transient_alarms, scores["enc"].fp) == (1, 0)
    assert score_by_detector([EV], alarms, recovery_s=1.0)["nis"].fp == 1


def test_score_by_detector_groups_alarms_and_keeps_silent_detectors():
    scores = score_by_detector(
        [EV], [alarm(10.1, 10.2, "nis"), alarm(50, 51, "enc")], duration_s=60, detectors=["enc", "kgn"]
    )
    assert set(scores) == {"enc", "kgn", "nis"}
    assert scores["nis"].tp == 1 and scores["enc"].fp == 1 and scores["enc"].tp == 0
    assert scores["kgn"].n_alarms == 0 and scores["kgn"].fn == 1


def test_to_dict_is_json_ready_with_null_for_undefined():
    data = score_log([EV], [], duration_s=60).to_dict()
    text = json.dumps(data, allow_nan=False)
    assert json.loads(text)["precision"] is None
    assert data["events"][0]["detected"] is False


def test_to_dict_carries_the_new_counts_and_the_per_event_flag():
    alarms = [(9.0, 10.5), (11.0, 11.5), (14.0, 14.5), (30.5, 30.6)]
    data = score_log([EV], alarms, duration_s=60, transients=[GLITCH]).to_dict()
    assert (data["at_onset"], data["recovery_alarms"], data["transient_alarms"], data["fp"]) == (1, 1, 1, 0)
    event = data["events"][0]
    assert event["active_at_onset"] is True and event["detected"] is True
    assert (event["alarms"], event["onset_alarms"], event["recovery_alarms"]) == ([1], [0], [2])
    assert event["latency_s"] == pytest.approx(1.0)


def test_events_from_truth_accepts_both_key_spellings():
    events = events_from_truth(
        [{"t_start": 1, "t_end": 2, "kind": "bias", "target": "accel.x"}, {"start": 3, "end": None}]
    )
    assert events[0] == FaultEvent(1.0, 2.0, "bias", "accel.x")
    assert events[1].t_end is None and math.isinf(events[1].end_or_inf)


@pytest.mark.parametrize("record", [{"kind": "bias"}, {"t_start": "x"}, {"t_start": 5, "t_end": 1}])
def test_events_from_truth_rejects_bad_records(record):
    with pytest.raises(InputError, match="ground-truth event 0"):
        events_from_truth([record], path="truth.json")


def test_simultaneous_faults_are_each_detected_by_the_alarm_that_names_them():
    """A hierarchical robot's attack hits the mocap position and both encoders at once: an alarm
    counts for every fault whose target its statistic names, else for the first fault only."""
    from logscan.verdict.evaluation import Span

    events = [
        FaultEvent(3.25, 5.0, "bias", "position"),
        FaultEvent(3.25, 5.0, "bias", "left_motor.encoder"),
        FaultEvent(3.25, 5.0, "bias", "right_motor.encoder"),
    ]
    outer = AlarmInterval(3.3, 6.0, 3.3, 3.5, 9.0, 1.0, 9.0, "upper", 5, signal="nis.position")
    left = AlarmInterval(3.25, 7.0, 3.25, 3.4, 9.0, 1.0, 9.0, "upper", 5, signal="left_motor/nis.encoder")
    matches, _ = classify_alarms(events, [outer, left])
    assert [m.detected for m in matches] == [True, True, False]  # the right encoder: nothing names it
    merged = Span(3.25, 7.0, frozenset({"nis.position", "left_motor/nis.encoder", "right_motor/nis.encoder"}))
    assert all(m.detected for m in classify_alarms(events, [merged])[0])
    anonymous = AlarmInterval(3.3, 6.0, 3.3, 3.5, 9.0, 1.0, 9.0, "upper", 5, signal="nis.all")
    assert [m.detected for m in classify_alarms(events, [anonymous])[0]] == [True, False, False]
