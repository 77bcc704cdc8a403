"""Block mode (`logscan.pipeline.blocks`): a log analysed as consecutive windows, each led in for
its detectors, merged into one analysis agrees with the analysis at once also across the block
borders, an alarm or incident across a border is one, and a log shorter than a block takes the
path it always took."""

from __future__ import annotations

import json

import hypothesis.extra.numpy as hnp
import hypothesis.strategies as st
import numpy as np
import pytest
from conftest import SAMPLES, need_testdata
from hypothesis import given, settings

from logscan.alarms import AlarmInterval
from logscan.pipeline import analyze_log
from logscan.pipeline.block_merge import merged_incidents, said_once
from logscan.pipeline.block_reduce import envelope, envelope_times
from logscan.pipeline.blocks import analyze_blocked, block_windows
from logscan.results import DetectorResult, Incident

BIAS = SAMPLES / "quad_imu_bias.mcap"  # 60 s at 100 Hz, an accelerometer bias from 30 to 40 s


def test_block_windows_cover_the_span_without_a_step_twice():
    windows = block_windows(100.0, 30.0, 0.01)
    ns = 1e-9  # each ends a nanosecond before the next begins
    assert windows == [(None, 25.0 - ns), (25.0, 50.0 - ns), (50.0, 75.0 - ns), (75.0, None)]  # none over 30 s
    assert block_windows(100.0, 30.0, 0.01, start_s=10.0, end_s=70.0) == [(10.0, 40.0 - ns), (40.0, 70.0)]
    assert block_windows(40.0, 30.0, 0.01) == [(None, 20.0 - ns), (20.0, None)]
    assert block_windows(30.2, 30.0, 0.01) == [(None, None)]  # within the slack: one
    # a log of 24 one-hour pieces, each a step apart: 48 blocks a step longer than half an hour
    day = block_windows(86400.24, 1800.0, 0.01)
    assert len(day) == 48 and day[1][0] == pytest.approx(1800.01) and day[-1][1] is None


def test_envelope_keeps_each_buckets_extremes_in_order_and_gaps():
    values = np.array([1.0, 5.0, 2.0, 0.0, np.nan, np.nan, 3.0])
    assert envelope(values, 2).tolist()[:4] == [1.0, 5.0, 2.0, 0.0]
    assert np.isnan(envelope(values, 2)[4:6]).all()  # a bucket of NaN only stays a gap
    assert envelope(values, 2)[6:].tolist() == [3.0, 3.0]
    assert envelope(np.array([False, True, False, False]), 2).tolist() == [True, True, False, False]
    assert envelope_times(np.arange(5.0), 2).tolist() == [0.0, 1.0, 2.0, 3.0, 4.0, 4.0]
    assert envelope(values, 1) is values


def _envelope_by_numpy(values: np.ndarray, width: int) -> np.ndarray:
    """The envelope as numpy's argmin / argmax define it (NaN as +-inf, the first of ties)."""
    n = values.shape[0]
    buckets = -(-n // width)
    padded = np.full((buckets * width, *values.shape[1:]), np.nan)
    padded[:n] = values
    grouped = padded.reshape(buckets, width, *values.shape[1:])
    missing = np.isnan(grouped)
    low_at = np.argmin(np.where(missing, np.inf, grouped), axis=1)[:, None]
    high_at = np.argmax(np.where(missing, -np.inf, grouped), axis=1)[:, None]
    low = np.take_along_axis(grouped, low_at, axis=1)[:, 0]
    high = np.take_along_axis(grouped, high_at, axis=1)[:, 0]
    in_order = (low_at <= high_at)[:, 0]
    pairs = np.stack([np.where(in_order, low, high), np.where(in_order, high, low)], axis=1)
    return pairs.reshape(2 * buckets, *values.shape[1:]).astype(values.dtype, copy=False)


@settings(max_examples=200, deadline=None)
@given(
    values=hnp.arrays(
        st.sampled_from([np.float32, np.float64]),
        st.tuples(st.integers(1, 40), st.integers(1, 3)),
        elements=st.sampled_from([0.0, -0.0, 1.0, -2.5, 3.0, np.nan, np.inf, -np.inf]),
    ),
    width=st.integers(2, 9),
    flat=st.booleans(),
)
def test_the_envelope_kernel_is_the_numpy_definition(values, width, flat):
    """Ties, NaN, infinities, a partial last bucket, (N,) and (N, k), float32 and float64: the
    compiled envelope gives numpy's argmin / argmax envelope bit for bit."""
    values = values[:, 0] if flat else values
    assert envelope(values, width).tobytes() == _envelope_by_numpy(values, width).tobytes()
    assert envelope(values, width).dtype == values.dtype


def _alarm(signal: str, start: float, end: float) -> AlarmInterval:
    return AlarmInterval(start, end, start, start, 2.0, 1.0, 2.0, "upper", 1, signal=signal, detector="nis")


def test_incidents_either_side_of_a_border_are_one():
    before, after = _alarm("nis.accel", 10.0, 19.99), _alarm("nis.accel", 20.0, 25.0)
    merged_alarm = _alarm("nis.accel", 10.0, 25.0)
    incidents = [
        Incident(10.0, 19.99, "accel", "", [before], "accelerometer inconsistent", "nis.accel", before),
        Incident(20.0, 25.0, "accel", "", [after], "accelerometer inconsistent", "nis.accel", after),
        Incident(40.0, 41.0, "gyro", "", [], "gyroscope inconsistent", "nis.gyro", None),
    ]
    result = DetectorResult("nis", alarms=[merged_alarm])
    out = merged_incidents(incidents, [result], gap_s=1.0)
    assert [(i.start, i.end) for i in out] == [(10.0, 25.0), (40.0, 41.0)]
    assert out[0].alarms == [merged_alarm] and out[0].quoted is merged_alarm
    assert "10.00-25.00 s" in out[0].headline


def test_an_incident_across_a_border_quotes_the_merged_alarms_peak():
    """The part before the border peaked at 2x, the part after at 4x: the merged incident quotes
    the merged alarm's peak (4x), its other words kept."""
    from dataclasses import replace

    before = _alarm("nis.accel", 10.0, 19.99)
    merged_alarm = replace(_alarm("nis.accel", 10.0, 25.0), peak_value=4.0, peak_ratio=4.0)
    detail = "nis.accel, peak 2x; 3 impossible samples rejected"
    incident = Incident(10.0, 19.99, "accel", "", [before], "accelerometer inconsistent", detail, before)
    (out,) = merged_incidents([incident], [DetectorResult("nis", alarms=[merged_alarm])], gap_s=1.0)
    assert out.detail == "nis.accel, peak 4x; 3 impossible samples rejected"
    assert out.headline.endswith("10.00-25.00 s (nis.accel, peak 4x; 3 impossible samples rejected)")


def test_a_line_each_block_says_with_its_own_figures_is_said_once():
    lines = [
        ["note", "group 'gps' is blind: mean NIS 0.17 over 150 updates"],
        ["note", "group 'gps' is blind: mean NIS 0.2 over 149 updates"],
        ["note"],
    ]
    assert said_once(lines) == [
        "note",
        "group 'gps' is blind: mean NIS 0.17 over 150 updates (said in 2 of 3 blocks; these figures are block 1's)",
    ]


@pytest.fixture(scope="module")
def both():
    whole = analyze_log(BIAS, free_series=True)
    blocks = analyze_blocked(BIAS, block_s=20.0, free_series=True)  # borders at 20 and 40 s
    return whole, blocks


def _alarms(analysis) -> list:
    return sorted((a.detector, a.signal, a.start, a.end, a.first_exceed) for a in analysis.alarms)


def test_blocks_agree_with_the_whole_log_across_the_borders(both):
    """Each block after the first is analysed from DETECTOR_LEAD_S before it (here: from the log's
    start), its alarms seen from its own first step: every alarm, judged share, count and the
    observability verdict are the analysis at once's, also at the borders (the accelerometer's
    fault ends across 40 s, where e_x and the pitch CUSUM once restarted)."""
    whole, blocks = both
    assert blocks.exit_code() == whole.exit_code()
    assert len(blocks.incidents) == len(whole.incidents) == 1
    assert blocks.incidents[0].headline == whole.incidents[0].headline
    assert float(blocks.run.t[0]) == float(whole.run.t[0]) and float(blocks.run.t[-1]) == float(whole.run.t[-1])
    assert _alarms(blocks) == _alarms(whole)
    for ours, theirs in zip(blocks.results, whole.results):
        assert ours.judged_fraction == pytest.approx(theirs.judged_fraction, abs=1e-3), ours.detector
    summary, whole_summary = blocks.prepared.filter_summary(), whole.prepared.filter_summary()
    assert {k: summary[k] for k in ("steps", "updates", "seeded")} == {
        k: whole_summary[k] for k in ("steps", "updates", "seeded")
    }
    # the verdict's windows as the readers read them (its final windows are kept reduced to that)
    assert blocks.observability.to_dict() == whole.observability.to_dict()
    assert [blocks.observability.event_verdict(e) for e in blocks.events] == [
        whole.observability.event_verdict(e) for e in whole.events
    ]
    kept = blocks.observability.t_start  # the last window and stride in full: its evidence the whole's
    np.testing.assert_allclose(blocks.observability.evidence, whole.observability.evidence[-kept.size :], rtol=1e-9)
    assert blocks.warnings[-2].startswith("analysed in 3 blocks of 20 s (--block-s), each after the first from")
    assert blocks.warnings[-1].startswith("--block-s 20: each block is analysed with the 62 s before it")


def test_the_summary_counts_the_logs_samples_not_the_envelopes_points(both, monkeypatch):
    """Series kept as envelopes (buckets of 6 steps here) still count, in the JSON summary, every
    sample and finite sample of the log, as the analysis at once does."""
    from logscan.pipeline import block_reduce

    whole, _ = both
    monkeypatch.setattr(block_reduce, "MERGED_POINTS", 2000)
    blocks = analyze_blocked(BIAS, block_s=20.0, free_series=True)
    for ours, theirs in zip(blocks.results, whole.results):
        assert ours.detector == theirs.detector
        for name, values in ours.series.items():
            assert len(values) < len(theirs.series[name])  # an envelope, not the series
        counts = {k: (v["n"], v["finite"]) for k, v in ours.to_dict()["series"].items()}
        assert counts == {k: (v["n"], v["finite"]) for k, v in theirs.to_dict()["series"].items()}, ours.detector


def test_a_lead_shorter_than_the_log_before_a_block_keeps_the_alarms(both, monkeypatch):
    """A lead of 5 s (blocks from 15 and 35 s): the detectors' windows (1 s) and sums run in, so
    the alarms at the borders are the analysis at once's; without one (a step) they are not."""
    from logscan.pipeline import blocks

    whole, _ = both
    monkeypatch.setattr(blocks, "DETECTOR_LEAD_S", 5.0)
    assert _alarms(analyze_blocked(BIAS, block_s=20.0, free_series=True)) == _alarms(whole)
    monkeypatch.setattr(blocks, "DETECTOR_LEAD_S", 0.01)
    assert _alarms(analyze_blocked(BIAS, block_s=20.0, free_series=True)) != _alarms(whole)


def test_an_alarm_across_a_border_is_one(both):
    _, blocks = both
    accel = [a for a in blocks.alarms if a.signal == "nis.accel"]
    assert [(a.start, round(a.end, 2)) for a in accel] == [(30.0, 41.27)]  # across the border at 40 s
    for result in blocks.results:  # no two alarms of one statistic within the merge gap
        for signal in {a.signal for a in result.alarms}:
            spans = sorted((a.start, a.end) for a in result.alarms if a.signal == signal)
            assert all(b[0] - a[1] > 1.0 for a, b in zip(spans, spans[1:]))


def test_a_log_shorter_than_a_block_takes_the_path_it_took(both):
    whole, _ = both
    for block_s in (None, 120.0):
        same = analyze_blocked(BIAS, block_s=block_s, free_series=True)
        assert json.dumps(same.summary(), default=str) == json.dumps(whole.summary(), default=str)
        assert not any("--block-s" in w for w in same.warnings)


def test_blocks_of_a_log_read_whole_are_said_to_be_analysed_at_once():
    analysis = analyze_blocked(SAMPLES / "quad_healthy.csv", block_s=10.0, free_series=True)
    assert any(w.startswith("--block-s: a csv") and "analysed at once" in w for w in analysis.warnings)


def test_a_log_read_whole_past_the_memory_budget_says_so_unless_at_once_was_asked(monkeypatch):
    """A CSV log with its own profile (read whole, no built-in profile's read to take blocks of)
    whose grid holds more steps than the budget allows at once warns that its memory grew with its
    length, and why it was not read in blocks; within the budget, or with --block-s 0 (at once,
    asked for), it does not."""
    from logscan.pipeline import blocks

    csv = SAMPLES / "quad_healthy.csv"  # 60 s at 100 Hz: 6,001 steps
    quiet = analyze_blocked(csv, free_series=True)
    assert not any(w.startswith("memory:") for w in quiet.warnings)
    monkeypatch.setattr(blocks, "AUTO_STEPS", 1000)
    warned = analyze_blocked(csv, free_series=True)
    lines = [w for w in warned.warnings if w.startswith("memory:")]
    steps = warned.run.n_steps
    assert len(lines) == 1 and f"{steps:,} grid steps were analysed at once, more than the 1,000" in lines[0]
    assert "a csv log analysed with --profile or its embedded one is read whole" in lines[0]
    assert "--start/--end" in lines[0]
    assert (warned.verdict(), warned.summary()["incidents"]) == (quiet.verdict(), quiet.summary()["incidents"])
    asked = analyze_blocked(csv, block_s=0, free_series=True)
    assert not any(w.startswith("memory:") for w in asked.warnings)


def test_a_ulog_goes_to_blocks_of_the_one_read_its_built_in_profile_made(monkeypatch):
    """A real PX4 ULog past the budget (here 1,000 steps, blocks of 2,000) is analysed in blocks,
    each a window of the read its built-in profile made (`logscan.pipeline.held_window`): the file
    is read once, the alarms and the verdict are those of the analysis at once."""
    from logscan.pipeline import blocks, preparation

    ulog = need_testdata("px4-ulog/sample_px4_events.ulg")  # 31 s of PX4's 250 Hz IMU: ~7,800 steps
    whole = analyze_blocked(ulog, block_s=0, free_series=True)
    reads = []
    read_log = preparation.read_log
    monkeypatch.setattr(preparation, "read_log", lambda *a, **k: reads.append(a[0]) or read_log(*a, **k))
    monkeypatch.setattr(blocks, "AUTO_STEPS", 1000)
    monkeypatch.setattr(blocks, "BLOCK_STEPS", 2000)
    parts = analyze_blocked(ulog, free_series=True)
    assert reads == [ulog]
    assert parts.warnings[-2].startswith("analysed in 4 blocks of 7.784 s")
    assert not any(w.startswith("memory:") for w in parts.warnings)
    assert (parts.verdict(), parts.exit_code()) == (whole.verdict(), whole.exit_code())
    assert _alarms(parts) == _alarms(whole)
    assert float(parts.run.t[0]) == float(whole.run.t[0]) and parts.run.n_steps == whole.run.n_steps


def test_the_command_writes_one_verdict_and_every_artifact_of_the_blocks(tmp_path, monkeypatch):
    import jsonschema

    from logscan.cli.main import main
    from logscan.pipeline import block_reduce

    monkeypatch.setattr(block_reduce, "MERGED_POINTS", 1000)  # buckets of 12 steps: the report draws envelopes

    paths = {name: tmp_path / name for name in ("r.html", "s.json", "j.xml", "m.md")}
    args = ["-o", paths["r.html"], "--json", paths["s.json"], "--junit", paths["j.xml"], "--markdown", paths["m.md"]]
    with pytest.raises(SystemExit) as exit_:
        main(["analyze", str(BIAS), "--block-s", "20", "-q", *map(str, args)])
    assert exit_.value.code == 1  # alarms, as at once
    document = json.loads(paths["s.json"].read_text())
    schema = json.loads((SAMPLES.parent / "docs" / "schema" / "analyze-summary.schema.json").read_text())
    jsonschema.Draft202012Validator(schema).validate(document)
    (log,) = document["logs"]
    assert log["n_incidents"] == 1 and log["filter"]["steps"] == 6001
    assert "nis.accel" in paths["r.html"].read_text() and "nis.accel" in paths["m.md"].read_text()
    assert "grid 6001 steps of 0.01 s" in paths["r.html"].read_text()  # the grid's, not the envelope's
    assert "<testsuite" in paths["j.xml"].read_text()
    counts = {s["n"] for d in log["detectors"] for s in d["series"].values()}
    assert counts == {6001}  # the log's samples, though its series are envelopes of buckets of 12


def test_merged_series_lie_on_the_merged_times(monkeypatch):
    from logscan.pipeline import block_reduce

    monkeypatch.setattr(block_reduce, "MERGED_POINTS", 1000)
    analysis = analyze_blocked(BIAS, block_s=20.0, free_series=True)
    n = analysis.run.t.size
    assert n < 6001 and np.all(np.diff(analysis.run.t) >= 0)
    for result in analysis.results:
        assert all(len(v) == n for v in result.series.values()), result.detector
        assert all(b.upper is None or len(b.upper) == n for b in result.thresholds.values())
        assert all(len(v) == n for v in result.judged.values())


def test_a_block_that_cannot_be_analysed_is_a_line_of_what_was_not_checked(monkeypatch):
    from logscan.errors import ExitCode, InputError
    from logscan.pipeline import blocks

    def analyze(path, profile_path=None, **options):
        if options.get("judged_from_s") == 20.0:  # as a block inside a long gap of the log
            raise InputError("too few samples on the analysis grid to filter", path=str(path))
        return analyze_log(path, profile_path, **options)

    monkeypatch.setattr(blocks, "analyze_log", analyze)
    analysis = analyze_blocked(BIAS, block_s=20.0, free_series=True)
    assert (
        analysis.unchecked[-1]
        == "block 2 of 3 (20.0-40.0 s) not analysed: too few samples on the analysis grid to filter"
    )
    assert analysis.exit_code() == ExitCode.BAD_INPUT


def test_blocks_of_a_window_start_their_filter_where_the_window_does():
    window = analyze_log(BIAS, start_s=5.0, free_series=True)
    blocks = analyze_blocked(BIAS, block_s=20.0, start_s=5.0, free_series=True)
    assert blocks.run.window == (5.0, None) and float(blocks.run.t[0]) == float(window.run.t[0])
    assert blocks.prepared.filter_summary()["lead_in_s"] == window.prepared.filter_summary()["lead_in_s"] == 5.0
    assert blocks.prepared.lead_in is not None  # the text's "filtered from 0.0 s"
    assert blocks.exit_code() == window.exit_code()


def test_a_window_two_blocks_give_is_kept_once_where_it_was_judged():
    from logscan.pipeline.block_merge import windows_once
    from logscan.verdict.observability import Observability

    directions: list = []
    before = Observability(np.array([0.0, 0.25, 0.5]), np.array([[1.0], [2.0], [np.nan]]), directions, t_end=0.74)
    after = Observability(np.array([0.5, 0.75]), np.array([[3.0], [4.0]]), directions, t_end=1.0)
    merged = windows_once(windows_once(None, before), after)  # folded in as block mode does
    assert merged.t_start.tolist() == [0.0, 0.25, 0.5, 0.75]
    assert merged.evidence[:, 0].tolist() == [1.0, 2.0, 3.0, 4.0] and merged.t_end == 1.0


def test_no_block_is_kept_once_it_is_folded_in(monkeypatch):
    """Each block, once reduced, is folded into the merged state and freed: when a block is reduced
    no block before it is alive (all of them were kept for the merge at the end: a 24-hour log's 48
    blocks held 1.5 MiB each), and the state's envelopes are about MERGED_POINTS points per series
    whether the log is analysed in 2 blocks or in 6."""
    import gc
    import weakref

    from logscan.pipeline import block_fold, block_reduce, blocks

    monkeypatch.setattr(block_reduce, "MERGED_POINTS", 600)  # 6000 steps: buckets of 20
    reduce, add = blocks.reduce_block, block_fold.BlockFold.add
    refs: list = []
    alive: list[int] = []
    held: list[int] = []

    def reduce_and_watch(analysis, width, *rest):
        gc.collect()
        alive.append(sum(ref() is not None for ref in refs))
        reduced = reduce(analysis, width, *rest)
        refs.append(weakref.ref(reduced))
        return reduced

    def add_and_measure(self, block, span):
        add(self, block, span)
        held.append(self.nbytes())

    monkeypatch.setattr(blocks, "reduce_block", reduce_and_watch)
    monkeypatch.setattr(block_fold.BlockFold, "add", add_and_measure)
    points, final = {}, {}
    for block_s in (30.0, 10.0):
        refs.clear(), alive.clear(), held.clear()
        analysis = analyze_blocked(BIAS, block_s=block_s, free_series=True)
        assert alive == [0] * len(alive) and len(alive) == 60 / block_s
        points[block_s], final[block_s] = analysis.run.t.size, held[-1]
    assert 600 <= points[30.0] <= 600 + 2 * 2 and 600 <= points[10.0] <= 600 + 2 * 6  # a bucket cut per block
    assert final[30.0] <= final[10.0] <= final[30.0] * 1.02


def test_the_fold_fills_what_a_block_does_not_give():
    from logscan.pipeline.block_fold import Columns

    columns = Columns()
    columns.append({"a": np.array([1.0, 2.0])}, 0, 2)
    columns.append(None, 2, 1)  # a block without the series: NaN, a gap in its line
    columns.append({"a": np.array([3.0]), "b": np.array([4.0], dtype=np.float32)}, 3, 1)
    assert columns.arrays["a"].tolist()[:2] == [1.0, 2.0] and np.isnan(columns.arrays["a"][2])
    assert columns.arrays["a"][3] == 3.0 and columns.arrays["b"].dtype == np.float32
    assert np.isnan(columns.arrays["b"][:3]).all() and columns.arrays["b"][3] == 4.0
    judged = Columns(fill=False)
    judged.append({"m": np.array([True])}, 0, 1)
    judged.append({}, 1, 2)
    assert judged.arrays["m"].tolist() == [True, False, False]


def test_a_log_longer_than_the_memory_budget_allows_at_once_goes_to_blocks(monkeypatch):
    """The longest span analysed at once is the 450 MB budget's (44.9 minutes at 100 Hz), not 1 GB's."""
    from logscan.pipeline import blocks
    from logscan.pipeline.preparation import load_profile_for

    loaded = load_profile_for(BIAS, None)  # the 100 Hz quadcopter's profile
    assert float(loaded.profile.vehicle.rate_hz) == 100.0
    # 44.9 minutes at once; beyond, blocks of equal length, none over BLOCK_STEPS
    for span_s, at_once in ((2690.0, True), (2700.0, False), (2710.0, False), (3600.0, False)):
        # an indexed MCAP file of that span with a message per grid step
        monkeypatch.setattr(blocks, "indexed_span_s", lambda path, s=span_s: (s, int(s * 100) + 1))
        windows = blocks.blocks_for(BIAS, loaded, None, None, None)
        assert (windows is None) == at_once, span_s
        if windows is not None:  # two blocks of half the span each
            assert windows[0] == (None, pytest.approx(span_s / 2 - blocks.BORDER_GAP_S)) and len(windows) == 2
    assert blocks.AUTO_STEPS * blocks.STEP_BYTES + blocks.START_BYTES <= blocks.MEMORY_BUDGET_BYTES
    # the --block-s help (docs/cli.md is generated from it, tests/test_docs_cli.py) says the same number
    assert f"more than {blocks.AUTO_STEPS:,} (" in (SAMPLES.parent / "docs" / "cli.md").read_text(encoding="utf-8")


def test_every_grid_step_of_a_ulog_is_in_one_block_whatever_its_phase():
    """The real robologs ULog's time zero is its logger's start, not a grid step: in 3-s blocks
    each step is analysed once (with half a step between blocks, a step fell between them at each
    of its 3 borders: 1792 steps of 1795)."""
    ulog = need_testdata("px4-ulog-extra/robologs_fmu_v5_test.ulg")
    whole = analyze_blocked(ulog, block_s=0, free_series=True)
    parts = analyze_blocked(ulog, block_s=3.0, free_series=True)
    assert parts.warnings[-2].startswith("analysed in 4 blocks")
    assert parts.prepared.filter_summary()["steps"] == whole.prepared.filter_summary()["steps"] == 1795
    assert _alarms(parts) == _alarms(whole)
