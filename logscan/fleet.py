"""One runner over many logs: log expansion, output naming, per-log failure isolation, one progress
bar, and local processes (`--jobs N`).

    logs = expand_logs(["runs/", "extra.mcap"])
    outcomes = run_many(logs, task, jobs=4, progress=True)   # results in input order

``task`` is any picklable callable of one log path, or of one tuple whose first item is the log
path (`logscan analyze` passes (log, report path) pairs); a module-level function or a
functools.partial of one; it returns what the caller wants back. A log whose task raises becomes a
`LogFailure` in its place and never stops the others. Results do not depend on ``jobs``: each log
is processed by the same task, and outcomes come back in the order of ``logs``.
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

from logscan.errors import InputError, LogscanError, UsageError

# What a directory expands to: log files by suffix, and sub-directories holding per-topic CSVs
# (each such directory is one log). Formats themselves are detected by content (logscan.readers).
LOG_FILE_SUFFIXES = (".mcap", ".ulg")


@dataclass
class LogFailure:
    """A log that could not be processed: one line, and the exit code its error maps to."""

    path: str
    message: str
    exit_code: int = 2


def expand_logs(paths: Sequence[str]) -> list[str]:
    """Files as given; a directory holding log files expands to them (sorted) and to its
    sub-directories of CSVs; a directory of per-topic CSVs (the ulog2csv pieces of one log) stays
    one log; CSVs that are not such pieces are one log per file.

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
        inner = [path / n for n, mode in entries if stat.S_ISREG(mode) and _suffix(n) in LOG_FILE_SUFFIXES]
        special = [path / n for n, mode in entries if _is_special(mode) and _suffix(n) in _SPECIAL_CHECKED]
        inner_dirs = [path / n for n, mode in entries if stat.S_ISDIR(mode)]
        found = (inner or _csv_logs(path, entries)) + [log for d in inner_dirs for log in _csv_logs(d)]
        logs.extend(raw if p == path else str(p) for p in (found + special) or [path])
    return logs


_SPECIAL_CHECKED = (*LOG_FILE_SUFFIXES, ".csv")  # special files named like a log are reported


def _suffix(name: str) -> str:
    return Path(name).suffix.lower()


def _is_special(mode: int) -> bool:
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


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
) -> list[Any]:
    """``task(log)`` for every log, in input order; a failing log yields a LogFailure (with
    ``isolate``; without it the first error propagates, e.g. for one log run in the foreground;
    an `OutputError` always propagates). ``jobs`` > 1 runs the logs in that many local processes,
    which ignore SIGINT: on Ctrl-C, or any error that stops the run, this process stops them
    (terminated and joined) before the exception propagates. ``progress`` shows one bar on stderr."""
    logs = list(logs)
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
        pool = ProcessPoolExecutor(max_workers=min(jobs, len(logs)), initializer=_worker_init)
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


def _worker_init() -> None:
    """Worker processes leave Ctrl-C to the parent, which stops them (SIGTERM) and removes their
    temporary files; on SIGTERM a worker ends its own children first (the background compile,
    logscan.filters.warmup), which would otherwise outlive it."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _end_worker)


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
