"""A window of a log read whole (`logscan.readers.held_window`): views of the samples a block needs
(the window and its margin, and each channel from its last finite sample before it), the whole
log's span and times, the source facts its own; the log read once for every window."""

from __future__ import annotations

import numpy as np
import pytest

from logscan.log import Channel, Log, SourceInfo
from logscan.readers.common import ReadWindow
from logscan.readers.held_window import held_window, whole_times

_S = 1_000_000_000


def _log() -> Log:
    t = np.arange(100, dtype=np.int64) * _S + 5 * _S  # 5 .. 104 s: time zero is the first sample
    gappy = np.arange(100.0)
    gappy[35:52] = np.nan  # no finite sample from 35 to 51 s (t = 40 .. 56 s)
    shuffled = np.array([3, 1, 2], dtype=np.int64) * _S + 5 * _S
    channels = {
        "/a/gappy": Channel("/a/gappy", t, gappy),
        "/a/dense": Channel("/a/dense", t, np.arange(100.0)),
        "/b/shuffled": Channel("/b/shuffled", shuffled, np.array([3.0, 1.0, 2.0])),
    }
    return Log(channels=channels, source=SourceInfo("held.csv", "csv"))


def _window(log: Log, start_s, end_s, plans: dict | None = None) -> Log:
    window = ReadWindow(start_s, end_s, margin_s=1.0, plans={} if plans is None else plans)
    return held_window("held.csv", window, frozenset({"a"}), lambda: log)


@pytest.fixture(autouse=True)
def _any_file(monkeypatch):
    from logscan.readers import held_window as module

    monkeypatch.setattr(module, "file_stat", lambda path: (0, 0))


def test_a_window_holds_its_span_and_margin_and_each_hold_from_its_last_finite_sample():
    whole = _log()
    part = _window(whole, 50.0, 60.0)  # 55 .. 65 s, with the 1-s margin 54 .. 66 s
    dense, gappy = part.channels["/a/dense"], part.channels["/a/gappy"]
    assert (dense.t[0], dense.t[-1]) == (53 * _S, 66 * _S)  # and the sample a hold into 54 s starts from
    assert (gappy.t[0], gappy.t[-1]) == (39 * _S, 66 * _S)  # from 39 s: the last finite sample before 54 s
    assert gappy.values[0] == 34.0 and np.isnan(gappy.values[1:18]).all()
    assert np.shares_memory(dense.values, whole.channels["/a/dense"].values)  # views, not copies
    assert part.channels["/b/shuffled"] is whole.channels["/b/shuffled"]  # out of order: all of it
    assert (part.start_ns, part.end_ns) == (whole.start_ns, whole.end_ns)  # the whole log's span
    first = _window(whole, None, 10.0).channels["/a/dense"]
    assert (first.t[0], first.t[-1]) == (5 * _S, 16 * _S)


def test_channels_of_one_time_array_share_the_whole_logs_times():
    whole = _log()
    times = whole_times(whole)
    assert times["/a/dense"] is times["/a/gappy"] and times["/b/shuffled"] is not times["/a/dense"]
    assert (times["/a/dense"].count, times["/a/dense"].first, times["/a/dense"].last) == (100, 5 * _S, 104 * _S)
    assert times["/b/shuffled"].fetch(0, 10 * _S).tolist() == [6 * _S, 7 * _S, 8 * _S]  # sorted
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
