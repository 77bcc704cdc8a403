"""What every way of running many logs shares: a log that could not be processed (`LogFailure`,
from the exception its task raised or a worker that died under it), a task run with its failure
isolated, the one progress bar."""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from logscan.artifacts import OutputError
from logscan.errors import InternalError, LogscanError, OutOfMemoryError


@dataclass
class LogFailure:
    """A log that could not be processed: one line, and the exit code its error maps to."""

    path: str
    message: str
    exit_code: int = 2


def failure_of(path: str, exc: BaseException) -> LogFailure:
    """The one line a failed log becomes (LogscanError: its message; anything else: a bug)."""
    if isinstance(exc, MemoryError):  # the machine is too small for this log: not a bug
        exc = OutOfMemoryError()
    if isinstance(exc, LogscanError):
        line = exc.one_line() if exc.path else f"{path}: {exc.one_line()}"
        return LogFailure(path, line, exc.exit_code)
    return LogFailure(
        path,
        f"{path}: internal error: {type(exc).__name__}: {exc} "
        "(a bug in logscan; rerun this log alone with `logscan --debug` for the traceback)",
        3,
    )


def log_of(item: Any) -> str:
    """The log path of one of `run_many`'s items: the item, or the first item of a tuple."""
    return str(item[0] if isinstance(item, tuple) else item)


@dataclass
class _Raised:
    """The error a task raised, sent back as its outcome (not retried, nor logged by the worker:
    a log's error is deterministic, and the command prints it)."""

    error: Exception


def _captured(task: Callable[[Any], Any], item: Any) -> Any:
    try:
        return task(item)
    except Exception as exc:  # noqa: BLE001 - raised in the client (run_on_dask)
        return _Raised(exc)


def _worker_died(path: str, attempts: int, exc: BaseException) -> LogFailure:
    return LogFailure(
        path,
        f"{path}: the Dask worker processing it died ({attempts} attempt(s); {type(exc).__name__}) "
        "(out of memory, or killed; rerun this log alone with `logscan --debug`)",
        3,
    )


def _worker_died_error(failure: LogFailure) -> LogscanError:
    return InternalError(failure.message)


# --scheduler: a Dask cluster. A task that raises is retried this many times by distributed (with
# ``isolate`` a log's error is its LogFailure, so only errors that stop the run, such as OutputError,
# raise); a log whose worker died (KilledWorker, after distributed.scheduler.allowed-failures) is
# resubmitted this many more times before it becomes a LogFailure.
TASK_RETRIES = 1

KILLED_WORKER_RESUBMITS = 2


def _isolated(task: Callable[[Any], Any], item: Any) -> Any:
    try:
        return task(item)
    except OutputError:
        raise  # the outputs cannot be written (disk full, read-only): no log can succeed, stop the run
    except Exception as exc:  # noqa: BLE001 - one bad log must not stop the others
        return failure_of(log_of(item), exc)  # the log's path, never the tuple's repr


def _progress_bar(total: int, label: str):
    import click

    bar = click.progressbar(length=total, label=label, file=sys.stderr, show_pos=True)
    bar.render_progress()
    return bar
