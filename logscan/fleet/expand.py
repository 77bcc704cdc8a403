"""What the logs of a command line are: files as given, folders expanded to their logs (by suffix),
rosbag2 directories and folders of per-topic CSVs each one log."""

from __future__ import annotations

import stat
from collections.abc import Sequence
from pathlib import Path

from logscan.errors import InputError
from logscan.readers.common import list_directory
from logscan.readers.csv_reader import csv_files, csv_log_name

# What a directory expands to: log files by suffix, rosbag2 directories (a `metadata.yaml` inside:
# one log each) and sub-directories holding per-topic CSVs (each such directory is one log).
# Formats themselves are detected by content (logscan.readers).
LOG_FILE_SUFFIXES = (".mcap", ".ulg", ".bag", ".db3")
ROSBAG2_METADATA = "metadata.yaml"


def expand_logs(paths: Sequence[str]) -> list[str]:
    """Files as given; a directory holding log files expands to them (sorted), to its rosbag2
    sub-directories and to its sub-directories of CSVs; a rosbag2 directory (its `metadata.yaml`)
    and a directory of per-topic CSVs (the ulog2csv pieces of one log) stay one log; CSVs that are
    not such pieces are one log per file.

    Only regular files are logs, and nothing is opened here. An entry named like a log (``.mcap``,
    ``.ulg``, ``.csv``) that is a FIFO, device or socket, and a directory or sub-directory that
    cannot be listed or searched, are listed as logs of their own: each fails with one line
    (exit 2) when it is read, and the other logs still run."""
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
    try:
        entries = list_directory(directory)
    except InputError:  # reading it will say why
        return [directory]
    return [directory] if _is_rosbag2(entries) else _csv_logs(directory, entries)


def _csv_logs(directory: Path, entries: list[tuple[str, int]] | None = None) -> list[Path]:
    """The directory when its CSVs are the pieces of one log, else its CSV files (one log each);
    none when it holds no regular ``.csv`` file."""
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
