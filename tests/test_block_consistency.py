"""Block mode judges the filter's consistency (a group blind, or far from its chi-square law) on
the log's NIS, the blocks' own updates end to end (`logscan.verdict.nis_consistency.summed`), not
each block's on its own with block 1's figures (docs/algorithms.md 8.1b)."""

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
