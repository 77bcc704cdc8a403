"""Writing outputs atomically (temp file + rename), so nothing already written is ever corrupted.

One file: `write_atomic` (or `write_json`). Several files that belong together (the reports and the
JSON of one `logscan analyze` run): `stage` each into a temporary file beside its target, then
`commit` them all at the end, or `discard` them. What a failure leaves:

- an error while writing (permissions, read-only file system, disk full, quota, file-size limit)
  is an `OutputError` (exit 2, one line with the path and what to do); the temporary files are
  removed and the previous files at the targets are untouched;
- an error while renaming puts the files already replaced back (from hard-linked copies), so
  either every target is new or every target is as before;
- SIGINT, SIGTERM and SIGHUP are held back during the renames (delivered right after), so an
  interrupted run leaves all previous files or all new ones. Only SIGKILL or a power cut in the
  few microseconds of the renames themselves can leave some targets new and some old (POSIX has
  no rename of several files at once); the JSON is renamed last, so a new JSON means new reports.
  Such a kill also leaves its ``.<name>.<pid>-<hex>.*.tmp`` temporary files behind (every
  temporary file and backup names the process that wrote it); the next run writing anything into
  that folder removes them (`remove_dead_temporaries`: the pid names a process that is gone).

A target that exists and is not a regular file is never replaced: a FIFO or a character device
(``/dev/null``, a terminal), or a path naming an open file descriptor (``/dev/stdout``,
``/dev/fd/N``), is written into directly by `commit`, after the renames (the data waits in
memory; opening a FIFO waits for its reader, with Ctrl-C working). What was written there cannot
be taken back, but a failed or interrupted direct write still puts the renamed targets back. A
directory, a socket or a block device as a target is an `OutputError` (see `check_target`).
"""

from __future__ import annotations

import errno
import io
import json
import os
import re
import secrets
import signal
import stat
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import IO, Any, BinaryIO, NamedTuple, cast

from logscan.errors import INTERRUPT_SEEN, LogscanError
from logscan.json_policy import jsonable

# errno -> (what is wrong, what to do) for the write-side errors a user can fix
_WRITE_ERRORS = {
    errno.EACCES: ("permission denied", "choose a writable location or fix the directory's permissions"),
    errno.EPERM: ("operation not permitted", "choose a writable location or fix the directory's permissions"),
    errno.EROFS: ("the file system is read-only", "write the outputs to a writable location"),
    errno.ENOSPC: ("no space left on the device", "free some space or write the outputs elsewhere"),
    errno.EDQUOT: ("disk quota exceeded", "free some space or write the outputs elsewhere"),
    errno.EFBIG: ("file too large for the file-size limit (ulimit -f) or the file system",
                  "raise the limit or write the outputs elsewhere"),
    errno.EISDIR: ("is a directory", "give a file name"),
    errno.ENOTDIR: ("a part of the path is not a directory", "give a path in an existing directory"),
    errno.ENOENT: ("the directory does not exist", "create it or give another path"),
    errno.ENAMETOOLONG: ("the file name is too long", "give a shorter path"),
    errno.EIO: ("input/output error on the device", "check the disk, or write the outputs elsewhere"),
    errno.EPIPE: ("the reader of the pipe closed it", "keep the pipe's reader running until logscan ends"),
}  # fmt: skip


class OutputError(LogscanError):
    """An output cannot be written (permissions, read-only or full file system, size limit)."""


class Staged(NamedTuple):
    """A complete temporary file beside its target, waiting for `commit`; or, for a target that is
    a FIFO or a device (``tmp`` None), the ``data`` `commit` writes into it."""

    tmp: str | None
    target: str
    data: bytes | None = None


def describe_os_error(exc: OSError) -> tuple[str, str | None]:
    """(what is wrong, what to do) for an OSError: the errno's words and hint when known."""
    if exc.errno in _WRITE_ERRORS:
        return _WRITE_ERRORS[exc.errno]
    return (exc.strerror or str(exc) or type(exc).__name__), None


def output_error(exc: OSError, path: str | os.PathLike) -> OutputError:
    """The one-line error for an OSError met while writing ``path``."""
    what, hint = describe_os_error(exc)
    if exc.errno == errno.ENOENT and os.path.isdir(os.path.dirname(os.path.abspath(path))):
        # the directory is there but refuses new files (a virtual file system such as /proc)
        what, hint = "the directory does not take new files", "give a path in an ordinary directory"
    return OutputError(f"cannot write the output: {what}", path=str(path), hint=hint)


def new_token() -> str:
    """A tag for the temporary files of one run: `cleanup` finds them by it, even those a worker
    process had written when the run was interrupted."""
    return f"{os.getpid()}-{secrets.token_hex(4)}"


def _umask() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return umask


def check_target(path: str | os.PathLike) -> bool:
    """Whether the output ``path`` is written into directly (True: an existing FIFO or character
    device, or a path naming an open file descriptor such as /dev/stdout) rather than staged and
    renamed (False: a regular file, or nothing there yet). A directory, a socket or a block
    device is an OutputError: none of them can take the output, and none may be replaced."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return False  # nothing there (or not reachable): staging creates it, or says why not
    if stat.S_ISREG(mode):
        # /dev/stdout redirected to a file: that file gets the output, never the link /dev/stdout
        return _names_descriptor(path)
    if stat.S_ISFIFO(mode) or stat.S_ISCHR(mode):
        return True
    what = "a directory" if stat.S_ISDIR(mode) else "a socket" if stat.S_ISSOCK(mode) else None
    what = what or ("a block device" if stat.S_ISBLK(mode) else "not a regular file")
    raise OutputError(
        f"cannot write the output: it is {what}",
        path=str(path),
        hint="give the name of a file, a FIFO or a character device such as /dev/null",
    )


def stage(path: str | os.PathLike, data: bytes | str, *, token: str = "") -> Staged:
    """Write ``data`` completely (flushed to disk) to a temporary file in ``path``'s directory;
    `commit` renames it onto ``path``. On an error the temporary file is removed. A FIFO or a
    device at ``path`` (`check_target`) is not staged: the data waits for `commit` in memory."""
    payload = data.encode("utf-8") if isinstance(data, str) else data
    return _staged(path, lambda fh: fh.write(payload), lambda: payload, token)


def stage_json(path: str | os.PathLike, obj: Any, *, token: str = "") -> Staged:
    """`stage` of `json_text` (``obj``), written to the temporary file piece by piece: the text of a
    day's summary with thousands of alarms (24 MB) is never whole in memory, nor are the ~130 MB of
    pieces `json.dumps` joins it from (bench/README.md, "the --json written in pieces")."""
    return _staged(path, lambda fh: write_json_into(fh, obj), lambda: json_text(obj).encode("utf-8"), token)


def _staged(path: str | os.PathLike, write: Callable[[IO[bytes]], object], payload: Callable[[], bytes], token: str):
    """`stage`: ``write`` fills the temporary file; ``payload`` is the data a FIFO or device waits with."""
    target = Path(path)
    if check_target(target):
        return Staged(None, str(target), payload())
    directory = target.parent if str(target.parent) else Path(".")
    if not directory.is_dir():
        raise OutputError("the output directory does not exist", path=str(directory), hint="create it first")
    _sweep_once(str(directory))
    prefix = f".{target.name}.{token or new_token()}."  # the pid in the name: see remove_dead_temporaries
    try:
        fd, tmp = tempfile.mkstemp(prefix=prefix, suffix=".tmp", dir=directory)
    except OSError as exc:
        raise output_error(exc, target) from None
    try:
        # mkstemp creates 0600; give the file the permissions a plain open() would (umask)
        os.chmod(tmp, 0o666 & ~_umask())
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
    except BaseException as exc:
        _unlink(tmp)
        if isinstance(exc, OSError):
            raise output_error(exc, target) from None
        raise
    return Staged(tmp, str(target))


def commit(staged: Sequence[Staged]) -> None:
    """Rename every staged file onto its target, in order, with SIGINT/SIGTERM/SIGHUP held back;
    then write the data of the FIFO and device targets into them, in order.

    When a rename fails, the targets already replaced get their previous content back (or are
    removed when they had none), the remaining temporary files are removed, and an OutputError
    says which target failed. A failed or interrupted direct write puts the renamed targets back
    the same way (what already went into a FIFO or device stays written)."""
    if INTERRUPT_SEEN[0]:  # Ctrl-C came, but a finalizer swallowed its exception: commit nothing
        discard(staged)
        raise KeyboardInterrupt
    files = [item for item in staged if item.tmp is not None]
    direct = [item for item in staged if item.tmp is None]
    kept: list[str | None] = []  # the backups of the renamed targets, while a direct write may fail
    try:
        with _signals_held():
            backups = [_backup(item.target) for item in files]
            done = 0
            try:
                for item in files:
                    os.replace(item.tmp, item.target)
                    done += 1
            except BaseException as exc:
                _roll_back(files[:done], backups[:done])
                discard(files[done:])
                _discard_backups(backups)
                if isinstance(exc, OSError):
                    raise output_error(exc, files[done].target) from None
                raise
            if direct:
                kept = backups
            else:
                _discard_backups(backups)
        # outside the held signals: opening a FIFO waits for its reader, and Ctrl-C must work
        for item in direct:
            try:
                _write_into(item.target, item.data or b"")
            except OSError as exc:
                raise output_error(exc, item.target) from None
    except BaseException:
        if kept:  # every file was renamed, then a direct write failed or was interrupted
            with _signals_held():
                _roll_back(files, kept)
            _discard_backups(kept)
        raise
    _discard_backups(kept)
    for directory in {os.path.dirname(os.path.abspath(item.target)) for item in files}:
        _fsync_directory(directory)


def discard(staged: Iterable[Staged]) -> None:
    """Remove the temporary files of ``staged`` (targets untouched)."""
    for item in staged:
        if item.tmp is not None:
            _unlink(item.tmp)


def cleanup(targets: Iterable[str | os.PathLike], token: str) -> None:
    """Remove every temporary file of the run tagged ``token`` beside ``targets`` (including those
    a worker process wrote and could not report back before an interruption); each directory is
    listed once."""
    if not token:
        return
    directories = {os.path.dirname(os.path.abspath(target)) for target in targets}
    marker = f".{token}."
    for directory in directories:
        try:
            names = os.listdir(directory)
        except OSError:
            continue
        for name in names:
            if name.startswith(".") and name.endswith(".tmp") and marker in name:
                _unlink(os.path.join(directory, name))


ORPHAN_AGE_S = 60.0  # a temporary file of a dead process younger than this is left alone
# ``.<target name>.<pid>-<8 hex>.<mkstemp's 8 characters>.tmp`` and ``.<target name>.<pid>-<8 hex>.bak``
_TEMPORARY = re.compile(r"\..+\.(?P<pid>[0-9]+)-[0-9a-f]{8}(\.[A-Za-z0-9_]+\.tmp|\.bak)")
_SWEPT: set[str] = set()  # the directories this process has cleaned (once each)


def remove_dead_temporaries(directory: str | os.PathLike) -> int:
    """Remove the temporary files and backups that killed runs of logscan left in ``directory``
    (their names carry their process's pid): those whose process no longer exists and that are
    over ORPHAN_AGE_S old (a live process, or one this machine cannot see, keeps its files).
    Returns how many were removed."""
    try:
        names = os.listdir(directory)
    except OSError:
        return 0
    removed = 0
    for entry in names:
        found = _TEMPORARY.fullmatch(entry)
        if found is None or _process_exists(int(found["pid"])):
            continue
        path = os.path.join(directory, entry)
        try:
            st = os.lstat(path)
            if stat.S_ISREG(st.st_mode) and time.time() - st.st_mtime > ORPHAN_AGE_S:
                os.unlink(path)
                removed += 1
        except OSError:
            continue
    return removed


def remove_orphans(targets: Iterable[str | os.PathLike]) -> None:
    """`remove_dead_temporaries` in the folder of each of ``targets``."""
    for directory in {os.path.dirname(os.path.abspath(target)) for target in targets}:
        remove_dead_temporaries(directory)


def _sweep_once(directory: str) -> None:
    """`remove_dead_temporaries` in ``directory``, the first time this process writes there."""
    key = os.path.abspath(directory)
    if key not in _SWEPT:
        _SWEPT.add(key)
        remove_dead_temporaries(key)


def _process_exists(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True  # someone else's process, or no such pid to ask about: keep its files
    return True


def write_atomic(path: str | os.PathLike, data: bytes | str) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same directory and a rename."""
    commit([stage(path, data)])


def json_text(obj: Any) -> str:
    """JSON under the one JSON policy (`logscan.json_policy.jsonable`: numpy values to plain ones,
    NaN and infinities to null)."""
    return "".join(_json_pieces(obj))


def write_json_into(fh: IO[Any], obj: Any) -> None:
    """`json_text` (``obj``), the same characters, written into ``fh`` (binary: as UTF-8) as the
    encoder makes them instead of joined first; ``fh`` stays open."""
    if not isinstance(fh, (io.BufferedIOBase, io.RawIOBase)):  # a text stream (sys.stdout)
        fh.writelines(_json_pieces(obj))
        fh.flush()
        return
    text = io.TextIOWrapper(cast(BinaryIO, fh), encoding="utf-8")
    try:
        text.writelines(_json_pieces(obj))
        text.flush()
    finally:
        text.detach()  # flushed into ``fh``, which its owner closes


def _json_pieces(obj: Any) -> Iterator[str]:
    """`json_text`'s characters in the pieces the encoder makes them."""
    yield from json.JSONEncoder(indent=2, sort_keys=False, allow_nan=False).iterencode(jsonable(obj))
    yield "\n"


def write_json(path: str | os.PathLike, obj: Any) -> None:
    """JSON to ``path`` atomically, or to stdout when ``path`` is "-" (see `json_text`)."""
    if str(path) == "-":
        write_json_into(sys.stdout, obj)
        return
    commit([stage_json(path, obj)])


# --- helpers ------------------------------------------------------------------------------------


def _unlink(path: str) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


# a directory of open file descriptors: /proc/<pid>/fd (Linux; /dev/fd links there), /dev/fd
_DESCRIPTOR_DIRECTORY = re.compile(r"/proc/[^/]+(/task/[^/]+)?/fd|/dev/fd")


def _names_descriptor(path: str | os.PathLike) -> bool:
    """Whether ``path`` (or a symbolic link on its way) is an entry of a directory of open file
    descriptors: /dev/stdout, /dev/fd/1 or /proc/self/fd/1 name whatever that descriptor is open
    on (writing through them reaches it); such an entry is never renamed onto."""
    current = os.path.abspath(path)
    for _ in range(40):  # the kernel's limit on links followed
        directory = os.path.realpath(os.path.dirname(current))
        if _DESCRIPTOR_DIRECTORY.fullmatch(directory):
            return True
        try:
            link = os.readlink(current)
        except OSError:
            return False  # not a link: the end of the chain
        current = os.path.normpath(os.path.join(directory, link))
    return False


def _write_into(target: str, data: bytes) -> None:
    """``data`` written into the existing FIFO or device ``target`` (never created or replaced;
    appended, so a file reached through /dev/stdout keeps what is already there)."""
    for stream in (sys.stdout, sys.stderr):  # text already printed comes first on a shared file
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):
            pass
    fd = os.open(target, os.O_WRONLY | os.O_APPEND | getattr(os, "O_NOCTTY", 0))
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view) :]
    finally:
        os.close(fd)


def _backup(target: str) -> str | None:
    """A hard link to the target's current file (None: no file, or no hard links here)."""
    if not os.path.isfile(target):
        return None
    directory, name = os.path.split(os.path.abspath(target))
    for _ in range(3):
        backup = os.path.join(directory, f".{name}.{os.getpid()}-{secrets.token_hex(4)}.bak")
        try:
            os.link(target, backup)
            return backup
        except FileExistsError:
            continue
        except OSError:
            return None
    return None


def _roll_back(replaced: Sequence[Staged], backups: Sequence[str | None]) -> None:
    for item, backup in zip(replaced, backups):
        try:
            if backup is None:
                os.unlink(item.target)
            else:
                os.replace(backup, item.target)
        except OSError:
            pass


def _discard_backups(backups: Iterable[str | None]) -> None:
    for backup in backups:
        if backup is not None:
            _unlink(backup)


def _fsync_directory(directory: str) -> None:
    """Make the renames durable (best effort: not every platform can open a directory)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


class _signals_held:
    """Hold back SIGINT, SIGTERM and SIGHUP (POSIX, main thread): delivered on exit."""

    _SIGNALS = {getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)}

    def __enter__(self):
        self._old = None
        if hasattr(signal, "pthread_sigmask") and threading.current_thread() is threading.main_thread():
            self._old = signal.pthread_sigmask(signal.SIG_BLOCK, self._SIGNALS)
        return self

    def __exit__(self, *exc) -> None:
        if self._old is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, self._old)
