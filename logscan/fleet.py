"""One runner over many logs: log expansion, output naming, per-log failure isolation, one progress
bar, and local processes (`--jobs N`).

    logs = expand_logs(["runs/", "extra.mcap"])
    outcomes = run_many(logs, task, jobs=4, progress=True)   # results in input order

``task`` is any picklable callable of one log path (a module-level function or a
functools.partial of one); it returns what the caller wants back. A log whose task raises becomes a
`LogFailure` in its place and never stops the others. Results do not depend on ``jobs``: each log
is processed by the same task, and outcomes come back in the order of ``logs``.
"""

from __future__ import annotations

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
    the current directory); logs of the same name get their parent directory's name as a prefix."""
    names = [f"{Path(log.rstrip('/')).stem}{suffix}" for log in logs]
    if len(set(names)) != len(names):
        names = [f"{Path(log.rstrip('/')).parent.name}_{n}" for log, n in zip(logs, names)]
    if output is None:
        return names
    if len(logs) == 1 and not Path(output).is_dir():
        return [output]
    directory = Path(output)
    if directory.exists() and not directory.is_dir():
        raise UsageError(f"--output {output} is a file, but {len(logs)} logs need a directory")
    directory.mkdir(parents=True, exist_ok=True)
    return [str(directory / name) for name in names]


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


def _isolated(task: Callable[[str], Any], path: str) -> Any:
    try:
        return task(path)
    except Exception as exc:  # noqa: BLE001 - one bad log must not stop the others
        return failure_of(path, exc)


def run_many(
    logs: Sequence[str],
    task: Callable[[str], Any],
    *,
    jobs: int = 1,
    progress: bool = False,
    label: str = "logs",
    isolate: bool = True,
) -> list[Any]:
    """``task(log)`` for every log, in input order; a failing log yields a LogFailure (with
    ``isolate``; without it the first error propagates, e.g. for one log run in the foreground).
    ``jobs`` > 1 runs the logs in that many local processes. ``progress`` shows one bar on stderr."""
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
        with ProcessPoolExecutor(max_workers=min(jobs, len(logs))) as pool:
            futures = {pool.submit(_isolated if isolate else _call, task, path): i for i, path in enumerate(logs)}
            for future in as_completed(futures):
                outcomes[futures[future]] = future.result()
                if bar:
                    bar.update(1)
        return outcomes
    finally:
        if bar:
            bar.render_finish()


def _call(task: Callable[[str], Any], path: str) -> Any:
    return task(path)


def _progress_bar(total: int, label: str):
    import click

    bar = click.progressbar(length=total, label=label, file=sys.stderr, show_pos=True)
    bar.render_progress()
    return bar
