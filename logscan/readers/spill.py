"""A reader's arrays held on disk: a long log's read held whole for block mode
(`logscan.pipeline.held_window`).

A PX4 ULog has no index, so block mode reads it whole once and cuts each block from that read:
held in memory it made the peak grow by about 190 MB per log-hour. Within `spilling()`, the read's
large arrays (its records, timestamps and channels: `empty`) are each backed by an unlinked
temporary file, mapped shared: the kernel writes their pages to the file and reads them back when
touched, and this process holds only the pages it touches until it gives them back
(`give_back`, `passed`): what a step has in hand, not the log. The values are the same arrays'
either way; only where the bytes wait differs. The files are in the temporary directory
(``TMPDIR``) and go with their arrays (or the process); where one cannot be made (no space, no
such directory, no ``madvise``), the array is an ordinary one. On a ``tmpfs`` temporary directory
the pages stay in memory, counted as the system's shared memory instead of this process's.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import mmap
import os
import re
import tempfile
import weakref
from collections.abc import Iterator

import numpy as np

from logscan.log import TIMES_CHUNK, TIMES_READ

try:
    import resource
except ImportError:  # Windows, where nothing is put on disk (`_CAN`)
    resource = None  # type: ignore[assignment]

MIN_BYTES = 64 << 10  # smaller arrays stay in memory: not worth the page faults
HELD_FROM_BYTES = 64 << 20  # a held read this large (a ULog's file, a bag's decoded values) waits on disk
# files mapped at once: each mapping holds a file descriptor, at most a quarter of the process's
MAX_FILES = 256
PASSED_BYTES = 64 << 20  # bytes read through on disk (`passed`) before their pages are given back
CHUNK = TIMES_CHUNK  # elements per step of a pass over a whole on-disk array (its pages given back between)
SHARED_BYTES = 8 << 20  # arrays up to this size are carved from one file of SHARED_FILE_BYTES
SHARED_FILE_BYTES = 64 << 20

_on = [False]
_mapped: weakref.WeakSet[mmap.mmap] = weakref.WeakSet()
_passed = [0]
_shared: list[np.ndarray | None] = [None]  # the file small arrays are carved from, per `spilling`
_shared_used = [0]
_CAN = hasattr(mmap, "MADV_DONTNEED") and hasattr(os, "posix_fallocate")  # Linux (not macOS, Windows)
_IN_MEMORY = frozenset({"tmpfs", "ramfs"})
_OCTAL = re.compile(r"\\([0-7]{3})")


@contextlib.contextmanager
def spilling(on: bool = True, needs: int = 0) -> Iterator[None]:
    """Within it (``on``), `empty` backs its large arrays by files; the pages touched are given back
    at the end. Not where the temporary directory is in memory (tmpfs: its files would hold the same
    memory, reserved whole) or has less than ``needs`` bytes free (a full disk would end the files)."""
    _on.append(on and _CAN and _room_on_disk(needs))
    _shared.append(None)
    _shared_used.append(0)
    try:
        yield
    finally:
        _on.pop()
        _shared.pop()  # its arrays keep it: no later array is carved from it
        _shared_used.pop()
        give_back()


def _room_on_disk(needs: int) -> bool:
    """Whether the temporary directory is on a disk (not tmpfs or ramfs) with ``needs`` bytes free."""
    try:
        directory = os.path.realpath(tempfile.gettempdir())  # FileNotFoundError: none is usable
        stat = os.statvfs(directory)
        with open("/proc/self/mounts", encoding="utf-8", errors="replace") as mounts:
            table = [line.split()[1:3] for line in mounts if len(line.split()) > 2]
    except OSError:
        return False
    # the filesystem of the longest mount point the directory lies under, the last mounted of
    # equals (it hides those before); /proc writes a space, tab or backslash in octal (\040)
    kind, longest = "", -1
    for point, fs in table:
        point = _OCTAL.sub(lambda code: chr(int(code.group(1), 8)), point)
        if _under(directory, point) and len(point) >= longest:
            kind, longest = fs, len(point)
    return kind not in _IN_MEMORY and stat.f_bavail * stat.f_frsize >= needs


def _under(path: str, point: str) -> bool:
    return path == point or path.startswith(point.rstrip("/") + "/")


def empty(shape: int | tuple[int, ...], dtype, alone: bool = False) -> np.ndarray:
    """``np.empty(shape, dtype)``, backed by a file within `spilling` when large: up to
    `SHARED_BYTES` carved from a shared file, unless ``alone`` (a file of its own, of its size: for
    a few arrays in a context of their own, which would reserve a whole shared file)."""
    if not _on[-1]:  # not spilling: numpy's own (a reader asks for a few arrays per topic)
        return np.empty(shape, dtype)
    dtype = np.dtype(dtype)
    size = int(math.prod(shape if isinstance(shape, (tuple, list)) else (shape,))) * dtype.itemsize
    if size < MIN_BYTES:
        return np.empty(shape, dtype)
    if size <= SHARED_BYTES and not alone:  # carved from a shared file: one mapping (one descriptor) for many
        if _shared[-1] is None or _shared[-1].size - _shared_used[-1] < size:
            _shared[-1], _shared_used[-1] = _mapping(SHARED_FILE_BYTES), 0
        shared = _shared[-1]
        if shared is not None:
            at = _shared_used[-1]
            _shared_used[-1] += _aligned(size)
            return shared[at : at + size].view(dtype).reshape(shape)
    own = _mapping(size)
    return np.empty(shape, dtype) if own is None else own[:size].view(dtype).reshape(shape)


def copied(values: np.ndarray, dtype=None, alone: bool = False) -> np.ndarray:
    """``values`` as ``dtype`` (None: their own) in an array of `empty` (on disk within `spilling`
    when large; ``alone``: as `empty`'s), else ``values.astype(dtype, copy=False)``."""
    kept = empty(values.shape, values.dtype if dtype is None else dtype, alone)
    if not on_disk(kept):
        return values.astype(kept.dtype, copy=False)
    kept[...] = values
    passed(kept.nbytes)
    return kept


def kept(array: np.ndarray) -> np.ndarray:
    """``array`` itself, or within `spilling` a copy of it on disk (`copied`) unless it is there."""
    if not _on[-1] or on_disk(array):
        return array
    return copied(array)


def joined(arrays: list[np.ndarray]) -> np.ndarray:
    """``np.concatenate(arrays)`` (1-D, one dtype; one contiguous array: itself) into an array of
    `empty`: on disk within `spilling` when large, its pages given back as it is written (`passed`)."""
    if not _on[-1]:
        return np.ascontiguousarray(arrays[0]) if len(arrays) == 1 else np.concatenate(arrays)
    if len(arrays) == 1 and on_disk(arrays[0]) and arrays[0].flags.c_contiguous:
        return arrays[0]
    out = empty(sum(a.size for a in arrays), arrays[0].dtype)
    at = 0
    for array in arrays:
        out[at : at + array.size] = array
        at += array.size
        passed(array.nbytes * (2 if on_disk(array) else 1))  # written, and read where it is on disk too
    return out


def copied_together(arrays: list[np.ndarray]) -> list[np.ndarray]:
    """Copies of ``arrays`` in one file of their summed size within `spilling` (each a file of
    its own would count against `MAX_FILES`; a shared file reserves `SHARED_FILE_BYTES`), else
    ``arrays`` themselves."""
    places = [_aligned(array.nbytes) for array in arrays]
    file = empty(sum(places), np.uint8, alone=True)
    if not on_disk(file):
        return arrays
    kept = []
    for at, array in zip(itertools.accumulate(places, initial=0), arrays):
        kept.append(file[at : at + array.nbytes].view(array.dtype).reshape(array.shape))
        kept[-1][...] = array
    passed(file.nbytes)
    return kept


def _aligned(size: int) -> int:
    """``size`` bytes rounded up to a cache line: where the next array carved from a file starts."""
    return -(-size // 64) * 64


def _mapping(size: int) -> np.ndarray | None:
    """``size`` bytes (uint8) of a new unlinked file, mapped shared; None when it cannot be made."""
    if len(_mapped) >= min(MAX_FILES, _descriptors() // 4):
        return None
    try:
        with tempfile.TemporaryFile() as file:  # unlinked: gone with the last mapping of it
            os.posix_fallocate(file.fileno(), 0, size)  # the blocks reserved: no SIGBUS on a full disk later
            mapped = mmap.mmap(file.fileno(), size)
            with contextlib.suppress(OSError):  # no read-ahead: the page cache's large folios (ext4
                # on Linux 6.16+) map a whole folio, megabytes, at each touch of a window's edge or
                # a binary search's probe (bench/README.md, "random access")
                mapped.madvise(getattr(mmap, "MADV_RANDOM", mmap.MADV_NORMAL))
    except (OSError, ValueError):
        return None
    _mapped.add(mapped)
    return np.frombuffer(mapped, np.uint8)


def _descriptors() -> int:
    """The soft limit of open files of this process."""
    if resource is None:
        return 1 << 20
    soft = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    return soft if soft != resource.RLIM_INFINITY else 1 << 20


def on_disk(array: np.ndarray) -> bool:
    """Whether ``array`` (or the array it views) is one `empty` put on disk."""
    return file_of(array) is not None


def file_of(array: np.ndarray) -> mmap.mmap | None:
    """The on-disk file ``array`` (or the array it views) lies in, None when it is in memory."""
    base = array
    while isinstance(base, np.ndarray) and base.base is not None:
        base = base.base
    if isinstance(base, memoryview):  # np.frombuffer's base: a view of the mapping
        base = base.obj
    return base if isinstance(base, mmap.mmap) and base in _mapped else None


def holding() -> bool:
    """Whether any array of this process is on disk now (a long log's read held there, or any other)."""
    return bool(_mapped)


def give_back() -> None:
    """Drop every on-disk array's pages from this process (they are read again when touched)."""
    _passed[0] = 0
    for mapped in list(_mapped):
        with contextlib.suppress(ValueError, OSError):  # closed meanwhile
            mapped.madvise(mmap.MADV_DONTNEED)


def passed(size: int) -> None:
    """Count ``size`` bytes of on-disk arrays read or written; from `PASSED_BYTES` on, `give_back`."""
    if not _mapped:
        return
    _passed[0] += size
    if _passed[0] >= PASSED_BYTES:
        give_back()


TIMES_READ.append(passed)  # the log's span: a pass over every time array (`logscan.log`)
