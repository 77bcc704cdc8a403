"""The filter's steps counted while its kernel runs (logscan.pipeline.step_counter): the EKF writes
the steps it has filtered into a counter without holding the GIL, a watcher thread hands them on as
(done, total), and analysing a log reports its filtering step's fraction up to every step."""

from __future__ import annotations

import threading
from pathlib import Path

from logscan.pipeline.step_counter import counted_steps

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_logs" / "quad_healthy.mcap"


def test_the_watcher_reports_the_counter_while_the_block_runs_and_the_end():
    seen: list[tuple[int, int]] = []
    saw_midway = threading.Event()

    def fraction(done: int, total: int) -> None:
        seen.append((done, total))
        if done == 40:
            saw_midway.set()

    with counted_steps(100, fraction, interval=0.005) as counter:
        counter[0] = 40
        assert saw_midway.wait(timeout=60), "the watcher never read the counter while the block ran"
        counter[0] = 100
    assert seen[-1] == (100, 100)
    assert all(total == 100 for _, total in seen)


def test_nobody_listening_starts_no_thread_and_a_failed_block_reports_no_end():
    before = threading.active_count()
    with counted_steps(10, None) as counter:
        assert threading.active_count() == before
        counter[0] = 3
    seen: list[tuple[int, int]] = []
    try:
        with counted_steps(10, lambda d, t: seen.append((d, t)), interval=60.0):
            raise RuntimeError("the filter failed")
    except RuntimeError:
        pass
    assert seen == []


def test_the_ekf_counts_every_step_it_filters():
    import numpy as np

    from logscan.filters.ekf import run_ekf
    from logscan.pipeline.preparation import load_profile_for, prepare
    from logscan.pipeline.stages import needs_of

    loaded = load_profile_for(SAMPLE, None)
    prepared = prepare(SAMPLE, loaded, needs_of([]))
    counter = np.zeros(1, dtype=np.int64)
    run_ekf(prepared.model, prepared.run, steps_done=counter, store_gain=False, store_S=False)
    assert counter[0] == prepared.run.n_steps > 1000


def test_analysing_a_log_reports_the_filtering_steps_up_to_the_last():
    from logscan.pipeline.run import analyze_log

    steps: list[str] = []
    calls: list[tuple[str, int, int]] = []
    analyze_log(
        SAMPLE,
        detector_names=["nis"],
        progress=steps.append,
        fraction=lambda done, total: calls.append((steps[-1], done, total)),
    )
    filtering = [(done, total) for step, done, total in calls if step == "filtering"]
    assert filtering, "the filtering step reported no fraction"
    total = filtering[-1][1]
    assert filtering[-1] == (total, total) and total > 1000
    assert [done for done, _ in filtering] == sorted(done for done, _ in filtering)
