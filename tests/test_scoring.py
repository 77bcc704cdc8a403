"""Scoring of alarm intervals against ground-truth events (docs/algorithms.md section 7.1)."""

from __future__ import annotations

import json
import math

import pytest

from logscan.errors import InputError
from logscan.results import AlarmInterval, FaultEvent, events_from_truth
from logscan.scoring import (
    aggregate,
    match_alarms,
    score_by_detector,
    score_log,
)

EV = FaultEvent(10.0, 12.0, "imu-bias", "accel.x")


def alarm(start, end, detector="d"):
    return AlarmInterval(start, end, start, start, 2.0, 1.0, 2.0, "upper", 1, "s", detector)


def test_alarm_inside_event_is_a_detection_with_latency():
    score = score_log([EV], [(10.25, 11.0)], duration_s=60)
    assert (score.tp, score.fn, score.fp) == (1, 0, 0)
    assert score.mean_latency_s == pytest.approx(0.25)
    assert score.precision == 1.0 and score.recall == 1.0 and score.f1 == 1.0


def test_alarm_touching_event_start_counts():
    score = score_log([EV], [(9.0, 10.0)])
    assert score.tp == 1 and score.fp == 0


def test_alarm_ending_just_before_event_is_false_alarm():
    score = score_log([EV], [(9.0, 9.999)])
    assert (score.tp, score.fn, score.fp) == (0, 1, 1)


def test_alarm_within_grace_after_event_end_counts():
    assert score_log([EV], [(13.0, 13.5)]).tp == 1  # starts exactly at t_end + grace
    assert score_log([EV], [(13.0001, 13.5)]).fp == 1  # just beyond


def test_grace_is_configurable():
    assert score_log([EV], [(13.5, 14.0)], grace_s=2.0).tp == 1
    assert score_log([EV], [(12.5, 13.0)], grace_s=0.0).fp == 1


def test_alarm_started_before_event_has_zero_latency_and_negative_raw_latency():
    score = score_log([EV], [(8.0, 10.5)])
    assert score.tp == 1
    assert score.latencies_s == [0.0]
    assert score.matches[0].raw_latency_s == pytest.approx(-2.0)


def test_two_alarms_on_one_event_count_once_and_latency_uses_earliest():
    score = score_log([EV], [(11.0, 11.2), (10.5, 10.6)])
    assert (score.tp, score.fp, score.n_alarms) == (1, 0, 2)
    assert score.latencies_s == [pytest.approx(0.5)]
    assert score.matches[0].alarm_indices == [0, 1]


def test_one_alarm_spanning_two_events_matches_the_first_only():
    second = FaultEvent(20.0, 21.0)
    score = score_log([second, EV], [(11.0, 20.5)])
    assert (score.tp, score.fn, score.fp) == (1, 1, 0)
    assert score.matches[1].detected and not score.matches[0].detected


def test_first_event_by_start_time_wins_when_windows_overlap():
    # alarm at 12.5 overlaps EV's grace window and a second event starting at 12.2
    other = FaultEvent(12.2, 15.0)
    _, alarm_event = match_alarms([other, EV], [(12.5, 12.6)])
    assert alarm_event == [1]


def test_open_ended_event_lasts_to_end_of_log():
    score = score_log([FaultEvent(5.0, None)], [(100.0, 101.0)])
    assert score.tp == 1 and score.latencies_s == [95.0]


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
    b = score_log([EV, FaultEvent(30, 31)], [(10.6, 11), (40, 41)], duration_s=60, detector="d")
    c = score_log([], [(1, 2)], duration_s=1800, detector="d")
    total = aggregate([a, b, c])
    assert (total.tp, total.fn, total.fp, total.n_logs) == (2, 1, 2, 3)
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
