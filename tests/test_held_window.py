"""A window of a log read whole (`logscan.pipeline.held_window`): views of the samples a block needs
(the window and its margin, and each time array from where its channels' holds into the window
start), the whole log's span and its channels' times as alignment cleans them, the source facts
its own; the log read once for every window."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.align.sample_hold import clean_samples
from logscan.log import Channel, Log, SourceInfo
from logscan.pipeline.held_window import held_window, whole_times
from logscan.readers.common import ReadWindow

_S = 1_000_000_000


def _log() -> Log:
    t = np.arange(100, dtype=np.int64) * _S + 5 * _S  # 5 .. 104 s: time zero is the first sample
    gappy = np.arange(100.0)
    gappy[35:52] = np.nan  # no finite sample from 35 to 51 s (t = 40 .. 56 s)
    shuffled = np.array([3, 1, 2], dtype=np.int64) * _S + 5 * _S
    twice = np.array([5, 50, 53, 53, 70], dtype=np.int64) * _S  # 53 s logged twice, the last NaN
    channels = {
        "/a/gappy": Channel("/a/gappy", t, gappy),
        "/a/dense": Channel("/a/dense", t, np.arange(100.0)),
        "/a/fine": Channel("/a/fine", t, np.arange(100.0) + 0.1),  # no float32 holds these
        "/a/never": Channel("/a/never", t, np.full(100, np.nan)),
        "/b/shuffled": Channel("/b/shuffled", shuffled, np.array([3.0, 1.0, 2.0])),
        "/c/twice": Channel("/c/twice", twice, np.array([0.0, 1.0, 2.0, np.nan, 4.0])),
    }
    return Log(channels=channels, source=SourceInfo("held.csv", "csv"))


def _window(log: Log, start_s, end_s, plans: dict | None = None) -> Log:
    window = ReadWindow(start_s, end_s, margin_s=1.0, plans={} if plans is None else plans)
    return held_window("held.csv", window, frozenset({"a"}), lambda: log)


@pytest.fixture(autouse=True)
def _any_file(monkeypatch):
    from logscan.pipeline import held_window as module

    monkeypatch.setattr(module, "file_stat", lambda path: (0, 0))


def test_a_window_holds_its_span_and_margin_and_each_hold_from_where_it_starts():
    whole = _log()
    read = dict(whole.channels)
    part = _window(whole, 50.0, 60.0)  # 55 .. 65 s, with the 1-s margin 54 .. 66 s
    dense, gappy = part.channels["/a/dense"], part.channels["/a/gappy"]
    # one view of the topic's times, from 39 s: the gappy field's last finite sample before 54 s
    # (the dense field's is at 53 s; the field never finite starts no hold)
    assert dense.t is gappy.t is part.channels["/a/never"].t
    assert (dense.t[0], dense.t[-1]) == (39 * _S, 66 * _S)
    assert gappy.values[0] == 34.0 and np.isnan(gappy.values[1:18]).all()
    # held as float32 where that is exact, each window's float64 again; the others views, not copies
    assert whole.channels["/a/dense"].values.dtype == np.float32 and dense.values.dtype == np.float64
    assert dense.values.tolist() == read["/a/dense"].values[34:62].tolist()
    assert whole.channels["/a/fine"].values.dtype == np.float64
    assert np.shares_memory(part.channels["/a/fine"].values, whole.channels["/a/fine"].values)
    shuffled = part.channels["/b/shuffled"]  # out of order: all of it
    assert shuffled.t is read["/b/shuffled"].t and shuffled.values.tolist() == [3.0, 1.0, 2.0]
    # 53 s logged twice, the last NaN (cleaning keeps it, then drops it): the hold starts at 50 s
    assert part.channels["/c/twice"].t.tolist() == [50 * _S, 53 * _S, 53 * _S]
    assert (part.start_ns, part.end_ns) == (whole.start_ns, whole.end_ns)  # the whole log's span
    assert part.window_zero_ns == whole.origin_ns == 5 * _S
    assert list(part.channels) == list(whole.channels)
    first = _window(whole, None, 10.0).channels["/a/dense"]
    assert (first.t[0], first.t[-1]) == (5 * _S, 16 * _S)


def test_the_whole_logs_times_are_those_alignment_cleans():
    whole = _log()
    times, never, _ = whole_times(whole)
    assert never == {"/a/never"} and "/a/never" not in times
    assert times["/a/dense"].count == 100 and times["/a/dense"].first == 5 * _S
    assert times["/a/gappy"] is not times["/a/dense"] and times["/a/gappy"].count == 83  # its finite samples
    assert times["/b/shuffled"].fetch(0, 10 * _S).tolist() == [6 * _S, 7 * _S, 8 * _S]  # sorted
    assert times["/c/twice"].fetch(0, 100 * _S).tolist() == [5 * _S, 50 * _S, 70 * _S]  # 53 s: NaN kept last
    assert np.concatenate(list(times["/a/dense"].batches())).tolist() == whole.channels["/a/dense"].t.tolist()
    part = _window(whole, 50.0, 60.0)
    assert part.whole_times["/a/dense"].fetch(60 * _S, 62 * _S).tolist() == [60 * _S, 61 * _S, 62 * _S]


def test_the_log_is_read_once_for_every_window_and_each_window_has_its_own_source_facts():
    whole, reads = _log(), []
    plans: dict = {}

    def read() -> Log:
        reads.append(1)
        return whole

    window = ReadWindow(20.0, 30.0, margin_s=0.0, plans=plans)
    first = held_window("held.csv", window, frozenset({"a"}), read)
    second = held_window("held.csv", ReadWindow(30.0, 40.0, margin_s=0.0, plans=plans), frozenset({"a"}), read)
    assert len(reads) == 1
    first.source.warnings.append("said by the first block")
    first.source.skip("x", "y")
    assert second.source.warnings == whole.source.warnings == []
    assert second.source.skipped == whole.source.skipped == []
    held_window("held.csv", ReadWindow(30.0, 40.0, margin_s=0.0, plans=plans), frozenset({"a", "b"}), read)
    assert len(reads) == 2  # other topics: read again


def test_a_real_ulog_whose_first_samples_are_nan_aligns_a_window_as_the_whole_log(monkeypatch):
    """The real events ULog with the first 50 samples of the topic that starts the grid made NaN:
    the grid starts where the whole log's does (its finite samples', not its messages'), so a
    window cut from the held read aligns as the whole log does on that window."""
    from conftest import need_testdata

    from logscan.align import align
    from logscan.pipeline.held_window import HeldLog, window_of
    from logscan.pipeline.preparation import load_profile_for

    loaded = load_profile_for(need_testdata("px4-ulog/sample_px4_events.ulg"), None)
    profile, log = loaded.profile, loaded.log
    spanning = [*profile.inputs.channels, *(ch for g in profile.measurements.values() for ch in g.channels)]
    earliest = min(spanning, key=lambda name: int(log.channels[name].t[0]))
    t = log.channels[earliest].t
    channels = dict(log.channels)
    for name, channel in log.channels.items():
        if channel.t is t:
            values = channel.values.copy()
            values[:50] = np.nan
            channels[name] = Channel(name, t, values)
    edited = Log(channels=channels, source=log.source)
    held = HeldLog(edited, (0, 0), frozenset(), *whole_times(edited))
    for start_s, end_s in ((None, None), (10.0, 20.0)):
        whole = align(edited, profile, start_s=start_s, end_s=end_s)
        part = align(window_of(held, ReadWindow(start_s, end_s, 5.02)), profile, start_s=start_s, end_s=end_s)
        assert (float(part.t[0]), part.n_steps, part.start_ns) == (float(whole.t[0]), whole.n_steps, whole.start_ns)
        np.testing.assert_array_equal(part.u, whole.u)
        for name, group in whole.groups.items():
            np.testing.assert_array_equal(part.groups[name].z, group.z, err_msg=name)


@given(
    count=st.integers(1, 60),
    nan_share=st.floats(0.0, 1.0),
    disorder=st.sampled_from(["in order", "twice", "shuffled"]),
    seed=st.integers(0, 2**32 - 1),
)
@settings(max_examples=80, deadline=None)
def test_each_channels_whole_times_are_its_cleaned_samples_times(count, nan_share, disorder, seed):
    """A channel with non-finite samples has its own times: those `clean_samples` keeps, found a
    batch at a time for times in order (a long log's channel is not copied whole as float64)."""
    from logscan.pipeline import held_window as module

    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.integers(1, 5, count)).astype(np.int64) * 1_000_000
    if disorder == "twice" and count > 1:
        t[rng.integers(1, count)] = t[0]
        t.sort()
    elif disorder == "shuffled":
        rng.shuffle(t)
    values = rng.normal(size=count).astype(np.float32)
    values[rng.random(count) < nan_share] = np.nan
    log = Log(channels={"/a/x": Channel.held("/a/x", t, values)}, source=SourceInfo(path="x", format="test"))
    old = module._BATCH
    module._BATCH = 7  # batch borders everywhere
    try:
        times, never, _ = whole_times(log)
    finally:
        module._BATCH = old
    expected = clean_samples(t, values.astype(np.float64)).t
    if not expected.size:
        assert "/a/x" in never and "/a/x" not in times
    else:
        found = times["/a/x"]
        assert (found.count, found.first, found.last) == (expected.size, expected[0], expected[-1])
        np.testing.assert_array_equal(np.concatenate(list(found.batches())), expected)
