"""Memory per log: raw samples released once aligned, trace parts kept only when asked for."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from logscan.memory import return_freed_arrays_to_the_system
from logscan.needs import Needs
from logscan.pipeline import create_detectors, load_profile_for, needs_of, prepare
from logscan.readers import read_log


def test_prepare_releases_the_raw_samples_and_keeps_the_logs_facts(sample):
    path = sample("quad_imu_bias.mcap")
    loaded = load_profile_for(path, None)
    before = read_log(path, topics=loaded.profile.topics()).summary()
    prepared = prepare(path, loaded, Needs.of(ekf=()))
    log = prepared.log
    assert log.channels and all(len(channel) == 0 for channel in log.channels.values())
    assert log.summary() == before
    assert prepared.run.n_steps == 6001 and np.isfinite(prepared.trace.nis).any()


def test_innovations_are_kept_only_when_a_detector_asks(sample):
    path = sample("quad_imu_bias.mcap")
    loaded = load_profile_for(path, None)
    default = prepare(path, loaded, needs_of(create_detectors(loaded, None)))
    assert default.trace.y is None and default.trace.S_diag is None and default.trace.K is None
    asked = prepare(path, loaded, Needs.of(ekf=("y",)))
    m = sum(asked.trace.group_sizes)
    assert asked.trace.y.shape == asked.trace.S_diag.shape == (asked.run.n_steps, m)
    updated = np.isfinite(asked.trace.y).any(axis=1)
    # the kept innovations belong to the same filter run: NIS defined exactly where y is
    np.testing.assert_array_equal(updated, np.isfinite(asked.trace.nis))
    np.testing.assert_array_equal(asked.trace.nis, default.trace.nis)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_the_mmap_threshold_is_fixed_on_glibc():
    assert return_freed_arrays_to_the_system() is True
