"""Block mode judges what the log could not check over the whole log, as at once: the blocks'
coverage figures are summed and judged by the same rules (`logscan.verdict.coverage`), not each
block's lines repeated as the log's (`logscan.pipeline.block_fold`, docs/algorithms.md 8.1b)."""

from __future__ import annotations

import pytest

from logscan.pipeline.block_merge import BlockSpan, merged_coverage, said_once
from logscan.verdict.coverage import Coverage, FilterCoverage, GroupUse, JudgedShare, Stop

GROUND = "/vehicle_land_detected_0/landed"


def _share(suspended_s, total_s, unjudged_air_s=0.0, air_s=0.0, reasons=("on the ground",)) -> JudgedShare:
    return JudgedShare(suspended_s, total_s, unjudged_air_s, air_s, GROUND, reasons)


def _coverage(uses=None, share=None, stopped=None, judged_s=0.0, heard=()) -> Coverage:
    return Coverage(FilterCoverage(uses or {}, 0, 100), share, stopped or {}, judged_s, frozenset(heard), ())


def test_a_block_all_on_the_ground_does_not_leave_the_log_unjudged():
    """Block 1 never flew (all of it unjudged: over the limit on its own); block 2 flew 100 s and
    judged 80 of them. The log flew, and judged most of its flight: a warning, not "not fully checked"."""
    ground_block = _share(1800.0, 1800.0)
    assert ground_block.over and "never says airborne" in ground_block.line()
    log = merged_coverage([_coverage(share=ground_block), _coverage(share=_share(30.0, 120.0, 20.0, 100.0))])
    assert log is not None and log.share is not None
    assert not log.share.over
    assert log.share.line().startswith("not judged for 1830.0 s of 1920.0 s (20.0 s of the 100.0 s in flight)")


def test_a_gate_closed_in_one_block_only_is_no_gate_closed_all_flight():
    closed = GroupUse(0, 0.0, 5.0, "fix_type below 3, no 3D fix")
    assert closed.used == 0 and _coverage({"gnss": closed}).filter.lines()[0].startswith(
        "measurement group 'gnss': its gate was closed all flight"
    )
    log = merged_coverage([_coverage({"gnss": closed}), _coverage({"gnss": GroupUse(480, 500.0, 5.0, "")})])
    assert log is not None and log.filter.lines() == []


def test_a_sensor_stopped_in_a_block_and_heard_again_later_did_not_stop():
    stopped = {"baro": Stop(50.0, 10.0)}
    first = _coverage(stopped=stopped, heard={"baro"})
    heard_again = merged_coverage([first, _coverage(judged_s=60.0, heard={"baro"})])
    assert heard_again is not None and heard_again.stopped == {}
    log = merged_coverage([first, _coverage(judged_s=60.0, heard={"gps"})])
    assert log is not None and log.stopped == {"baro": Stop(50.0, 70.0)}  # its own 10 s and the next block's 60


def test_blocks_held_back_nowhere_count_for_the_log_and_none_held_back_is_no_line():
    """A block all in flight (nothing held back: no share of its own) still counts as flight; a
    log held back nowhere has no unjudged line, as at once."""
    takeoff, cruise = _share(10.0, 100.0, 5.0, 95.0), _share(0.0, 100.0, 0.0, 100.0)
    log = merged_coverage([_coverage(share=takeoff), _coverage(share=cruise)])
    assert log is not None and log.share is not None and log.share.air_s == 195.0
    nowhere = merged_coverage([_coverage(share=cruise), _coverage(share=cruise)])
    assert nowhere is not None and nowhere.share is None


def test_a_line_not_every_block_says_names_the_blocks_and_their_spans():
    spans = [BlockSpan(k + 1, 4, start, start + 599.99) for k, start in enumerate((-0.004, 600.0, 1200.0, 1800.0))]
    lines = [["read in part"], ["read in part", "gps: 3 of 9"], ["read in part"], ["read in part", "gps: 2 of 9"]]
    assert said_once(lines, spans) == [
        "read in part",
        "gps: 3 of 9 (in blocks 2, 4 of 4: 600.0-1200.0 s, 1800.0-2400.0 s; these figures are block 2's)",
    ]
    assert said_once([["a"], []], spans[:2]) == ["a (in block 1 of 4: 0.0-600.0 s)"]
    # a block refused (the third): the others' numbers stand
    assert said_once([["a"], [], ["a"]], [spans[0], spans[1], spans[3]]) == [
        "a (in blocks 1, 4 of 4: 0.0-600.0 s, 1800.0-2400.0 s)"
    ]


@pytest.mark.testdata("px4-ulog/sample_px4_events.ulg")
def test_a_real_ulog_in_short_blocks_is_not_checked_for_the_reasons_it_is_at_once():
    """The real PX4 events log (31 s; no 3D fix for its first 8 s, on the ground for most of it) in
    four blocks: the blocks said, as the log's, that the GNSS gate was closed all flight, that its
    NIS was never computed, that the model-based statistics never judged a flight (block 1's) and
    that they judged 1.7 of 23.4 s (block 3's, its lead-in counted). Judged over the log, the lines
    are those of the log at once."""
    from conftest import need_testdata

    from logscan.pipeline.blocks import analyze_blocked
    from logscan.pipeline.run import analyze_log

    path = need_testdata("px4-ulog/sample_px4_events.ulg")
    whole, blocks = analyze_log(path), analyze_blocked(path, block_s=10.0)
    assert blocks.unchecked == whole.unchecked
    assert len(whole.unchecked) == 1 and "27.7 s of 31.1 s (8.0 s of the 11.4 s in flight)" in whole.unchecked[0]
    assert blocks.exit_code() == whole.exit_code() == 2


@pytest.mark.testdata("ros-robots/robot_localization_test1_husky.bag")
def test_the_real_husky_drive_in_short_blocks_is_fully_checked_as_at_once():
    """The real Husky drive (ROS 1 bag) is fully checked at once (exit 0); in 3-s blocks its blocks'
    own lines made it "not fully checked" (exit 2). Judged over the log, its verdict is the same."""
    from conftest import need_testdata

    from logscan.pipeline.blocks import analyze_blocked
    from logscan.pipeline.run import analyze_log

    path = need_testdata("ros-robots/robot_localization_test1_husky.bag")
    whole, blocks = analyze_log(path), analyze_blocked(path, block_s=3.0)
    assert whole.unchecked == [] and whole.exit_code() == 0
    assert blocks.unchecked == [] and blocks.exit_code() == 0


def test_a_check_the_log_could_not_run_is_one_no_block_ran():
    """Merged over three blocks: a check with nothing to judge in blocks 1 and 3 is named with them;
    one without a valid sample in block 1 only had one in the others (not the log's, as at once);
    one no block could run, with each block's own figures, is the log's, with block 1's figures."""
    from logscan.pipeline.block_fold import _Detector
    from logscan.results import DetectorResult, NotChecked

    spans = [BlockSpan(k + 1, 3, 10.0 * k, 10.0 * k + 9.99) for k in range(3)]
    never, battery = NotChecked("gnss: never armed"), NotChecked("battery: connected 0 all flight", partial=True)
    blocks = [
        [never, battery, NotChecked("motor: NaN at all 7 samples")],
        [NotChecked("motor: NaN at all 9 samples")],
        [NotChecked("motor: NaN at all 3 samples"), never],
    ]
    detector = _Detector(DetectorResult("health", not_checked=blocks[0]))
    for k, not_checked in enumerate(blocks):
        detector.append(DetectorResult("health", not_checked=not_checked), 0, 0, 0, k)
    assert [n.reason for n in detector.merged(1.0, 0, spans).not_checked] == [
        "gnss: never armed (in blocks 1, 3 of 3: 0.0-10.0 s, 20.0-30.0 s)",
        "motor: NaN at all 7 samples (said in 3 of 3 blocks; these figures are block 1's)",
    ]


def test_a_blocks_stopped_sensor_counts_only_the_blocks_own_judged_time():
    """A block run from its lead-in (steps 0-59, the block before's) whose baro's last sample is at
    step 50: the judged time it stopped for is the block's own 40 steps, not the lead-in's too; at
    once (no first step given) all 49 steps after it."""
    from types import SimpleNamespace

    import numpy as np

    from logscan.verdict.coverage import stopped_groups

    t = np.arange(100) * 0.1
    z = np.where(np.arange(100)[:, None] <= 50, 1.0, np.nan)
    run = SimpleNamespace(n_steps=100, t=t, dt=0.1, groups={"baro": SimpleNamespace(z=z, gate_closed=None)})
    assert stopped_groups(run, None)["baro"] == Stop(pytest.approx(5.0), pytest.approx(4.9))
    assert stopped_groups(run, None, from_s=6.0)["baro"] == Stop(pytest.approx(5.0), pytest.approx(4.0))


@pytest.mark.testdata("px4-ulog/sample_px4_events.ulg")
def test_a_block_past_the_profiles_sensors_is_not_analysed_and_says_why():
    """A block whose own span holds no grid step (the log's other topics run on after its IMU
    stops: its lead-in alone has steps) raised IndexError; it is a block not analysed, said."""
    from conftest import need_testdata

    from logscan.pipeline.blocks import _in_blocks
    from logscan.pipeline.preparation import load_profile_for

    path = need_testdata("px4-ulog/sample_px4_events.ulg")
    merged = _in_blocks(path, None, load_profile_for(path, None), [(None, 31.0), (31.3, 40.0)], (None, None), {})
    assert merged.unchecked[-1] == (
        "block 2 of 2 (31.3-40.0 s) not analysed: no grid step of its own: the profile's sensors have no "
        "sample there (the grid ends at 31.1 s)"
    )
    assert merged.exit_code() == 2
