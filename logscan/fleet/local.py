"""Many logs in local processes (`run_many`, `--jobs N`): one progress bar, per-log failure
isolation, workers that end with their parent and are resubmitted when killed."""

from __future__ import annotations

import gc
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any

from logscan.child_processes import exit_with_parent, share_cores
from logscan.fleet.dask import run_on_dask
from logscan.fleet.failures import (
    _isolated,
    _progress_bar,
)
from logscan.numba_cache import initialise_jit


def run_many(
    logs: Sequence[Any],
    task: Callable[[Any], Any],
    *,
    jobs: int = 1,
    progress: bool = False,
    label: str = "logs",
    isolate: bool = True,
    scheduler: str | None = None,
) -> list[Any]:
    """``task(log)`` for every log, in input order; a failing log yields a LogFailure (with
    ``isolate``; without it the first error propagates, e.g. for one log run in the foreground;
    an `OutputError` always propagates). ``jobs`` > 1 runs the logs in that many local processes,
    which ignore SIGINT: on Ctrl-C, or any error that stops the run, this process stops them
    (terminated and joined) before the exception propagates. ``scheduler``: the logs run on that
    Dask cluster instead (`run_on_dask`). ``progress`` shows one bar on stderr."""
    logs = list(logs)
    if scheduler is not None:
        return run_on_dask(logs, task, scheduler=scheduler, progress=progress, label=label, isolate=isolate)
    call = (lambda path: _isolated(task, path)) if isolate else task
    bar = _progress_bar(len(logs), label) if progress and len(logs) > 1 else None
    try:
        if jobs <= 1 or len(logs) <= 1:
            outcomes = []
            for path in logs:
                outcomes.append(call(path))
                if bar:
                    bar.update(1)
            return outcomes
        outcomes: list[Any] = [None] * len(logs)
        initialise_jit()  # once here, inherited by the forked workers (not once in each)
        _warm_up(task, logs)
        workers = min(jobs, len(logs))
        pool = ProcessPoolExecutor(max_workers=workers, initializer=_worker_init, initargs=(os.getpid(), workers))
        try:
            futures = {pool.submit(_isolated if isolate else _call, task, path): i for i, path in enumerate(logs)}
            for future in as_completed(futures):
                outcomes[futures[future]] = future.result()
                if bar:
                    bar.update(1)
        except BaseException:
            _stop(pool)
            raise
        pool.shutdown()
        return outcomes
    finally:
        if bar:
            bar.render_finish()


def _warm_up(task: Callable[[Any], Any], logs: list[Any]) -> None:
    """The task's ``warm_up(logs)``, when it has one (`logscan.tasks.AnalyzeTask.warm_up`: the
    kernels of the first log's analysis): what every worker's first log would load, loaded once
    here before the fork. When the caller froze its objects for the collector (`gc.freeze`, as
    `logscan analyze` does), the warm-up's join them: the workers share those pages instead of
    copying them as their collector walks them; `gc.unfreeze` releases both."""
    warm_up = getattr(task, "warm_up", None)
    if warm_up is None:
        return
    frozen = gc.get_freeze_count() > 0
    warm_up(logs)
    if frozen:
        gc.freeze()


def _worker_init(parent_pid: int | None = None, workers: int = 1) -> None:
    """Worker processes leave Ctrl-C to the parent, which stops them (SIGTERM) and removes their
    temporary files; on SIGTERM a worker ends its own children first (the background compile,
    logscan.filters.warmup), which would otherwise outlive it. A worker whose parent dies (killed
    alone) ends too (`logscan.child_processes`). Each of the ``workers`` starts threads (a large
    CSV's parse) on its share of the cores only (`logscan.child_processes.usable_cores`)."""
    import signal

    share_cores(workers)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _end_worker)
    if parent_pid is not None:
        exit_with_parent(parent_pid)


def _end_worker(signum, frame) -> None:
    import multiprocessing

    for child in multiprocessing.active_children():
        child.terminate()
    os._exit(128 + signum)


def _stop(pool: ProcessPoolExecutor) -> None:
    """Cancel the queued logs and terminate the running workers (the executor's process table is
    private, but it is the only way to stop a task that is running), then wait for them."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    for process in processes:
        process.join(timeout=10)


def _call(task: Callable[[str], Any], path: str) -> Any:
    return task(path)
