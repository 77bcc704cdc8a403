"""Block mode's report context: the `RunContext` of each block's own steps (`run_context`'s
``from_s``), joined end to end into the log's (`joined`), within the same bounds as one run's.

- the path and the mode's series: the blocks' points end to end, decimated again as one run's
  (`MAX_PATH_POINTS`, `MAX_MODE_POINTS`) once they hold twice as many;
- the mode's intervals and the autopilot's states: end to end, an interval that runs to a block's
  end joined with the next block's that begins there with the same value; the mode's intervals
  dropped (a step line instead) past `MAX_MODE_INTERVALS`, as in one run;
- the logged messages: end to end, the first `MAX_MESSAGES` / `MAX_LOG_MESSAGES`; their counts
  summed (each block counts those in its own span, so the log's messages outside the blocks stay
  outside);
- the parameters: the first block's (the log's);
- the true state (full-rate arrays on the grid): not kept; block mode's report draws no UBIKF truth.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from logscan.log import MAX_MESSAGES
from logscan.report.decimate import decimate_indices
from logscan.report.run_context import (
    MAX_LOG_MESSAGES,
    MAX_MODE_INTERVALS,
    MAX_MODE_POINTS,
    MAX_PATH_POINTS,
    MAX_STATE_INTERVALS,
    ModeTrack,
    Path2D,
    RunContext,
    path_indices,
    run_starts,
)

_TOUCH_S = 1e-6  # an interval ending this close to where the next begins runs on into it


def own_part(context: RunContext | None) -> RunContext | None:
    """A block's context as kept once its full-rate arrays are freed: all but the true state."""
    return None if context is None else replace(context, true_states={})


def joined(before: RunContext | None, after: RunContext | None) -> RunContext | None:
    """``after`` (a later block's context) after ``before`` (the blocks' before it)."""
    if before is None or after is None:
        return after if before is None else before
    return replace(
        before,
        path=_paths(before.path, after.path),
        mode=_modes(before.mode, after.mode),
        messages=(before.messages + after.messages)[:MAX_MESSAGES],
        t_span=_span(before.t_span, after.t_span),
        states={
            name: _intervals(before.states.get(name, []), after.states.get(name, []))[:MAX_STATE_INTERVALS]
            for name in {**before.states, **after.states}
        },
        log_messages=(before.log_messages + after.log_messages)[:MAX_LOG_MESSAGES],
        n_log_messages=before.n_log_messages + after.n_log_messages,
        n_outside=after.n_outside - before.n_log_messages,  # the log's, less the blocks' so far
        window=_span(before.window, after.window),
    )


def _span(a: tuple[float, float] | None, b: tuple[float, float] | None) -> tuple[float, float] | None:
    return a if b is None else b if a is None else (a[0], b[1])


def _paths(a: Path2D | None, b: Path2D | None) -> Path2D | None:
    if a is None or b is None:
        return a if b is None else b
    t, x, y = (np.concatenate([getattr(a, f), getattr(b, f)]) for f in ("t", "x", "y"))
    if t.size > 2 * MAX_PATH_POINTS:
        idx = path_indices(x, y, np.arange(t.size), MAX_PATH_POINTS)
        t, x, y = t[idx], x[idx], y[idx]
    return replace(a, t=t, x=x, y=y)


def _modes(a: ModeTrack | None, b: ModeTrack | None) -> ModeTrack | None:
    if a is None or b is None:
        return a if b is None else b
    t, value = np.concatenate([a.t, b.t]), np.concatenate([a.value, b.value])
    if t.size > 2 * MAX_MODE_POINTS:
        idx = decimate_indices(value, MAX_MODE_POINTS, keep=run_starts(value), simplify_flat=True)
        t, value = t[idx], value[idx]
    border_change = run_starts(np.array([a.value[-1], b.value[0]])).size - 1  # NaN equals NaN there
    intervals: list = []
    if a.intervals and b.intervals:  # both ran in few intervals: still few, or too many now
        intervals = _intervals(a.intervals, b.intervals)
        intervals = intervals if len(intervals) <= MAX_MODE_INTERVALS else []
    return replace(a, t=t, value=value, intervals=intervals, n_changes=a.n_changes + b.n_changes + border_change)


def _intervals(a: list, b: list) -> list:
    """Intervals (start, end[, value]) end to end; ``a``'s last joined with ``b``'s first when it
    runs to where that begins, with the same value."""
    if a and b and abs(a[-1][1] - b[0][0]) <= _TOUCH_S and a[-1][2:] == b[0][2:]:
        return [*a[:-1], (a[-1][0], b[0][1], *b[0][2:]), *b[1:]]
    return [*a, *b]
