"""Where each log's outputs go (`output_paths`, unique names) and the refusal to overwrite an input
with an output (`refuse_clobbering`)."""

from __future__ import annotations

import os
import stat
from collections.abc import Sequence
from pathlib import Path

from logscan.artifacts import output_error
from logscan.errors import InputError, UsageError
from logscan.fleet.expand import LOG_FILE_SUFFIXES, _suffix
from logscan.readers.common import list_directory


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
        path = Path(os.path.abspath(log))  # "." names its folder
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
    return list_directory(path)


def _file_id(path: str) -> tuple[int, int] | None:
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return (st.st_dev, st.st_ino)
