"""Small input files that a command line, a profile or a sidecar names (tables, baseline,
suppressions, ground truth): read only as regular files under a size limit, and, when a log names
them (its embedded profile), only inside the log's folder.

A FIFO there would block the read forever, a device such as /dev/zero would be read until memory
runs out, and a profile that travels inside a log is the log's author's, not the user's: it may name
a file beside the log, never /etc/... or ../../... (issue 31). The special-file refusal
(`special_kind`) and the words for OS errors (`os_error_text`) live here and the log readers use them
too: checked with ``os.stat`` before opening, and again on the opened descriptor (the path may have
been replaced in between), opened non-blocking.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from logscan.errors import InputError, ProfileError

MB = 1 << 20
MAX_TABLES_BYTES = 256 * MB  # trained tables: A-TFM tables of many windows and modes stay far below
MAX_BASELINE_BYTES = 512 * MB  # a previous `--json` summary of a large fleet
MAX_SUPPRESSIONS_BYTES = 16 * MB
MAX_TRUTH_BYTES = 64 * MB
MAX_PROFILE_SIDECAR_BYTES = 16 * MB  # a CSV log's <log>.profile.toml

_SPECIAL_KINDS = (
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)
SPECIAL_FILE_HINT = "logscan reads regular files only; save the data to a file first"


def special_kind(mode: int) -> str | None:
    """What a non-regular, non-directory ``st_mode`` is ("a FIFO (named pipe)", ...); None for a
    regular file or a directory."""
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    return next((text for test, text in _SPECIAL_KINDS if test(mode)), "a special file")


def os_error_text(exc: OSError, *, directory: bool = False) -> tuple[str, str | None]:
    """(what is wrong, what to do) for an OSError met while reading an input."""
    if isinstance(exc, FileNotFoundError):
        return "no such file", None
    if isinstance(exc, PermissionError):
        if directory:  # listing needs read, reaching the entries needs execute (search) permission
            return (
                "permission denied (cannot list or search the directory)",
                "make it listable and searchable: chmod +rx",
            )
        return "permission denied", "make the file readable (chmod +r) and its directories searchable (chmod +x)"
    if isinstance(exc, IsADirectoryError):
        return "is a directory, not a file", "give a file"
    if isinstance(exc, NotADirectoryError):
        return "a part of the path is not a directory", "check the path"
    if exc.errno == errno.ELOOP:
        return "too many levels of symbolic links", "check the path"
    reason = exc.strerror or str(exc) or type(exc).__name__
    return f"cannot read: {reason}", "check the disk, the network mount or the file system, then retry"


def read_input_bytes(path: str | os.PathLike, *, what: str, limit: int) -> bytes:
    """The bytes of the regular file ``path`` (``what`` names it in messages: "the tables file"),
    at most ``limit`` of them; InputError naming the file otherwise."""
    where = str(path)
    try:
        st = os.stat(path)
    except OSError as exc:
        message, hint = os_error_text(exc)
        raise InputError(f"cannot read {what}: {message}", path=where, hint=hint) from None
    _check_kind(st, what, where, limit)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        message, hint = os_error_text(exc)
        raise InputError(f"cannot read {what}: {message}", path=where, hint=hint) from None
    try:
        _check_kind(os.fstat(fd), what, where, limit)  # the file opened is the one checked
        chunks, size = [], 0
        while size <= limit:
            chunk = os.read(fd, min(limit + 1 - size, 1 << 20))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as exc:
        message, hint = os_error_text(exc)
        raise InputError(f"cannot read {what}: {message}", path=where, hint=hint) from None
    finally:
        os.close(fd)
    if size > limit:  # it grew since the stat
        raise _too_large(what, where, size, limit)
    return b"".join(chunks)


def read_input_text(path: str | os.PathLike, *, what: str, limit: int) -> str:
    """`read_input_bytes` decoded as UTF-8 (InputError naming the file when it is not)."""
    data = read_input_bytes(path, what=what, limit=limit)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(
            f"{what} is not UTF-8 text (bad byte at offset {exc.start})", path=str(path), hint="give the right file"
        ) from None


def _check_kind(st: os.stat_result, what: str, where: str, limit: int) -> None:
    kind = "a directory" if stat.S_ISDIR(st.st_mode) else special_kind(st.st_mode)
    if kind is not None:
        raise InputError(f"{what} is {kind}, not a regular file", path=where, hint=SPECIAL_FILE_HINT)
    if st.st_size > limit:
        raise _too_large(what, where, st.st_size, limit)


def _too_large(what: str, where: str, size: int, limit: int) -> InputError:
    return InputError(
        f"{what} is {size:,} bytes, more than the {limit:,} it may have", path=where, hint="give the right file"
    )


def inside_log_folder(name: str, log_path: str | os.PathLike, *, key: str, source: str) -> str:
    """The path ``name`` (a profile's ``key``, e.g. ``tables``) of a profile embedded in the log
    ``log_path``, resolved in the log's folder; ProfileError (naming ``source``) when it is absolute
    or leads out of that folder (``..``, a symbolic link): a log may only point beside itself."""
    folder = Path(os.path.abspath(log_path)).parent
    hint = f"copy the file into {folder} and name it there, or pass --{key} (your own choice of file)"
    if os.path.isabs(name):
        raise ProfileError(
            f"{key} = {name!r}: a profile embedded in a log may only name a file in the log's folder", path=source,
            hint=hint,
        )  # fmt: skip
    target = folder / name
    real_folder, real_target = os.path.realpath(folder), os.path.realpath(target)
    if os.path.commonpath([real_folder, real_target]) != real_folder or real_target == real_folder:
        raise ProfileError(
            f"{key} = {name!r} leads out of the log's folder: a profile embedded in a log may only name a file "
            "in the log's folder",
            path=source,
            hint=hint,
        )
    return str(target)
