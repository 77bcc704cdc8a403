"""Alignment of channels that share one time array (a topic's fields): cleaned and gap-checked once,
with the same results as channel by channel; a HeldTable's padded read equals its masked one."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from test_align import BASE, MS, FakeModel, force_100hz

from logscan.align import HeldTable, align, clean_samples
from logscan.align.sample_hold import time_order
from logscan.log import Channel, Log, SourceInfo
from logscan.profiles import parse_profile

PAIR = """
[measurements.pair]
channels = ["/pair/a", "/pair/b"]
rate_hz = 20
stale_s = 0.06
"""


def shared_log(t_ms: np.ndarray, a: np.ndarray, b: np.ndarray) -> Log:
    """A log whose /pair/a and /pair/b share one time array, as a reader builds a topic's fields."""
    t_force, force = force_100hz()
    t = np.asarray(t_ms, dtype=np.int64) * MS
    channels = {
        "/force": Channel("/force", t_force * MS, force),
        "/pair/a": Channel("/pair/a", t, a),
        "/pair/b": Channel("/pair/b", t, b),
    }
    return Log(channels, SourceInfo("test.mcap", "mcap"))


def test_a_shared_time_order_cleans_as_each_channel_alone():
    """Unsorted times with duplicates: the order found once gives each channel what cleaning it
    alone gives, and the channels' cleaned times are one array."""
    t = np.array([30, 10, 20, 20, 40, 50, 50, 60], dtype=np.int64)
    a = np.array([3.0, 1.0, 2.0, 2.5, np.nan, 5.0, 5.5, 6.0])
    b = np.array([-3.0, -1.0, -2.0, -2.5, -4.0, -5.0, -5.5, np.inf])
    order = time_order(t)
    assert (order.unsorted, order.duplicates) == (1, 2)
    for values in (a, b):
        alone, shared = clean_samples(t, values), clean_samples(t, values, order)
        np.testing.assert_array_equal(shared.t, alone.t)
        np.testing.assert_array_equal(shared.values, alone.values)
        assert (shared.unsorted, shared.duplicates, shared.nonfinite) == (alone.unsorted, alone.duplicates, 1)
    finite = np.arange(8.0)
    assert clean_samples(t, finite, order).t is clean_samples(t, 2 * finite, order).t  # one array for both
    np.testing.assert_array_equal(order.t_clean, [10, 20, 30, 40, 50, 60])


def test_channels_sharing_their_times_align_as_separate_ones():
    """The same samples in one shared time array or in two copies: the same held values, fresh
    masks, gaps and warnings (a gap from 400 to 800 ms, duplicates, a backward step, a NaN)."""
    t = np.concatenate([np.arange(0, 401, 50), [350], np.arange(800, 1001, 50), [1000]])
    a, b = t * 0.5, np.where(t == 900, np.nan, t * -2.0)
    profile = parse_profile(BASE + PAIR, model=FakeModel())
    shared = align(shared_log(t, a, b), profile)
    log = shared_log(t, a, b)
    log.channels["/pair/b"] = Channel("/pair/b", log.channels["/pair/b"].t.copy(), b)
    separate = align(log, profile)
    np.testing.assert_array_equal(shared.groups["pair"].z, separate.groups["pair"].z)
    np.testing.assert_array_equal(shared.groups["pair"].fresh, separate.groups["pair"].fresh)
    # both from 400 to 800 ms; /pair/b's NaN at 900 ms (its own cleaned times) leaves one more
    assert shared.gaps == separate.gaps and [g[2] for g in shared.gaps] == ["/pair/a", "/pair/b", "/pair/b"]
    assert shared.warnings == separate.warnings
    assert any("duplicate" in w for w in shared.warnings) and any("out of order" in w for w in shared.warnings)
    assert shared.channel_stats == separate.channel_stats


def test_a_padded_held_table_reads_like_the_masked_one():
    """Row -1 (nothing held) reads NaN from the pad row as from the mask, for every kind of index,
    and a read never writes into the samples (one step held nowhere: its row is a copy)."""
    samples = np.arange(12.0, dtype=np.float32).reshape(6, 2)
    padded = np.vstack([samples, np.full((1, 2), np.nan, dtype=np.float32)])
    row = np.array([-1, 0, 0, 1, 3, -1, -1, 5, 2, -1], dtype=np.int32)
    plain, pad = HeldTable(samples, row), HeldTable(padded[:-1], row, padded)
    for index in (slice(None), slice(2, 8), 0, 4, np.array([9, 1, 0]), row >= 0):
        got, expected = pad[index], plain[index]
        assert got.dtype == expected.dtype == np.float32
        np.testing.assert_array_equal(got, expected)
    assert np.isnan(np.asarray(pad)[[0, 5, 6, 9]]).all()
    np.testing.assert_array_equal(np.asarray(pad), np.asarray(plain))
    np.testing.assert_array_equal(samples, np.arange(12.0).reshape(6, 2))


@given(
    t=st.lists(st.integers(0, 40), min_size=0, max_size=30).map(lambda v: np.array(v, dtype=np.int64)),
    chunk=st.integers(1, 5),
)
@settings(max_examples=200, deadline=None)
def test_a_time_array_is_found_in_order_a_chunk_at_a_time_as_whole(t, chunk):
    # a long log's times on disk are checked a megasample at a time: an inversion or a repeat at a
    # chunk's border counts as one inside it
    from logscan.align import sample_hold

    whole = time_order(t)
    old, sample_hold._CHUNK = sample_hold._CHUNK, chunk
    try:
        chunked = time_order(t)
    finally:
        sample_hold._CHUNK = old
    assert (chunked.sort is None, chunked.keep is None) == (whole.sort is None, whole.keep is None)
    assert chunked.t_clean.tolist() == whole.t_clean.tolist()
    in_order = bool((t[1:] > t[:-1]).all())
    assert (chunked.t_clean is t) == in_order
