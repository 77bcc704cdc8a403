"""`--jobs N` workers start threads (a large CSV's parse) on their share of the cores only: N
workers on C cores C/N each, not C each waiting for a core (`logscan.child_processes.usable_cores`)."""

from __future__ import annotations

import os

import pytest

from logscan import child_processes as cores
from logscan.fleet import run_many


@pytest.fixture
def mask_of(monkeypatch):
    def set_mask(n: int) -> None:
        monkeypatch.setattr(cores.os, "sched_getaffinity", lambda pid: set(range(n)), raising=False)

    monkeypatch.setattr(cores, "_sharers", 1)
    return set_mask


@pytest.mark.parametrize("mask, sharers, expected", [(4, 1, 4), (4, 2, 2), (3, 2, 1), (2, 4, 1), (8, 3, 2)])
def test_a_process_uses_its_share_of_its_affinity_mask(mask_of, mask, sharers, expected):
    mask_of(mask)
    cores.share_cores(sharers)
    assert cores.usable_cores() == expected


def test_without_an_affinity_call_the_machine_s_cores_are_shared(monkeypatch):
    monkeypatch.setattr(cores, "_sharers", 1)
    monkeypatch.delattr(cores.os, "sched_getaffinity", raising=False)
    monkeypatch.setattr(cores.os, "cpu_count", lambda: 6)
    cores.share_cores(2)
    assert cores.usable_cores() == 3


def _cores_here(_log: str) -> tuple[int, int]:
    return os.getpid(), cores.usable_cores()


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity"), reason="needs an affinity mask")
def test_jobs_workers_each_get_their_share_and_the_parent_keeps_all():
    mask = len(os.sched_getaffinity(0))
    outcomes = run_many(["a", "b", "c", "d"], _cores_here, jobs=2, isolate=False)
    assert {pid for pid, _ in outcomes} - {os.getpid()}, "the logs ran in worker processes"
    assert all(share == max(1, mask // 2) for _, share in outcomes)
    assert cores.usable_cores() == mask  # the parent's own share is untouched
