"""Block mode's report context (`logscan.report.context_join`): each block's context of its own
steps, joined end to end, is the analysis at once's: the same mode intervals and changes, the path
on the position fixes over the whole log, the messages and their counts once each."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import SAMPLES

from logscan.log import LoggedMessage
from logscan.pipeline import analyze_log
from logscan.pipeline.blocks import analyze_blocked
from logscan.report.context_join import joined
from logscan.report.run_context import MAX_PATH_POINTS, ModeTrack, Path2D, RunContext

BIAS = SAMPLES / "quad_imu_bias.mcap"  # 60 s, its flight mode changing during it


@pytest.fixture(scope="module")
def contexts():
    whole = analyze_log(BIAS, free_series=True, sensor_views=True).prepared.context
    merged = analyze_blocked(BIAS, block_s=20.0, free_series=True, sensor_views=True).prepared.context
    return whole, merged


def test_the_mode_intervals_joined_across_borders_are_the_whole_logs(contexts):
    whole, merged = contexts
    assert whole.mode is not None and merged is not None and merged.mode is not None
    assert len(whole.mode.intervals) >= 2  # a change to join across (or not) at the borders of 20 and 40 s
    np.testing.assert_allclose(merged.mode.intervals, whole.mode.intervals, rtol=0, atol=1e-9)
    assert merged.mode.n_changes == whole.mode.n_changes
    assert merged.t_span == pytest.approx(whole.t_span, abs=1e-9)


def test_the_path_spans_the_log_on_its_position_fixes_once_each(contexts):
    whole, merged = contexts
    assert whole.path is not None and merged.path is not None
    t = merged.path.t
    assert np.all(np.diff(t) > 0)  # no lead-in fix twice
    assert t[0] == pytest.approx(whole.path.t[0]) and t[-1] == pytest.approx(whole.path.t[-1])
    assert np.count_nonzero((t > 15.0) & (t < 45.0)) > 10  # every block's part of it
    assert merged.path.group == whole.path.group and merged.path.channels == whole.path.channels
    assert merged.true_states == {}  # full-rate arrays: not kept in blocks


def _context(t0: float, t1: float, messages: list[float], outside: int, mode: list, states: list) -> RunContext:
    """A block's context over [t0, t1): messages at those times, ``outside`` of the log's others."""
    t = np.linspace(t0, t1, 50, endpoint=False)
    return RunContext(
        path=Path2D(t, np.sin(t), np.cos(t), ("x", "y"), "position"),
        mode=ModeTrack("mode", np.array([m[0] for m in mode]), np.array([m[2] for m in mode]), mode, len(mode) - 1),
        messages=[LoggedMessage(s, "WARNING", f"at {s}") for s in messages],
        t_span=(t0, t1 - 0.01),
        states={"armed": states},
        log_messages=[LoggedMessage(s, "INFO", f"at {s}") for s in messages],
        n_log_messages=len(messages),
        n_outside=outside,
    )


def test_joined_contexts_keep_each_message_once_and_join_what_runs_on():
    """Three blocks of a log of 10 messages: 4, 0 and 3 in their spans (3 outside any: a window).
    The counts are summed, the outside count is the log's less them; the mode's interval and the
    armed state that run across a border are one; a border where the value changes counts one."""
    a = _context(0.0, 10.0, [1.0, 2.0, 3.0, 9.0], 6, [(0.0, 10.0, 1.0)], [(2.0, 10.0)])
    b = _context(10.0, 20.0, [], 10, [(10.0, 15.0, 1.0), (15.0, 20.0, 2.0)], [(10.0, 20.0)])
    c = _context(20.0, 30.0, [21.0, 22.0, 25.0], 7, [(20.0, 30.0, 3.0)], [(20.0, 24.0)])
    merged = joined(joined(joined(None, a), b), c)
    assert [m.t for m in merged.messages] == [1.0, 2.0, 3.0, 9.0, 21.0, 22.0, 25.0]
    assert merged.n_log_messages == 7 and merged.n_outside == 3
    assert merged.mode.intervals == [(0.0, 15.0, 1.0), (15.0, 20.0, 2.0), (20.0, 30.0, 3.0)]
    assert merged.mode.n_changes == 2  # 1 -> 2 inside b, 2 -> 3 on the border
    assert merged.states == {"armed": [(2.0, 24.0)]}
    assert merged.t_span == (0.0, 29.99)
    assert merged.path.t.size == 150


def test_a_long_run_of_blocks_keeps_the_path_within_its_bound():
    """Forty blocks of 50 fixes each: the joined path is decimated again, never past twice the bound,
    and keeps the log's first and last fix."""
    merged = None
    for k in range(40):
        merged = joined(merged, _context(10.0 * k, 10.0 * (k + 1), [], 0, [(10.0 * k, 10.0 * (k + 1), 1.0)], []))
    assert merged.path.t.size <= 2 * MAX_PATH_POINTS
    assert merged.path.t[0] == 0.0 and merged.path.t[-1] == pytest.approx(399.8)
    assert merged.mode.intervals == [(0.0, 400.0, 1.0)] and merged.mode.n_changes == 0
