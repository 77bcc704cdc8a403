"""Block mode's observability verdict (`logscan.pipeline.block_merge.windows_folded`,
`logscan.verdict.observability_folded`): the windows no later block can replace are reduced to what
the verdict's readers read (blind runs, each truth event's largest evidence), so the merged verdict
is exactly the unreduced merge's (summary, blind periods, report shading, event verdicts) while what
it keeps stops growing with the number of blocks."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import SAMPLES

from logscan.pipeline import block_fold
from logscan.pipeline.block_merge import windows_folded, windows_once
from logscan.pipeline.blocks import analyze_blocked
from logscan.report.observability_figures import observability_rows
from logscan.results import FaultEvent
from logscan.verdict.evaluation import evaluate_analysis
from logscan.verdict.observability import Direction, Observability, snr_needed

BIAS = SAMPLES / "quad_imu_bias.mcap"  # 60 s, an accelerometer bias from 30 to 40 s (blind periods too)
MOTOR = SAMPLES / "quad_motor_offset.mcap"  # 60 s, an actuator offset on motor1
DIRECTIONS = [Direction("motor1", "actuator"), Direction("accel.x", "sensor", "accel/x")]


def _unreduced(monkeypatch, path, block_s):
    """The block-mode analysis with the windows merged unreduced (the fold before this change)."""
    with monkeypatch.context() as patch:
        patch.setattr(block_fold, "windows_folded", lambda merged, part, events: windows_once(merged, part))
        return analyze_blocked(path, block_s=block_s, free_series=True)


def _verdicts(verdict, events) -> list:
    """Each event's verdict at its own magnitude and at a few others (the maxima serve any)."""
    out = []
    for event in events:
        for scale in (1.0, 0.3, 0.05, 3.0):
            magnitude = None if event.magnitude is None else event.magnitude * scale
            out.append(verdict.event_verdict(replace(event, magnitude=magnitude)))
    return out


@pytest.mark.parametrize("path", [BIAS, MOTOR])
def test_a_block_mode_verdict_is_the_unreduced_merge(monkeypatch, path):
    """Blocks of 10 s (the fault across the border at 40 s): the summary's verdict, the blind
    periods, the report's shading and every truth event's verdict are the unreduced merge's, while
    the verdict keeps the rows of the last window and stride only."""
    ours = analyze_blocked(path, block_s=10.0, free_series=True)
    theirs = _unreduced(monkeypatch, path, 10.0)
    reduced, full = ours.observability, theirs.observability
    assert reduced.t_start.size <= 6 < 200 < full.t_start.size  # it did reduce
    assert reduced.to_dict() == full.to_dict() and reduced.blind_periods() == full.blind_periods()
    assert observability_rows(reduced) == observability_rows(full)
    assert ours.events == theirs.events and ours.events
    assert _verdicts(reduced, ours.events) == _verdicts(full, theirs.events)
    assert ours.summary() == theirs.summary()
    scored, scored_full = evaluate_analysis(ours), evaluate_analysis(theirs)
    assert {k: s.to_dict() for k, s in scored.scores.items()} == {k: s.to_dict() for k, s in scored_full.scores.items()}
    if path == BIAS:
        assert reduced.blind_periods()  # there is something to join across the borders


def _block_parts(evidence: np.ndarray, rows_per_block: int, t_end: float, lead_rows: int = 4) -> list:
    """The verdicts block mode folds in: block k's rows from a window (``lead_rows``) before its
    first row, those the block's end cuts short unjudged (NaN), as `observability_of` leaves them."""
    t = 0.25 * np.arange(evidence.shape[0])
    parts = []
    for first in range(0, evidence.shape[0], rows_per_block):
        stop = min(first + rows_per_block, evidence.shape[0])
        lead = max(first - lead_rows, 0)
        block_evidence = evidence[lead:stop].copy()
        if stop < evidence.shape[0]:
            block_evidence[-lead_rows:] = np.nan
        end = t_end if stop == evidence.shape[0] else float(t[stop - 1]) + 0.2
        snr = snr_needed()
        parts.append(Observability(t[lead:stop].copy(), block_evidence, DIRECTIONS, snr_min=snr, t_end=end))
    return parts


def _evidence(rows: int, seed: int) -> np.ndarray:
    """Evidence around the thresholds (blind and seen runs of every length), NaN where not judged."""
    rng = np.random.default_rng(seed)
    threshold = snr_needed() ** 2
    evidence = threshold * rng.lognormal(0.0, 1.5, size=(rows, 2)) * np.array([100.0, 1.0])  # 10 % offsets
    evidence[rng.random(rows) < 0.1] = np.nan
    return evidence


@pytest.mark.parametrize("seed", range(4))
def test_folded_windows_give_what_the_unreduced_merge_gives(seed):
    """Random evidence in blocks of 40 rows (10 s): blind periods and the verdicts of events of every
    span (across borders, within one, open-ended, at the log's end) equal the unreduced merge's."""
    evidence = _evidence(1000, seed)
    t_end = 0.25 * 999 + 0.2
    events = [
        FaultEvent(a, None if b is None else b, kind, target, magnitude)
        for a, b in [(9.0, 11.0), (9.9, 10.1), (5.0, 55.0), (20.0, 20.5), (240.0, None), (100.0, 100.0), (249.0, 300.0)]
        for kind, target, magnitude in [("actuator-offset", "motor1", -0.1), ("bias", "accel.x", 1.0)]
    ] + [FaultEvent(30.0, 40.0, "lost-actuator", "motor1", None)]
    full = folded = None
    for part in _block_parts(evidence, 40, t_end):
        full = windows_once(full, part)
        folded = windows_folded(folded, part, events)
    assert folded.first_start == 0.0 and folded.t_start.size < 10
    assert folded.to_dict() == full.to_dict() and folded.blind_periods()
    assert folded.t_first == full.t_first and folded.t_end == full.t_end
    assert _verdicts(folded, events) == _verdicts(full, events)
    assert {True, False} <= set(_verdicts(full, events))


def test_the_kept_verdict_stops_growing_with_the_number_of_blocks():
    """The rows kept in full stay those of the last window (the unreduced merge kept 1.76 MiB per
    log-hour of a quadcopter's 16 directions); what grows is only the blind runs, here none."""
    evidence = np.full((2000, 2), 1e6)  # always seen: no blind run
    state = None
    kept = []
    for part in _block_parts(evidence, 40, 0.25 * 1999 + 0.2):
        state = windows_folded(state, part, [])
        kept.append((state.t_start.size, state.evidence.shape[0], state.nbytes()))
    assert kept[5] == kept[-1] and kept[-1][0] <= 6


def test_a_block_that_reaches_back_into_reduced_windows_is_refused():
    evidence = np.full((200, 2), 1e6)
    parts = _block_parts(evidence, 40, 0.25 * 199 + 0.2)
    state = windows_folded(windows_folded(None, parts[0], []), parts[1], [])
    with pytest.raises(RuntimeError, match="reach back"):
        windows_folded(state, parts[0], [])
