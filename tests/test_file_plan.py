"""A window read's file plan (`logscan.readers.mcap.file_plan`) is read once and kept for the next
window of the file, and the topics' times across the file are kept as runs (`logscan.timebase.time_runs`)
that give exactly what `outlying_runs` and `dense_span` give on the whole arrays of times."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_mcap_window import MARGIN_S, S, assert_same_run, profile_of, rewrite

from logscan.align import align
from logscan.readers import read_log
from logscan.readers.common import MCAP_MAGIC, ReadWindow
from logscan.readers.mcap import file_plan
from logscan.readers.mcap.records import OP_CHUNK, walk_records
from logscan.readers.mcap.scan import Scan
from logscan.timebase import time_runs as time_runs_module
from logscan.timebase.time_runs import dense_runs, dropped_times, median_step, runs_of, time_runs
from logscan.timebase.time_sanity import dense_span, outlying_runs


@pytest.fixture(scope="module")
def chunked(tmp_path_factory) -> dict[str, Path]:
    """The quadcopter sample, and that log rewritten in 16 KiB chunks with its Message Indexes."""
    source = Path(__file__).resolve().parent.parent / "sample_logs" / "quad_healthy.mcap"
    if not source.exists():
        pytest.skip(f"{source} missing (run sample_logs/make_samples.py)")
    indexed = tmp_path_factory.mktemp("plan") / "indexed.mcap"
    rewrite(source, indexed)
    return {"source": source, "indexed": indexed}


def batched(t: np.ndarray, size: int):
    def batches():
        for lo in range(0, t.size, size):
            yield t[lo : lo + size]

    return batches


def runs_in_batches(t: np.ndarray, size: int):
    return time_runs(batched(t, size), lambda lo, hi: t[(t >= lo) & (t <= hi)])


SPACINGS = {
    "100 Hz exactly": lambda rng, n: np.full(n, 10_000_000),
    "100 Hz jittered": lambda rng, n: rng.integers(9_000_000, 11_000_000, n),
    "two spacings, ties at the median": lambda rng, n: rng.choice([10_000_000, 20_000_000], n),
    "seconds to hours": lambda rng, n: rng.integers(1, 3, n) * rng.choice([1, S, 3600 * S], n),
    "wider than 2**53 ns": lambda rng, n: rng.choice([2**54 + 12345, 2**55 + 1], n) // 1000,
    "gaps over 10 s": lambda rng, n: rng.choice([10_000_000, 20 * S], n, p=[0.995, 0.005]),
}


@pytest.mark.parametrize("kind", SPACINGS)
@pytest.mark.parametrize("seed", range(4))
def test_the_runs_are_outlying_runs_of_the_whole_array(kind, seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(40, 4000))
    t = np.unique(1_700_000_000 * S + np.cumsum(SPACINGS[kind](rng, n)).astype(np.int64))
    if seed % 2:  # a stray time far before and one far after
        t = np.unique(np.concatenate(([int(t[0]) - 7200 * S], t, [2**63 - 1])))
    runs = runs_in_batches(t, int(rng.integers(1, 1500)))
    (lo, hi), tiny_lo, tiny_hi, gap = outlying_runs(t)
    assert runs.n == t.size and (runs.first, runs.last) == (t[0], t[-1]) and runs.gap == gap
    assert (runs.starts[runs.main], runs.ends[runs.main]) == (t[lo], t[hi - 1])
    np.testing.assert_array_equal(runs.starts[runs.tiny], t[tiny_lo])
    np.testing.assert_array_equal(runs.ends[runs.tiny], t[tiny_hi - 1])
    if t.size > 1:
        steps = (t[1:].view(np.uint64) - t[:-1].view(np.uint64)).astype(np.float64)
        assert median_step(batched(t, 97), t.size - 1) == np.median(steps)


@pytest.mark.parametrize("seed", range(12))
def test_the_dense_span_of_runs_is_that_of_the_whole_arrays(seed):
    """Channels with outlying samples before and after, one sharing another's times (a topic's
    fields): the same span, drops and channels at its ends, and the dropped times read again."""
    rng = np.random.default_rng(seed)
    times = {}
    for name in ("imu", "gps", "baro"):
        t = 10**18 + np.cumsum(rng.integers(5_000_000, 15_000_000, int(rng.integers(60, 3000))))
        early = rng.integers(0, 10**17, int(rng.integers(0, 3)))
        late = 2**62 + rng.integers(0, 10**9, int(rng.integers(0, 4)))
        times[name] = np.unique(np.concatenate((early, t, late)).astype(np.int64))
    times["imu.y"] = times["imu"]
    found = {id(t): runs_in_batches(t, 250) for t in times.values()}
    runs = {name: found[id(t)] for name, t in times.items()}
    first, last, drops, ends = dense_span(times, "log")
    assert dense_runs(runs, "log")[:2] == (first, last) and dense_runs(runs, "log")[3] == ends
    dropped = dense_runs(runs, "log")[2]
    assert dropped.keys() == drops.keys()
    for name, drop in drops.items():
        np.testing.assert_array_equal(dropped_times(runs[name], dropped[name]), times[name][drop])


def written(source, path, edit) -> dict[str, np.ndarray]:
    """``source`` rewritten to ``path`` with ``edit``; each topic's log times as written."""
    times: dict[str, list[int]] = {}

    def noting(topic, n, t, data):
        out = edit(topic, n, t, data)
        times.setdefault(topic, []).extend(int(when) for when, _ in out)
        return out

    rewrite(source, path, edit=noting)
    return {topic: np.unique(np.array(ts, dtype=np.int64)) for topic, ts in times.items()}


def late_gps(topic, n, t, data):
    """The last three GPS fixes two hours late (an outlying run), two IMU samples written out of
    order (index records that overlap in time)."""
    if topic == "/gps" and n >= 597:
        return [(t + 7200 * S, data)]
    if topic == "/imu" and n in (2500, 4000):
        return [(t - 20 * S + 3_000_000, data)]
    return [(t, data)]


def twice(topic, n, t, data):
    """Every 500th IMU sample logged twice."""
    return [(t, data)] if topic != "/imu" or n % 500 else [(t, data), (t, data)]


def test_a_topics_runs_are_those_of_its_whole_index(chunked, tmp_path, monkeypatch):
    """The runs of each topic kept for a window are `outlying_runs` of all the times its index
    lists (read in batches of 300 times), and the window aligns as the whole read does, the late
    fixes dropped as outlying from the runs kept."""
    monkeypatch.setattr(file_plan, "BATCH_TIMES", 300)
    path = tmp_path / "late_gps.mcap"
    expected = written(chunked["source"], path, late_gps)
    whole, window = assert_same_run(path, 20.0, 30.0)
    assert window.whole_times and any("outlying" in w for w in align_warnings(window, path))
    for name, whole_times in window.whole_times.items():
        t = expected[name.rsplit("/", 1)[0]]
        runs = runs_of(whole_times)
        (lo, hi), tiny_lo, _, gap = outlying_runs(t)
        assert (runs.n, runs.gap, runs.starts[runs.main], runs.ends[runs.main]) == (t.size, gap, t[lo], t[hi - 1])
        np.testing.assert_array_equal(runs.starts[runs.tiny], t[tiny_lo])


def align_warnings(log, path):
    return align(log, profile_of(path), start_s=20.0, end_s=30.0).warnings


def test_a_damaged_chunks_times_stay_in_the_runs(chunked, tmp_path):
    """A chunk that does not decompress: the whole read skips it, the index still lists its times,
    and the runs kept are those of every time the index lists, as the full index read gave them
    (a time logged twice counted once)."""
    path = tmp_path / "damaged.mcap"
    expected = written(chunked["source"], path, twice)
    data = bytearray(path.read_bytes())
    top = walk_records(np.frombuffer(bytes(data), dtype=np.uint8), len(MCAP_MAGIC), len(data))
    chunks = top.offsets[top.ops == OP_CHUNK]
    chunk = int(chunks[chunks.size // 4])  # about 15 s in: not a chunk the window reads
    data[chunk + 60 : chunk + 90] = b"\xff" * 30  # inside its compressed records
    path.write_bytes(bytes(data))
    profile = profile_of(chunked["source"])
    assert read_log(path, topics=profile.topics()).source.partial  # the whole read lost the chunk
    log = read_log(path, topics=profile.topics(), window=ReadWindow(40.0, 50.0, MARGIN_S, plans={}))
    assert log.whole_times  # read as a window of the file
    for name, whole_times in log.whole_times.items():
        t = expected[name.rsplit("/", 1)[0]]
        runs = runs_of(whole_times)
        (lo, hi), _, _, gap = outlying_runs(t)
        assert (runs.n, runs.gap, runs.starts[runs.main], runs.ends[runs.main]) == (t.size, gap, t[lo], t[hi - 1])
        assert whole_times.count == t.size + (-(-t.size // 500) if name.startswith("/imu/") else 0)  # messages


def test_the_next_window_reads_neither_the_top_level_nor_the_index_again(chunked, monkeypatch):
    """A second window of the file with the first's plans: no walk of the top-level records, no
    index read, no pass over the times, and the same log as a read of its own."""
    path, profile = chunked["indexed"], profile_of(chunked["indexed"])
    plans: dict = {}
    first = read_log(path, topics=profile.topics(), window=ReadWindow(10.0, 20.0, MARGIN_S, plans=plans))
    runs = {name: runs_of(w) for name, w in first.whole_times.items()}
    assert list(plans) == [str(path)]

    def refused(*args, **kwargs):
        raise AssertionError("read again")

    calls: list[str] = []
    monkeypatch.setattr(Scan, "_walk", refused)
    monkeypatch.setattr(file_plan, "channel_index", refused)
    monkeypatch.setattr(time_runs_module, "time_runs", lambda *a: calls.append("runs"))
    second = read_log(path, topics=profile.topics(), window=ReadWindow(40.0, 50.0, MARGIN_S, plans=plans))
    again = {name: runs_of(w) for name, w in second.whole_times.items()}  # kept: no pass over the times
    monkeypatch.undo()
    alone = read_log(path, topics=profile.topics(), window=ReadWindow(40.0, 50.0, MARGIN_S))
    assert second.channels.keys() == alone.channels.keys()
    for name, channel in alone.channels.items():
        np.testing.assert_array_equal(second.channels[name].t, channel.t)
        np.testing.assert_array_equal(second.channels[name].values, channel.values)
    assert again.keys() == runs.keys() and all(again[name] is runs[name] for name in runs) and not calls
    assert (second.start_ns, second.end_ns) == (alone.start_ns, alone.end_ns)


def test_a_file_changed_since_is_planned_again(chunked, tmp_path):
    path = tmp_path / "changing.mcap"
    path.write_bytes(chunked["indexed"].read_bytes())
    profile = profile_of(path)
    plans: dict = {}
    first = read_log(path, topics=profile.topics(), window=ReadWindow(10.0, 20.0, MARGIN_S, plans=plans))
    before = plans[str(path)]
    rewrite(chunked["source"], path, edit=lambda topic, n, t, data: [(t + S, data)])
    again = read_log(path, topics=profile.topics(), window=ReadWindow(10.0, 20.0, MARGIN_S, plans=plans))
    assert plans[str(path)] is not before and again.start_ns == first.start_ns + S
