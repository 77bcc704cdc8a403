"""One runner over many logs: log expansion, output naming, per-log failure isolation, one progress
bar, local processes (`--jobs N`) and a Dask cluster (`--scheduler ADDRESS`).

    logs = expand_logs(["runs/", "extra.mcap"])
    outcomes = run_many(logs, task, jobs=4, progress=True)   # results in input order

``task`` is any picklable callable of one log path, or of one tuple whose first item is the log
path (`logscan analyze` passes (log, report path) pairs); a module-level function or a
functools.partial of one; it returns what the caller wants back. A log whose task raises becomes a
`LogFailure` in its place and never stops the others. Results do not depend on ``jobs``: each log
is processed by the same task, and outcomes come back in the order of ``logs``.

With ``scheduler`` (``tcp://host:8786``, or ``local:N`` for a LocalCluster of N worker processes
started for the run) the same task runs on Dask workers (`run_on_dask`): same outcomes, same order.
Workers must see the logs and the output directories at the same paths (a shared file system).
"""

from __future__ import annotations

import os
import stat
import sys
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from logscan.errors import InputError, LogscanError, OutOfMemoryError, UsageError

# What a directory expands to: log files by suffix, rosbag2 directories (a `metadata.yaml` inside:
# one log each) and sub-directories holding per-topic CSVs (each such directory is one log).
# Formats themselves are detected by content (logscan.readers).
LOG_FILE_SUFFIXES = (".mcap", ".ulg", ".bag", ".db3")
ROSBAG2_METADATA = "metadata.yaml"


@dataclass
class LogFailure:
    """A log that could not be processed: one line, and the exit code its error maps to."""

    path: str
    message: str
    exit_code: int = 2


def expand_logs(paths: Sequence[str]) -> list[str]:
    """Files as given; a directory holding log files expands to them (sorted), to its rosbag2
    sub-directories and to its sub-directories of CSVs; a rosbag2 directory (its `metadata.yaml`)
    and a directory of per-topic CSVs (the ulog2csv pieces of one log) stay one log; CSVs that are
    not such pieces are one log per file.

    Only regular files are logs, and nothing is opened here. An entry named like a log (``.mcap``,
    ``.ulg``, ``.csv``) that is a FIFO, device or socket, and a directory or sub-directory that
    cannot be listed or searched, are listed as logs of their own: each fails with one line
    (exit 2) when it is read, and the other logs still run."""
    from logscan.readers.common import list_directory

    logs: list[str] = []
    for raw in paths:
        path = Path(raw)
        if not path.is_dir():
            logs.append(raw)
            continue
        try:
            entries = sorted(list_directory(path))
        except InputError:
            logs.append(raw)
            continue
        if _is_rosbag2(entries):  # one ROS 2 bag: its storage files are pieces of it
            logs.append(raw)
            continue
        inner = [path / n for n, mode in entries if stat.S_ISREG(mode) and _suffix(n) in LOG_FILE_SUFFIXES]
        special = [path / n for n, mode in entries if _is_special(mode) and _suffix(n) in _SPECIAL_CHECKED]
        inner_dirs = [path / n for n, mode in entries if stat.S_ISDIR(mode)]
        found = (inner or _csv_logs(path, entries)) + [log for d in inner_dirs for log in _dir_logs(d)]
        logs.extend(raw if p == path else str(p) for p in (found + special) or [path])
    return logs


_SPECIAL_CHECKED = (*LOG_FILE_SUFFIXES, ".csv")  # special files named like a log are reported


def _suffix(name: str) -> str:
    return Path(name).suffix.lower()


def _is_special(mode: int) -> bool:
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def _is_rosbag2(entries: list[tuple[str, int]]) -> bool:
    return any(name == ROSBAG2_METADATA and stat.S_ISREG(mode) for name, mode in entries)


def _dir_logs(directory: Path) -> list[Path]:
    """A sub-directory's logs: itself when it is a rosbag2 directory, else its CSV logs."""
    from logscan.readers.common import list_directory

    try:
        entries = list_directory(directory)
    except InputError:  # reading it will say why
        return [directory]
    return [directory] if _is_rosbag2(entries) else _csv_logs(directory, entries)


def _csv_logs(directory: Path, entries: list[tuple[str, int]] | None = None) -> list[Path]:
    """The directory when its CSVs are the pieces of one log, else its CSV files (one log each);
    none when it holds no regular ``.csv`` file."""
    from logscan.readers.common import list_directory
    from logscan.readers.csv_reader import csv_files, csv_log_name

    if entries is None:
        try:
            entries = list_directory(directory)
        except InputError:  # reading it will say why
            return [directory]
    if not any(stat.S_ISREG(mode) and _suffix(name) == ".csv" for name, mode in entries):
        return []
    files = csv_files(directory)
    if files and not csv_log_name(directory, files):
        return files
    return [directory] if files else []


def output_paths(logs: Sequence[str], output: str | None, suffix: str = ".report.html") -> list[str]:
    """Output file per log: ``output`` itself for one log, else ``output/<name><suffix>`` (default:
    the current directory). Names never clash: when two logs have the same name (ignoring case, as
    some file systems do) every name gets its parent directory's name as a prefix, and a name that
    still clashes gets a number (``run-2``)."""
    names = unique_names(logs, suffix)
    if output is None:
        return names
    if len(logs) == 1 and not Path(output).is_dir():
        return [output]
    directory = Path(output)
    if directory.exists() and not directory.is_dir():
        raise UsageError(f"--output {output} is a file, but {len(logs)} logs need a directory")
    if not directory.exists() and not output.endswith(("/", os.sep)):
        # `-o two.html` for several logs is a mistake, not a directory to create
        raise UsageError(
            f"--output {output} does not exist, and {len(logs)} logs need a directory",
            hint=f"give an existing directory, or end the name with / to create it (-o {output}/)",
        )
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        from logscan.artifacts import output_error

        raise output_error(exc, directory) from None
    return [str(directory / name) for name in names]


def unique_names(logs: Sequence[str], suffix: str) -> list[str]:
    """``<log stem><suffix>`` per log, made unique as `output_paths` says."""
    stems = [Path(log.rstrip("/") or log).stem for log in logs]
    folded = [stem.casefold() for stem in stems]
    if len(set(folded)) != len(folded):
        stems = [f"{_parent_name(log)}_{stem}" for log, stem in zip(logs, stems)]
    names, taken = [], set()
    for stem in stems:
        name, number = stem, 2
        while name.casefold() in taken:
            name, number = f"{stem}-{number}", number + 1
        taken.add(name.casefold())
        names.append(name + suffix)
    return names


def _parent_name(log: str) -> str:
    parent = Path(log.rstrip("/") or log).parent
    return parent.name or Path(os.path.abspath(parent)).name or "root"


# Outputs named like these would be read as a log or a profile by the next run (or replace one)
LOG_LIKE_SUFFIXES = (*LOG_FILE_SUFFIXES, ".csv", ".toml")


def refuse_clobbering(
    outputs: Sequence[tuple[str, str | None]], logs: Sequence[str], profile: str | None = None
) -> None:
    """Raise UsageError (before any work) when an output would replace an input or another output.

    ``outputs``: (option, path) pairs; None and "-" (stdout) are skipped. Inputs are the logs, their
    ``.truth.json`` / ``.profile.toml`` sidecars, the files of a log directory, and the profile.
    The same file is found by device and inode (hard links, symbolic links, a case-insensitive
    file system) when it exists, else by resolved path. An output named like a log or a profile
    (``.mcap``, ``.ulg``, ``.csv``, ``.toml``) is refused as well."""
    inputs = _input_files(logs, profile)
    seen_ids = {key: ("input", path) for path in inputs if (key := _file_id(path)) is not None}
    seen_paths = {os.path.realpath(path): ("input", path) for path in inputs}
    for option, path in outputs:
        if path is None or path == "-" or _is_char_device(path):  # /dev/null may take every output
            continue
        key, resolved = _file_id(path), os.path.realpath(path)
        clash = (seen_ids.get(key) if key is not None else None) or seen_paths.get(resolved)
        if clash is not None and clash[0] == "input":
            raise UsageError(
                f"{option} {path} would replace the input {clash[1]}",
                hint="inputs are never modified: give another output path",
            )
        if clash is not None:
            raise UsageError(
                f"{option} {path} is the same file as {clash[0]} {clash[1]}", hint="give each output its own path"
            )
        if _suffix(path) in LOG_LIKE_SUFFIXES:
            raise UsageError(
                f"{option} {path} is named like a log or a profile",
                hint="give the output another name, e.g. .html for a report or .json for the summary",
            )
        if key is not None:
            seen_ids[key] = (option, path)
        seen_paths[resolved] = (option, path)


def _is_char_device(path: str) -> bool:
    try:
        return stat.S_ISCHR(os.stat(path).st_mode)
    except OSError:
        return False


def _input_files(logs: Sequence[str], profile: str | None) -> list[str]:
    files = [profile] if profile else []
    for log in logs:
        path = Path(log)
        files.append(log)
        for suffix in (".truth.json", ".profile.toml"):  # the CSV reader's sidecars
            files.append(str(path.with_name(path.name + suffix) if path.is_dir() else path.with_suffix(suffix)))
        if path.is_dir():
            try:
                files.extend(str(path / name) for name, mode in _listing(path) if stat.S_ISREG(mode))
            except InputError:
                pass
    return files


def _listing(path: Path) -> list[tuple[str, int]]:
    from logscan.readers.common import list_directory

    return list_directory(path)


def _file_id(path: str) -> tuple[int, int] | None:
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return (st.st_dev, st.st_ino)


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


def _isolated(task: Callable[[Any], Any], item: Any) -> Any:
    from logscan.artifacts import OutputError

    try:
        return task(item)
    except OutputError:
        raise  # the outputs cannot be written (disk full, read-only): no log can succeed, stop the run
    except Exception as exc:  # noqa: BLE001 - one bad log must not stop the others
        return failure_of(log_of(item), exc)  # the log's path, never the tuple's repr


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
        pool = ProcessPoolExecutor(max_workers=min(jobs, len(logs)), initializer=_worker_init, initargs=(os.getpid(),))
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


def _worker_init(parent_pid: int | None = None) -> None:
    """Worker processes leave Ctrl-C to the parent, which stops them (SIGTERM) and removes their
    temporary files; on SIGTERM a worker ends its own children first (the background compile,
    logscan.filters.warmup), which would otherwise outlive it. A worker whose parent dies (killed
    alone) ends too (`logscan.fleet_workers`)."""
    import signal

    from logscan.fleet_workers import exit_with_parent

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


def _progress_bar(total: int, label: str):
    import click

    bar = click.progressbar(length=total, label=label, file=sys.stderr, show_pos=True)
    bar.render_progress()
    return bar


# --scheduler: a Dask cluster. A task that raises is retried this many times by distributed (with
# ``isolate`` a log's error is its LogFailure, so only errors that stop the run, such as OutputError,
# raise); a log whose worker died (KilledWorker, after distributed.scheduler.allowed-failures) is
# resubmitted this many more times before it becomes a LogFailure.
TASK_RETRIES = 1
KILLED_WORKER_RESUBMITS = 2
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
    from distributed.scheduler import KilledWorker

    logs = list(logs)
    function = _isolated if isolate else _captured
    bar = _progress_bar(len(logs), label) if progress and len(logs) > 1 else None
    try:
        with _DaskClient(scheduler) as client:
            futures = {}
            attempts = [1] * len(logs)

            def submit(index: int):
                future = client.submit(function, task, logs[index], pure=False, retries=TASK_RETRIES)
                futures[future] = index
                return future

            pending = as_completed([submit(i) for i in range(len(logs))])
            outcomes: list[Any] = [None] * len(logs)
            done = [False] * len(logs)
            errors: dict[int, BaseException] = {}
            try:
                for future in pending:
                    index = futures.pop(future)
                    try:
                        outcome = future.result()
                        if isinstance(outcome, _Raised):
                            raise outcome.error
                        outcomes[index] = outcome
                    except KilledWorker as exc:
                        if attempts[index] <= KILLED_WORKER_RESUBMITS:
                            attempts[index] += 1
                            pending.add(submit(index))
                            continue
                        failure = _worker_died(log_of(logs[index]), attempts[index], exc)
                        if not isolate:
                            errors[index] = _worker_died_error(failure)
                        outcomes[index] = failure
                    except Exception as exc:  # raised by the task (isolate: only what stops the run)
                        from logscan.artifacts import OutputError

                        if not isolate:
                            errors[index] = exc
                        elif isinstance(exc, OutputError):
                            raise
                        else:  # e.g. an outcome that could not be sent back
                            outcomes[index] = failure_of(log_of(logs[index]), exc)
                    done[index] = True
                    if bar:
                        bar.update(1)
                    if errors:
                        first = min(errors)
                        if all(done[:first]):
                            raise errors[first]
            except BaseException:
                client.cancel(list(futures))
                raise
            return outcomes
    finally:
        if bar:
            bar.render_finish()


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
    from logscan.errors import InternalError

    return InternalError(failure.message)
