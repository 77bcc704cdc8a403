"""Block mode judges the filter's consistency (a group blind, or far from its chi-square law) on
the log's NIS, the blocks' own updates end to end (`logscan.verdict.nis_consistency.summed`), and
says alignment's gate and gap warnings of the log from the blocks' own steps
(`logscan.pipeline.block_alignment`), not each block's with block 1's figures (docs/algorithms.md 8.1b)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.verdict.nis_consistency import GroupNis, NisConsistency, summed

CALIBRATE = "logscan train LOG --calibrate -o tables.json"


def _consistency(rng, n: int) -> NisConsistency:
    quiet = 0.01 * rng.chisquare(1, n)  # blind
    loud = 50.0 * rng.chisquare(3, n)  # far above its chi-square median
    mixed = np.where(rng.random(n) < 0.01, 10.0, 0.001) * rng.chisquare(2, n)  # blind most of the time
    judged = rng.random(n) < 0.7
    return NisConsistency(
        [
            GroupNis("gnss", 1, quiet, judged),
            GroupNis("baro", 3, loud, judged.copy()),
            GroupNis("attitude", 2, mixed, judged.copy()),
        ]
    )


def _cut(whole: NisConsistency, borders: list[int]) -> list[NisConsistency]:
    edges = [0, *borders, whole.groups[0].nis.size]
    return [
        NisConsistency([GroupNis(g.name, g.size, g.nis[a:b], g.judged[a:b]) for g in whole.groups])
        for a, b in zip(edges, edges[1:], strict=False)
    ]


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 1000), cuts=st.lists(st.integers(1, 1999), max_size=6, unique=True))
def test_the_blocks_summed_say_what_the_log_says(seed, cuts):
    whole = _consistency(np.random.default_rng(seed), 2000)
    parts = _cut(whole, sorted(cuts))
    merged = summed([None, *parts])  # a block without a filter adds nothing
    assert merged is not None
    assert merged.lines({"baro"}, CALIBRATE) == whole.lines({"baro"}, CALIBRATE)
    lines = whole.lines(set(), CALIBRATE)
    assert [line.split(":")[0] for line in lines] == [
        "group 'gnss' is blind",
        "group 'baro'",
        "group 'attitude' is blind most of the time",
    ]
    assert "its checks alarmed" in whole.lines({"baro"}, CALIBRATE)[1]


def test_a_short_block_judged_alone_would_say_otherwise():
    """What the merge is for: a block's few updates give other figures and even another kind of line."""
    whole = _consistency(np.random.default_rng(4), 2000)
    first = _cut(whole, [100])[0]
    assert first.lines(set(), CALIBRATE) != whole.lines(set(), CALIBRATE)
    assert summed([]) is None


@pytest.mark.parametrize(
    ("name", "block_s"),
    [
        pytest.param(name, block_s, marks=pytest.mark.testdata(name))
        for name, block_s in (
            ("px4-ulog/sample_px4_events.ulg", 10.0),
            ("ros-robots/robot_localization_test1_husky.bag", 3.0),
        )
    ],
)
def test_a_real_log_in_short_blocks_warns_of_its_consistency_as_at_once(name, block_s):
    """The real events ULog in 10-s blocks said four lines for three groups (the attitude group both
    "blind" and "blind most of the time", with block 1's figures); the Husky drive in 3-s blocks
    four for two. Judged on the log's NIS: the at-once lines, group for group, the same kind and
    count of updates (a block's filter restarts from its lead-in, so a figure may differ in its
    last digit)."""
    from conftest import need_testdata

    from logscan.pipeline.blocks import analyze_blocked
    from logscan.pipeline.run import analyze_log

    path = need_testdata(name)
    whole, blocks = analyze_log(path), analyze_blocked(path, block_s=block_s)
    at_once = [w for w in whole.warnings if " NIS " in w]
    in_blocks = [w for w in blocks.warnings if " NIS " in w]
    assert len(at_once) >= 2 and len(in_blocks) == len(at_once)
    for a, b in zip(at_once, in_blocks, strict=True):
        assert a.split(":")[0] == b.split(":")[0]  # the group and the kind of line
        assert a.split(" updates")[0].rsplit(" over ", 1)[1] == b.split(" updates")[0].rsplit(" over ", 1)[1]
        assert "said in" not in b


def _run(t, gaps, closed=None, warnings=()):
    from types import SimpleNamespace

    from logscan.align.notes import GapReport

    groups = {"gnss": SimpleNamespace(gate_closed=closed)}
    reports = [
        GapReport("/gps/lat", "0.2", np.array([a for a, _, _ in gaps]), np.array([b for _, b, _ in gaps]), gaps[-1][2])
    ]
    return SimpleNamespace(t=t, n_steps=t.size, dt=0.1, groups=groups, gap_reports=reports, warnings=list(warnings))


def test_a_gap_across_a_border_is_the_next_blocks_and_the_log_says_its_gaps_and_gate_once():
    """At once, /gps/lat has gaps 1-2 s, 4.9-5.6 s and 8-10 s (running to the log's end) and its
    gate closed for 3 of 100 steps. Block 1 (0-4.9 s) sees the second gap run to its end without a
    sample; block 2 (led in from 0 s, its own steps from 5 s) sees it whole, and the first again."""
    from types import SimpleNamespace

    from logscan.align.notes import GapReport, gap_lines, gate_line
    from logscan.pipeline.block_alignment import alignment_figures, alignment_lines

    specs = {"gnss": SimpleNamespace(gate_channel="/gps/fix", gate_min=3)}
    t = np.arange(100) * 0.1
    closed = np.zeros(100, bool)
    closed[[10, 60, 61]] = True
    said = gate_line("gnss", "/gps/fix", 3, 0.1, 5.0)
    first = alignment_figures(_run(t[:50], [(1.0, 2.0, False), (4.9, 4.9, True)], closed[:50], [said]), specs, 0)
    second = alignment_figures(_run(t, [(1.0, 2.0, False), (4.9, 5.6, False), (8.0, 9.9, True)], closed), specs, 50)
    assert said in first.said and gap_lines([]) == []
    at_once = GapReport("/gps/lat", "0.2", np.array([1.0, 4.9, 8.0]), np.array([2.0, 5.6, 9.9]))
    expected = [gate_line("gnss", "/gps/fix", 3, 3 * 0.1, 100 * 0.1), *gap_lines([at_once])]
    assert alignment_lines([first, second], specs) == expected
    assert "3 gaps longer than stale_s=0.2 s (longest 1.900 s from t=8.000 s)" in expected[1]
    assert alignment_lines([], specs) == []


@pytest.mark.parametrize(
    "name",
    [
        pytest.param(name, marks=pytest.mark.testdata(name))
        for name in ("px4-ulog/sample_px4_events.ulg", "px4-ulog/sample_logging_tagged_and_default_params.ulg")
    ],
)
def test_a_real_ulog_in_short_blocks_gives_the_warnings_of_the_log_at_once(name):
    """The real ULogs in 10-s blocks gave their GNSS gate closed "for 8.3 s of 9.9 s" and gaps with
    block 1's figures ("said in 2 of 4 blocks"), and the NIS lines of each block. Said of the log,
    every warning is the one at once, word for word; block mode adds only its own lines."""
    from conftest import need_testdata

    from logscan.pipeline.blocks import analyze_blocked
    from logscan.pipeline.run import analyze_log

    path = need_testdata(name)
    whole, blocks = analyze_log(path), analyze_blocked(path, block_s=10.0)
    own = [w for w in blocks.warnings if w.startswith(("analysed in ", "--block-s "))]
    assert len(own) == 2
    assert [w for w in blocks.warnings if w not in own] == whole.warnings
    assert any(" gap" in w for w in whole.warnings) and any("below 3 for" in w for w in whole.warnings)
