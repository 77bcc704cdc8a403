"""A log's span (first and last sample time) in one pass over each distinct time array, a chunk at a
time past `TIMES_CHUNK`: the same as the minimum and maximum of every channel's times."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan import log as log_module
from logscan.log import Channel, Log, SourceInfo, TopicInfo


@settings(max_examples=60, deadline=None)
@given(
    arrays=st.lists(st.lists(st.integers(-(2**62), 2**62), min_size=0, max_size=40), min_size=1, max_size=5),
    shared=st.booleans(),
    chunk=st.integers(1, 7),
)
def test_span_is_every_channels_min_and_max(arrays, shared, chunk):
    original, log_module.TIMES_CHUNK = log_module.TIMES_CHUNK, chunk  # every border, and one chunk alike
    try:
        check_span(arrays, shared)
    finally:
        log_module.TIMES_CHUNK = original


def check_span(arrays: list[list[int]], shared: bool) -> None:
    times = [np.array(values, dtype=np.int64) for values in arrays]
    channels = {}
    for i, t in enumerate(times):  # unsorted times too: a damaged file's are read as they stand
        channels[f"/c{i}"] = Channel(f"/c{i}", t, np.zeros(t.size))
        if shared:  # a topic's fields share their time array
            channels[f"/c{i}b"] = Channel(f"/c{i}b", t, np.ones(t.size))
    log = Log(channels=channels, source=SourceInfo(path="x", format="csv"))
    held = [t for t in times if t.size]
    if held:
        expected = (int(min(t.min() for t in held)), int(max(t.max() for t in held)))
    else:
        expected = (None, None)
    assert (log.start_ns, log.end_ns) == expected
    assert log.duration_s == (0.0 if not held else (expected[1] - expected[0]) / 1e9)


def test_span_without_samples_comes_from_the_topics():
    source = SourceInfo(path="x", format="ulog")
    source.topics["a"] = TopicInfo(name="a", message_count=2, first_ns=5, last_ns=9)
    source.topics["b"] = TopicInfo(name="b", message_count=2, first_ns=3, last_ns=7)
    log = Log(channels={"/a/x": Channel("/a/x", np.empty(0, np.int64), np.empty(0))}, source=source)
    assert (log.start_ns, log.end_ns) == (3, 9)


def test_span_pass_reads_each_distinct_array_once(monkeypatch):
    """The bytes told to TIMES_READ (a held read on disk gives its pages back by them): each time
    array once, however many channels share it, min and max in the same pass."""
    told = []
    monkeypatch.setattr(log_module, "TIMES_READ", [told.append])
    monkeypatch.setattr(log_module, "TIMES_CHUNK", 3)
    t = np.arange(10, dtype=np.int64)
    channels = {f"/c{i}": Channel(f"/c{i}", t, np.zeros(10)) for i in range(4)}
    Log(channels=channels, source=SourceInfo(path="x", format="csv")).duration_s  # noqa: B018
    assert sum(told) == t.nbytes * 2  # Log() takes it once (its span check), duration_s once more
