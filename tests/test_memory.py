"""Memory per log: raw samples released once aligned, trace parts kept only when asked for."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from logscan.memory import reuse_freed_arrays
from logscan.needs import Needs
from logscan.pipeline import create_detectors, load_profile_for, needs_of, prepare
from logscan.readers import read_log
from logscan.report.run_context import STATE_TOPICS
from logscan.timebase.clock import GNSS_UTC_CHANNELS


def test_prepare_releases_the_raw_samples_and_keeps_the_logs_facts(sample):
    path = sample("quad_imu_bias.mcap")
    loaded = load_profile_for(path, None)
    # what prepare reads: the profile's topics and the report's context (states, a ULog's UTC)
    context = set(STATE_TOPICS) | set(GNSS_UTC_CHANNELS)
    before = read_log(path, topics=loaded.profile.topics() | context).summary()
    prepared = prepare(path, loaded, Needs.of(ekf=()))
    log = prepared.log
    assert log.channels and all(len(channel) == 0 for channel in log.channels.values())
    assert log.summary() == before
    assert prepared.run.n_steps == 6001 and np.isfinite(prepared.trace.nis).any()


def test_innovations_are_kept_only_when_a_detector_asks(sample):
    path = sample("quad_imu_bias.mcap")
    loaded = load_profile_for(path, None)
    # nis does not ask for them (cusum, a default detector, does; encoded_ekf asks for e_x's
    # predicted variance, which the filter computes, so it keeps no K and S either)
    default = prepare(path, loaded, needs_of(create_detectors(loaded, ["encoded_ekf", "nis"])))
    assert default.trace.y is None and default.trace.S_diag is None and default.trace.K is None
    assert default.trace.ex_variance is not None
    with_cusum = prepare(path, loaded, needs_of(create_detectors(loaded, None)))
    assert with_cusum.trace.y is not None and with_cusum.trace.P_prior is None
    asked = prepare(path, loaded, Needs.of(ekf=("y",)))
    m = sum(asked.trace.group_sizes)
    assert asked.trace.y.shape == asked.trace.S_diag.shape == (asked.run.n_steps, m)
    updated = np.isfinite(asked.trace.y).any(axis=1)
    # the kept innovations belong to the same filter run: NIS defined exactly where y is
    np.testing.assert_array_equal(updated, np.isfinite(asked.trace.nis))
    np.testing.assert_array_equal(asked.trace.nis, default.trace.nis)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_the_mmap_threshold_is_fixed_on_glibc():
    assert reuse_freed_arrays() is True


FREED_INSIDE_THE_HEAP = """
import numpy as np
from logscan.memory import every_free_page, return_freed_pages, reuse_freed_arrays

def rss_mib():
    with open("/proc/self/status") as fh:
        return next(int(line.split()[1]) for line in fh if line.startswith("VmRSS:")) / 1024

reuse_freed_arrays()
arrays = [np.ones(1 << 20) for _ in range(50)]  # 50 x 8 MiB: carved from the heap
pinned = np.ones(1 << 20)  # above them: the heap's top is not free
del arrays[:10]  # 80 MiB free inside the heap, under the trim threshold: kept for reuse
before = rss_mib()
print(return_freed_pages(), round(before - rss_mib()))
with every_free_page():  # block mode: given back all the same
    before = rss_mib()
    print(return_freed_pages(), round(before - rss_mib()))
del arrays[:10]  # 80 MiB free again, after the block: kept again
before = rss_mib()
print(return_freed_pages(), round(before - rss_mib()))
arrays.clear()  # 320 MiB free: given back
before = rss_mib()
print(return_freed_pages(), round(before - rss_mib()))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc_trim")
def test_freed_pages_inside_the_heap_go_back_from_the_trim_threshold_or_in_block_mode():
    out = subprocess.run([sys.executable, "-c", FREED_INSIDE_THE_HEAP], capture_output=True, text=True, check=True)
    (kept, _), (blocks, blocks_mib), (kept_again, _), (returned, mib) = (
        line.split() for line in out.stdout.split("\n")[:4]
    )
    assert kept == "False" and kept_again == "False"  # a log analysed at once reuses them
    assert blocks == "True" and int(blocks_mib) >= 70  # of the 80 MiB under the trim threshold
    assert returned == "True" and int(mib) >= 250  # of the 320 MiB freed below the pinned array


def test_the_filter_reads_the_aligned_samples_in_place(sample):
    from logscan.filters.ekf import pack_run

    path = sample("quad_imu_bias.mcap")
    loaded = load_profile_for(path, None)
    prepared = prepare(path, loaded, Needs())
    packed = pack_run(prepared.model, prepared.run)
    for name, group in prepared.run.groups.items():
        assert np.shares_memory(packed.z, group.z), name
    # a hand-built run (groups in their own arrays) is copied into the same layout
    first = next(iter(prepared.run.groups.values()))
    first.z = first.z.copy()
    copied = pack_run(prepared.model, prepared.run)
    assert not np.shares_memory(copied.z, first.z)
    np.testing.assert_array_equal(copied.z, packed.z)


class _Undeclared:
    """A detector that does not say what it reads (a plugin): nothing may be freed before it runs."""

    name = "undeclared"
    reads = None

    def run(self, run, trace, **context):
        self.seen = (trace.x_post is not None, run.onboard_state is not None, run.u is not None)
        from logscan.results import DetectorResult

        return DetectorResult(detector=self.name)


def test_each_large_series_is_freed_once_no_detector_left_reads_it(sample):
    from logscan.pipeline import detect

    path = sample("quad_imu_bias.mcap")
    loaded = load_profile_for(path, None)
    encoded, nis = create_detectors(loaded, ["encoded_ekf", "nis"])
    kept = detect(prepare(path, loaded, needs_of([encoded, nis])), [encoded, nis])
    assert kept.trace.x_prior is not None and kept.run.onboard_state is not None  # not asked to free

    prepared = prepare(path, loaded, needs_of([encoded, nis]))
    undeclared = _Undeclared()
    freed = detect(prepared, [encoded, undeclared, nis], free_series=True)
    assert undeclared.seen == (True, True, True)  # still there for the detector that did not declare
    trace, run = freed.trace, freed.run
    assert trace.x_prior is None and trace.P_post_diag is None and run.onboard_state is None and run.u is None
    assert all(group.z is None for group in run.groups.values())
    assert trace.nis is not None and trace.updated is not None  # read after the detectors
    by_name = {r.detector: r for r in kept.results}
    for result in freed.results:
        if result.detector in by_name:
            assert [a.to_dict() for a in result.alarms] == [a.to_dict() for a in by_name[result.detector].alarms]
    assert freed.summary()["filter"] == kept.summary()["filter"]


def test_the_report_needs_only_the_grid_and_the_results(sample, tmp_path):
    from logscan.pipeline import analyze_log

    path = sample("quad_imu_bias.mcap")
    analysis = analyze_log(path, free_series=True)
    summary = analysis.summary()
    analysis.prepared.release_series()
    assert analysis.summary() == summary
    assert analysis.prepared.traces == {} and analysis.run.t.size == 6001
    report = analysis.report_input()
    assert report.t is analysis.run.t and report.results == analysis.results


@pytest.mark.parametrize("name", ["quad_imu_bias.mcap", "sbw_yaw_rate_bitflip.mcap", "jackal_healthy.mcap"])
def test_decoding_chunk_by_chunk_gives_the_same_log(sample, monkeypatch, name):
    """The reader decodes the scan's batches whenever FLUSH_BYTES are held: flushing after every
    chunk (and every 7 top-level records) reads the same channels as one flush at the end."""
    from logscan.readers.mcap import scan

    path = sample(name)
    whole = read_log(path)
    monkeypatch.setattr(scan, "FLUSH_BYTES", 1)
    monkeypatch.setattr(scan, "TOP_LEVEL_SLICE", 7)
    monkeypatch.setattr(scan, "WALK_WINDOW", 100)  # record boundaries found 100 bytes at a time
    pieces = read_log(path)
    assert list(pieces.channels) == list(whole.channels) and whole.channels
    for channel, again in zip(whole.channels.values(), pieces.channels.values()):
        np.testing.assert_array_equal(channel.t, again.t)
        np.testing.assert_array_equal(channel.values, again.values)
    assert pieces.summary() == whole.summary()


def test_unchunked_mcap_decoded_in_slices_of_top_level_records(tmp_path, monkeypatch):
    import json

    from mcap.writer import Writer

    from logscan.readers.mcap import scan

    path = tmp_path / "flat.mcap"
    with open(path, "wb") as fh:
        writer = Writer(fh, use_chunking=False)
        writer.start()
        schema = writer.register_schema("S", "jsonschema", b"{}")
        channel = writer.register_channel("/v", "json", schema)
        for k in range(1000):
            writer.add_message(channel, 1000 + k, json.dumps({"k": k, "half": k / 2}).encode(), 1000 + k)
        writer.finish()
    whole = read_log(path)
    monkeypatch.setattr(scan, "FLUSH_BYTES", 1)
    monkeypatch.setattr(scan, "TOP_LEVEL_SLICE", 64)
    sliced = read_log(path)
    np.testing.assert_array_equal(sliced.channels["/v/k"].values, np.arange(1000))
    for name, channel in whole.channels.items():
        np.testing.assert_array_equal(channel.values, sliced.channels[name].values)
        np.testing.assert_array_equal(channel.t, sliced.channels[name].t)


@pytest.mark.parametrize("name", ["quad_imu_bias.mcap", "sbw_yaw_rate_bitflip.mcap", "jackal_healthy.mcap"])
def test_inspect_folds_each_batch_into_the_same_facts(sample, monkeypatch, name):
    """`inspect` on an MCAP keeps per-channel statistics, not samples: the same facts as reading
    the whole log, with a flush after every chunk."""
    from logscan.cli.inspect_cmd import inspect_facts, read_facts
    from logscan.readers.mcap import scan

    path = sample(name)
    whole = inspect_facts(read_log(path))
    monkeypatch.setattr(scan, "FLUSH_BYTES", 1)
    streamed = read_facts(path, None, False)
    assert streamed == whole
    assert streamed["channels"] and all(info["samples"] > 0 for info in streamed["channels"].values())
