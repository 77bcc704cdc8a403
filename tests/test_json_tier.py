"""The bulk JSON kernel only where it pays (`logscan.readers.json_template.JsonTier`): a log's
JSON messages take the generic path while the kernel is neither compiled nor cached, until they
reach TIER_BYTES; both paths give the same log."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from logscan.readers import read_log
from logscan.readers.json_template import TIER_BYTES, JsonTier

SAMPLES = Path(__file__).resolve().parents[1] / "sample_logs"
MCAP_SAMPLES = sorted(path.name for path in SAMPLES.glob("*.mcap"))


def test_the_generic_path_until_its_bytes_reach_the_tier_then_the_kernel():
    tier = JsonTier()
    tier.ready = False  # neither compiled here nor cached
    batch = TIER_BYTES // 3 + 1
    assert [tier.use_kernel(batch) for _ in range(5)] == [False, False, False, True, True]
    assert tier.generic_bytes == 3 * batch


def test_the_generic_bytes_of_earlier_reads_count_through_the_tally(tmp_path):
    tally = tmp_path / "tally"
    batch = TIER_BYTES // 2 + 1
    first = JsonTier(tally)
    first.ready = False
    assert first.generic_bytes == 0 and not first.use_kernel(batch)
    first.save()
    assert tally.read_text() == str(batch)
    second = JsonTier(tally)  # a later read on the same machine
    second.ready = False
    assert second.generic_bytes == batch
    assert [second.use_kernel(batch), second.use_kernel(batch)] == [False, True]
    second.save()
    assert tally.read_text() == str(2 * batch) and sorted(p.name for p in tmp_path.iterdir()) == ["tally"]


def test_a_tally_that_cannot_be_read_or_written_only_counts_this_read(tmp_path):
    garbled = tmp_path / "garbled"
    garbled.write_text("not a count")
    assert JsonTier(garbled).generic_bytes == 0
    nowhere = JsonTier(tmp_path / "missing" / "tally")
    nowhere.ready = False
    assert not nowhere.use_kernel(10)
    nowhere.save()  # its folder does not exist: nothing written, nothing raised
    assert nowhere.generic_bytes == 10


def test_a_compiled_or_cached_kernel_is_used_from_the_first_batch():
    tier = JsonTier()
    tier.ready = True
    assert tier.use_kernel(1) and tier.generic_bytes == 0


@pytest.mark.parametrize("name", MCAP_SAMPLES)
def test_both_paths_read_the_same_log(sample, name, monkeypatch):
    path = sample(name)
    monkeypatch.setattr(JsonTier, "use_kernel", lambda self, size: False)
    generic = read_log(path)
    monkeypatch.setattr(JsonTier, "use_kernel", lambda self, size: True)
    bulk = read_log(path)
    assert generic.channels.keys() == bulk.channels.keys()
    for channel, theirs in bulk.channels.items():
        ours = generic.channels[channel]
        np.testing.assert_array_equal(ours.t, theirs.t)
        assert ours.values.dtype == theirs.values.dtype
        np.testing.assert_array_equal(ours.values, theirs.values)
    assert generic.source.warnings == bulk.source.warnings


def test_the_tier_counts_what_a_read_parses(sample, monkeypatch):
    """The reader asks its tier for every JSON batch: here never ready, so the whole sample goes
    the generic way and is counted."""
    asked: list[int] = []

    def never(self, size):
        asked.append(size)
        return False

    monkeypatch.setattr(JsonTier, "use_kernel", never)
    read_log(sample("quad_imu_bias.mcap"))
    assert len(asked) >= 9 and 3_000_000 < sum(asked) < TIER_BYTES  # nine topics, 3.7 MB of JSON


@pytest.mark.slow
def test_a_small_log_on_a_cold_cache_compiles_no_json_kernel(tmp_path, sample):
    probe = textwrap.dedent(
        f"""
        from logscan.readers import read_log
        from logscan.readers.json_template import match_and_parse
        import logscan.readers.json_template as json_template
        read_log({str(sample("quad_imu_bias.mcap"))!r})
        print(len(match_and_parse.signatures))
        json_template.TIER_BYTES = 0  # a log as large as the compile is worth
        read_log({str(sample("quad_healthy.mcap"))!r})
        print(len(match_and_parse.signatures))
        """
    )
    cache = str(tmp_path / "cache")  # fresh: no kernel, no tally
    env = dict(os.environ, NUMBA_CACHE_DIR=cache, LOGSCAN_CACHE_DIR=cache)
    done = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["0", "1"]
