"""Where glibc's malloc keeps a log's freed arrays: on the heap for reuse, the largest returned.

glibc serves an allocation above its mmap threshold by a fresh mapping, whose pages the kernel
zeroes on first touch and which goes back to the system when freed. At a small threshold (its
128 KiB default start) every channel, trace column and numpy temporary of a long log is such a
mapping: `logscan analyze` of a 1-hour 100 Hz log took
2.1 million page faults and 4.9-5.8 s of system time (a third of its CPU). With the threshold at
64 MiB those arrays are carved from the heap and reused; the few larger than that (a full K or S
trace) stay mappings and are returned; the heap top is trimmed only when 256 MiB lie free there.
Measured on that log (bench/README.md, "System time"): 72 thousand page faults, 0.5-0.8 s of
system time, peak RSS +30-48 MiB (+6-9 %). On a longer log the freed reading and aligning buffers
left inside the heap grow past that, below arrays still alive (not at the top): between the
pipeline's steps, from 256 MiB free there (the trim threshold; in block mode from any), its whole
free pages go back to the system (`return_freed_pages`).

Python's cyclic collector is paused (`collector_paused`) where code makes many objects at once:
each 700 container objects made start a collection of the youngest generation, every tenth of those
one of the middle generation, and the objects a numba compile (hundreds of thousands) or a log's
read (a channel per field: 2,000-2,500 in a short PX4 log) makes were walked again and
again while they were made. Paused, what they leave is walked once, when the collector is back on.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import mmap
import sys
from collections.abc import Iterator
from contextlib import contextmanager

M_TRIM_THRESHOLD = -1  # mallopt parameter numbers (malloc.h)
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD_BYTES = 64 * 1024 * 1024
TRIM_THRESHOLD_BYTES = 256 * 1024 * 1024


_heap: ctypes.CDLL | None = None  # glibc 2.33 or later, once its thresholds are set (`reuse_freed_arrays`)
# the free bytes inside the heap from which `return_freed_pages` gives them back (`every_free_page`)
_trim_from = [TRIM_THRESHOLD_BYTES]


def reuse_freed_arrays() -> bool:
    """Set glibc's mmap and trim thresholds; False where there is no glibc (then nothing changes)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        done = bool(libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)) and bool(
            libc.mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES)
        )
    except (OSError, AttributeError):  # musl and other C libraries have no mallopt
        return False
    global _heap
    if done and hasattr(libc, "mallinfo2"):  # `return_freed_pages` reads the heap's free bytes
        libc.mallinfo2.restype = _MallInfo2
        _heap = libc
    return done


class _MallInfo2(ctypes.Structure):
    """glibc's `struct mallinfo2` (malloc.h, glibc 2.33 and later)."""

    _fields_ = [
        (name, ctypes.c_size_t)
        for name in ("arena", "ordblks", "smblks", "hblks", "hblkhd")
        + ("usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")
    ]


@contextmanager
def every_free_page() -> Iterator[None]:
    """Within it, `return_freed_pages` gives back whatever lies free, not only from the trim
    threshold: block mode (`logscan.pipeline.blocks`), whose peak must not depend on whether the
    heap's free bytes happen to stand above the threshold (the 24-hour log: 431 or 522 MiB,
    bench/README.md, "page return between blocks"), for ~10 % more system time. A log analysed at
    once keeps the threshold: its next step reuses the pages without faulting them in again."""
    _trim_from.append(0)
    try:
        yield
    finally:
        _trim_from.pop()


def return_freed_pages() -> bool:
    """Give the system back the whole free pages inside the heap (glibc's malloc_trim), wherever
    they lie, when at least the trim threshold lies free there (anything within `every_free_page`):
    glibc returns them by itself only from the heap's top, and between the pipeline's steps a long
    log's freed read, align and detector buffers sit below arrays still alive. Below the threshold
    the pages stay, for the next step's arrays to reuse without faulting them in again. True when
    pages were returned; only where `reuse_freed_arrays` set the thresholds."""
    if _heap is None or _heap.mallinfo2().fordblks < _trim_from[-1]:
        return False
    return bool(_heap.malloc_trim(0))


def drop_mapped_pages(mapped: mmap.mmap, stop: int) -> None:
    """Drop the pages of the read-only file mapping ``mapped`` before byte ``stop`` from this
    process (they are read again from the page cache if touched): a reader's RSS then follows what
    it has in hand, not the file it walked (reading a byte maps the whole folio around it)."""
    length = stop - stop % mmap.PAGESIZE
    if length > 0 and hasattr(mmap, "MADV_DONTNEED"):
        mapped.madvise(mmap.MADV_DONTNEED, 0, length)


@contextmanager
def collector_paused() -> Iterator[None]:
    """The cyclic collector off inside the block (as it was before, after it): a kernel's compile
    (about 0.7 s of the first run's CPU walked numba's objects) or a log's read (a tenth of a short
    PX4 log's read, bench/README.md). What cyclic garbage they leave waits for the collector: a
    read's, a few thousand objects whatever the log's length; a compile's, about 200,000."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()
