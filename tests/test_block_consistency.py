"""Block mode judges the filter's consistency (a group blind, or far from its chi-square law) on
the log's NIS, the blocks' own updates end to end (`logscan.verdict.nis_consistency.summed`), and
says alignment's gate and gap warnings of the log from the blocks' own steps
(`logscan.pipeline.block_alignment`), not each block's with block 1's figures (docs/algorithms.md 8.1b)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.pipeline import kept_nis
from logscan.readers import spill
from logscan.verdict import nis_consistency
from logscan.verdict.nis_consistency import GroupNis, NisConsistency, pieces_by_group, summed

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


@settings(max_examples=15, deadline=None)
@given(
    seed=st.integers(0, 1000),
    cuts=st.lists(st.integers(1, 99_999), max_size=8, unique=True),  # a part of 11,112 or more: on disk
    on_disk=st.booleans(),
    pending=st.sampled_from([1, 50_000, 1 << 30]),
)
def test_the_fold_keeps_the_blocks_nis_in_order_on_disk_or_not(seed, cuts, on_disk, pending):
    # a long log's fold sums its earlier blocks' NIS a few MB at a time, on disk with its held read
    whole = _consistency(np.random.default_rng(seed), 100_000)
    kept = kept_nis.KeptNis()
    kept.PENDING_BYTES = pending
    for part in [None, *_cut(whole, sorted(cuts))]:
        kept.add(part, on_disk)
    merged = kept.summed()
    assert merged is not None
    pieces = pieces_by_group([merged])
    assert list(pieces) == merged.group_names() == [g.name for g in whole.groups]
    for want in whole.groups:
        got = pieces[want.name]
        assert {g.size for g in got} == {want.size}
        np.testing.assert_array_equal(np.concatenate([g.nis for g in got]), want.nis)
        np.testing.assert_array_equal(np.concatenate([g.judged for g in got]), want.judged)
    assert merged.lines({"baro"}, CALIBRATE) == whole.lines({"baro"}, CALIBRATE)
    if on_disk and pending == 1 and spill._CAN and spill._room_on_disk(0):
        large = [g.nis for part in kept.kept for g in part.groups if g.nis.nbytes >= spill.MIN_BYTES]
        assert large and all(spill.on_disk(nis) for nis in large)


def test_the_merge_reads_the_pieces_on_disk_without_joining_them(monkeypatch):
    """A long log's NIS grows with it (180 MB at 24 hours of a 100 Hz quadcopter): the fold keeps it
    on disk by default, each joined part in one file, and the merge's warnings read it there a
    chunk at a time, told to `spill` so that its pages go back: the merge holds no group whole."""
    whole = _consistency(np.random.default_rng(7), 60_000)
    kept = kept_nis.KeptNis()
    kept.PENDING_BYTES = 700_000  # two parts (405 KB each) a file
    for part in _cut(whole, [15_000, 30_000, 45_000]):
        kept.add(part)
    assert len(kept.kept) == 2 and len(kept.pending) == 0
    if spill._CAN and spill._room_on_disk(0):
        for part in kept.kept:
            arrays = [a for g in part.groups for a in (g.nis, g.judged)]
            assert all(spill.on_disk(a) for a in arrays)
            assert len({id(spill.file_of(a)) for a in arrays}) == 1
    merged = kept.summed()
    assert merged.group_names() == ["gnss", "baro", "attitude"]
    assert len(merged.groups) == 6  # two pieces a group, none joined
    expected = whole.lines({"baro"}, CALIBRATE)
    read = []
    real = nis_consistency.read_in_chunks
    monkeypatch.setattr(nis_consistency, "read_in_chunks", lambda a: read.append(a.size) or real(a, 4096))
    monkeypatch.setattr(nis_consistency, "SELECT_AT_ONCE", 500)  # the median's last step: at most 500 values
    partitioned = []
    real_partition = np.partition
    monkeypatch.setattr(np, "partition", lambda a, k: partitioned.append(a.size) or real_partition(a, k))
    assert merged.lines({"baro"}, CALIBRATE) == expected
    assert read and max(read) == 30_000  # a piece at a time, 4096 values a chunk
    assert partitioned and max(partitioned) <= 500


@settings(max_examples=60, deadline=None)
@given(
    pieces=st.lists(
        st.lists(st.floats(-1e6, 1e6, allow_nan=False) | st.sampled_from([0.0, 1.0, 2.5]), min_size=1, max_size=60),
        min_size=2,
        max_size=5,
    ),
    at_once=st.sampled_from([1, 3, 1 << 20]),
)
def test_the_median_of_pieces_is_numpys_of_them_joined(pieces, at_once):
    # exact: radix selection on the values' sort keys, whatever the candidates held at once
    arrays = [np.asarray(p, dtype=np.float64) for p in pieces]
    joined = np.concatenate(arrays)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(nis_consistency, "SELECT_AT_ONCE", at_once)
        assert nis_consistency._median(arrays) == np.median(joined)
        for k in {0, joined.size // 2, joined.size - 1}:
            assert nis_consistency.order_statistic(arrays, k) == np.partition(joined, k)[k]


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


_NS = 1_000_000_000


def _block(samples_s, grid_s, first_s=None, delay_s=0.0, closed=None, said=()):
    """The alignment figures of a run on the grid ``grid_s`` (a block's: from its lead-in), its own
    steps from ``first_s``, of one channel sampled at ``samples_s`` held ``delay_s`` after the steps
    (stale after 1 s), by the aligner's own gap report."""
    from types import SimpleNamespace

    from logscan.align.aligner import _Aligner
    from logscan.pipeline.block_alignment import alignment_figures

    samples = np.round(np.asarray(samples_s) * _NS).astype(np.int64)
    aligner = _Aligner(SimpleNamespace(channels={}), None)
    aligner.clean = lambda name: SimpleNamespace(t=samples)
    grid = np.round(np.asarray(grid_s) * _NS).astype(np.int64)
    aligner.report_gaps("/gps/x", grid + round(delay_s * _NS), 1.0)
    t = grid / _NS
    run = SimpleNamespace(gap_reports=aligner.gap_reports, t=t, n_steps=t.size, dt=0.1, warnings=list(said))
    run.groups = {"gnss": SimpleNamespace(gate_closed=closed)}
    first = 0 if first_s is None else int(np.searchsorted(t, first_s - 1e-9))
    return aligner, alignment_figures(run, {"gnss": _GATE}, first)


_GATE = __import__("types").SimpleNamespace(gate_channel="/gps/fix", gate_min=3)


@pytest.mark.parametrize("delay_s", [0.0, 0.5])
@pytest.mark.parametrize("resumes_s", [9.95, 10.2, 12.0])
def test_a_gap_across_a_border_is_counted_once_as_at_once(resumes_s, delay_s):
    """A 10 Hz grid in two blocks, 0-9.9 s and 10-19.9 s (led in from 5 s), a channel silent from
    8 s until ``resumes_s``: at once one gap; in blocks the same one, whether its sample comes
    between block 1's last step and block 2's first (9.95 s), or inside block 1's span of a
    grid the delay shifts (10.2 s, 0.5 s late), or well into block 2."""
    from logscan.align.notes import gap_lines
    from logscan.pipeline.block_alignment import alignment_lines

    samples = np.r_[np.arange(0, 80) * 0.1, resumes_s + np.arange(0, 120) * 0.1]
    steps = np.arange(200) * 0.1
    whole, _ = _block(samples, steps, delay_s=delay_s)
    _, first = _block(samples, steps[:100], delay_s=delay_s)
    _, second = _block(samples, steps[50:], first_s=10.0, delay_s=delay_s)
    expected = gap_lines(whole.gap_reports)
    assert len(expected) == 1 and ": 1 gap longer than" in expected[0]
    assert alignment_lines([replace(first, number=1), replace(second, number=2)], {}) == expected


def test_the_log_says_its_gate_closed_over_the_blocks_own_steps():
    from logscan.align.notes import gate_line
    from logscan.pipeline.block_alignment import alignment_lines

    samples = np.arange(200) * 0.1
    closed = np.zeros(200, bool)
    closed[[10, 60, 61]] = True  # steps 60 and 61 in block 1's span, and in block 2's lead-in
    steps = np.arange(200) * 0.1
    said = gate_line("gnss", "/gps/fix", 3, 0.1, 10.0)
    _, first = _block(samples, steps[:100], closed=closed[:100], said=[said])
    _, second = _block(samples, steps[50:], first_s=10.0, closed=closed[50:])
    assert said in first.said
    assert alignment_lines([first, replace(second, number=1)], {"gnss": _GATE}) == [
        gate_line("gnss", "/gps/fix", 3, 0.3, 20.0)
    ]
    assert alignment_lines([], {}) == []


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


def test_the_logs_alignment_lines_stand_after_the_first_blocks_run_warnings():
    """As at once: after the profile's notes, the reader's and alignment's own warnings, before the
    filter's; where the first block's run warned of nothing, after the notes and the reader's."""
    from types import SimpleNamespace

    from logscan.pipeline.block_fold import _after_alignment

    def block(run_warnings, warnings):
        prepared = SimpleNamespace(
            run=SimpleNamespace(warnings=run_warnings),
            loaded=SimpleNamespace(notes=["note"]),
            log=SimpleNamespace(source=SimpleNamespace(warnings=["read"])),
        )
        return SimpleNamespace(prepared=prepared, warnings=warnings)

    assert _after_alignment(block(["aligned", "gaps"], ["nis", "note", "read", "aligned", "gaps", "filter"])) == 5
    assert _after_alignment(block([], ["nis", "note", "read", "filter diverged"])) == 3
    assert _after_alignment(block([], ["filter diverged"])) == 0


@pytest.mark.parametrize(("resumes_s", "longest"), [(25.0, "17.100"), (12.0, "2.000")])
def test_a_gap_running_into_a_block_not_analysed_is_counted_once(resumes_s, longest):
    """Block 2 of 3 (10-20 s) refused (the log holds too little there). A channel silent from 7.9 s
    until 25 s: block 3, led in from 15 s, has the gap whole from its last sample; until 12 s: no
    block has its end, so block 1's stretch counts, to its border."""
    from logscan.pipeline.block_alignment import alignment_lines

    samples = np.r_[np.arange(0, 80) * 0.1, resumes_s + np.arange(0, 200) * 0.1]
    steps = np.arange(300) * 0.1
    _, first = _block(samples, steps[:100])
    _, third = _block(samples, steps[150:], first_s=20.0)
    lines = alignment_lines([replace(first, number=1), replace(third, number=3)], {})
    assert len(lines) == 1 and ": 1 gap longer than" in lines[0]
    assert f"(longest {longest} s from t=7.900 s)" in lines[0]
