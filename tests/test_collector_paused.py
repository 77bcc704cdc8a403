"""The cyclic collector paused where many objects are made at once (`logscan.memory.collector_paused`): a ULog
read sets off no collection while it makes its channels (one at most, once it is done), and the
collector is left as it was."""

from __future__ import annotations

import gc

import pytest
from conftest import need_testdata

from logscan.memory import collector_paused
from logscan.readers.ulog_reader import read_ulog


@pytest.fixture
def collections():
    """The collections started while the test runs (gc.callbacks' "start" phases)."""
    started: list[int] = []
    gc.collect()  # an empty youngest generation: a collection set off before the read is not counted

    def count(phase: str, info: dict) -> None:
        if phase == "start":
            started.append(info["generation"])

    gc.callbacks.append(count)
    yield started
    gc.callbacks.remove(count)


def test_a_ulog_read_sets_off_one_collection_at_most(collections):
    path = need_testdata("px4-ulog-extra/robologs_fmu_v5_test.ulg")  # 2,479 channels
    assert gc.isenabled()
    log = read_ulog(path, None)
    assert len(log.channels) > 2000  # enough objects to set off collections were it not paused
    # without the pause 131 collections here; with it at most the one the collector, back on,
    # makes of what the read left
    assert len(collections) <= 1
    assert gc.isenabled()


def test_paused_collector_comes_back_as_it_was(collections):
    gc.disable()
    try:
        with collector_paused():
            assert not gc.isenabled()
        assert not gc.isenabled()  # it was off: it stays off
    finally:
        gc.enable()
    with pytest.raises(ValueError), collector_paused():
        raise ValueError("inside")
    assert gc.isenabled()  # back on after an error too
    objects = [[] for _ in range(10 * gc.get_threshold()[0])]
    assert collections  # and collecting again
    del objects
