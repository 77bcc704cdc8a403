"""Many logs on a Dask cluster (`run_on_dask`, `--scheduler ADDRESS`): same task, same outcomes,
same order as `run_many`."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from logscan.artifacts import OutputError
from logscan.child_processes import share_cores
from logscan.errors import UsageError
from logscan.fleet.failures import (
    KILLED_WORKER_RESUBMITS,
    TASK_RETRIES,
    _captured,
    _isolated,
    _progress_bar,
    _Raised,
    _worker_died,
    _worker_died_error,
    failure_of,
    log_of,
)

DASK_EXTRA_MESSAGE = "--scheduler needs the dask extra: pip install 'logscan[dask]'"


def check_scheduler(address: str) -> str:
    """``address`` when it is ``local:N`` (N >= 1) or a scheduler URL (``tcp://host:port``, any
    ``scheme://``); UsageError otherwise, or when distributed is not installed."""
    import importlib.util

    if importlib.util.find_spec("distributed") is None:
        raise UsageError(DASK_EXTRA_MESSAGE)
    if address.startswith("local:"):
        count = address.removeprefix("local:")
        if not count.isdigit() or int(count) < 1:
            raise UsageError(f"--scheduler {address}: local:N needs a number of workers N >= 1")
        return address
    if "://" not in address or not address.split("://", 1)[1]:
        raise UsageError(
            f"--scheduler {address} is not a scheduler address",
            hint="give tcp://HOST:PORT (a running dask scheduler) or local:N (N local worker processes)",
        )
    return address


CONNECT_TIMEOUT_S = 10.0  # at most, to reach a --scheduler (less if distributed.comm.timeouts.connect says so)


def _connect_timeout_s() -> float:
    import dask
    from dask.utils import parse_timedelta

    configured = parse_timedelta(dask.config.get("distributed.comm.timeouts.connect"), default="seconds")
    return min(CONNECT_TIMEOUT_S, configured or CONNECT_TIMEOUT_S)


class _DaskClient:
    """A distributed.Client for ``address`` (a LocalCluster started for ``local:N``), closed on exit
    with the cluster it started. A scheduler that cannot be reached within distributed's connect
    timeout (distributed.comm.timeouts.connect) is a UsageError."""

    def __init__(self, address: str):
        self.address = check_scheduler(address)
        self.cluster = None
        self.client = None

    def __enter__(self):
        import logging

        from distributed import Client, LocalCluster

        logging.getLogger("distributed").setLevel(logging.ERROR)  # the run's own output stays readable
        if self.address.startswith("local:"):
            workers = int(self.address.removeprefix("local:"))
            self.cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
            self.client = Client(self.cluster)
            self.client.run(share_cores, workers)  # the workers share this machine's cores
            return self.client
        try:
            self.client = Client(self.address, timeout=_connect_timeout_s())
        except (OSError, TimeoutError, ValueError) as exc:
            reason = (str(exc).splitlines() or [type(exc).__name__])[0]
            raise UsageError(
                f"--scheduler {self.address}: cannot connect to the scheduler ({reason})",
                hint="start one with `dask scheduler` and its workers with `dask worker ADDRESS`, or use local:N",
            ) from None
        return self.client

    def __exit__(self, *exc_info) -> None:
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def run_on_dask(
    logs: Sequence[Any],
    task: Callable[[Any], Any],
    *,
    scheduler: str,
    progress: bool = False,
    label: str = "logs",
    isolate: bool = True,
) -> list[Any]:
    """`run_many` on a Dask cluster: ``client.submit`` of the same per-log call, outcomes in the
    order of ``logs`` (the same objects as local runs), progress as they complete. A log whose worker
    died is resubmitted (`KILLED_WORKER_RESUBMITS` times), then is a LogFailure saying so (exit 3);
    without ``isolate`` the error of the first log in input order propagates, once every log before
    it has completed. On Ctrl-C or an error that stops the run the logs still queued are cancelled."""
    from distributed import as_completed

    logs = list(logs)
    function = _isolated if isolate else _captured
    bar = _progress_bar(len(logs), label) if progress and len(logs) > 1 else None
    try:
        with _DaskClient(scheduler) as client:
            futures = {}

            def submit(index: int):
                future = client.submit(function, task, logs[index], pure=False, retries=TASK_RETRIES)
                futures[future] = index
                return future

            pending = as_completed([submit(i) for i in range(len(logs))])
            collected = _Outcomes(logs, isolate)
            try:
                for future in pending:
                    index = futures.pop(future)
                    if not collected.record(index, future, lambda i: pending.add(submit(i))):
                        continue  # resubmitted: its worker died
                    if bar:
                        bar.update(1)
                    collected.raise_first_error()
            except BaseException:
                client.cancel(list(futures))
                raise
            return collected.outcomes
    finally:
        if bar:
            bar.render_finish()


class _Outcomes:
    """The outcomes of a run on Dask in the order of the logs, recorded as their futures complete,
    and the errors that stop it (without ``isolate``)."""

    def __init__(self, logs: list[Any], isolate: bool):
        self.logs, self.isolate = logs, isolate
        self.outcomes: list[Any] = [None] * len(logs)
        self.done = [False] * len(logs)
        self.attempts = [1] * len(logs)
        self.errors: dict[int, BaseException] = {}

    def record(self, index: int, future, resubmit: Callable[[int], Any]) -> bool:
        """Record the outcome of log ``index`` from its completed future; False when its worker
        died and ``resubmit(index)`` ran it again instead (`KILLED_WORKER_RESUBMITS` times)."""
        from distributed.scheduler import KilledWorker

        try:
            outcome = future.result()
            if isinstance(outcome, _Raised):
                raise outcome.error
            self.outcomes[index] = outcome
        except KilledWorker as exc:
            if self.attempts[index] <= KILLED_WORKER_RESUBMITS:
                self.attempts[index] += 1
                resubmit(index)
                return False
            failure = _worker_died(log_of(self.logs[index]), self.attempts[index], exc)
            if not self.isolate:
                self.errors[index] = _worker_died_error(failure)
            self.outcomes[index] = failure
        except Exception as exc:  # raised by the task (isolate: only what stops the run)
            if not self.isolate:
                self.errors[index] = exc
            elif isinstance(exc, OutputError):
                raise
            else:  # e.g. an outcome that could not be sent back
                self.outcomes[index] = failure_of(log_of(self.logs[index]), exc)
        self.done[index] = True
        return True

    def raise_first_error(self) -> None:
        """The error of the first log in input order, once every log before it has completed."""
        if self.errors:
            first = min(self.errors)
            if all(self.done[:first]):
                raise self.errors[first]
