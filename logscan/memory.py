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
left inside the heap grow past that: between the pipeline's steps, from 256 MiB free there (the trim
threshold), its whole free pages go back to the system (`return_freed_pages`).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

M_TRIM_THRESHOLD = -1  # mallopt parameter numbers (malloc.h)
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD_BYTES = 64 * 1024 * 1024
TRIM_THRESHOLD_BYTES = 256 * 1024 * 1024


_heap: ctypes.CDLL | None = None  # glibc 2.33 or later, once its thresholds are set (`reuse_freed_arrays`)


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


def return_freed_pages() -> bool:
    """Give the system back the whole free pages inside the heap (glibc's malloc_trim) when at
    least the trim threshold lies free there, wherever: glibc returns that much only from the
    heap's top, and between the pipeline's steps a long log's freed read and align buffers sit
    below the trace's arrays, which, larger than the mmap threshold, cannot reuse them. Below the
    threshold the pages stay, for the next step's arrays to reuse without faulting them in again.
    True when pages were returned; only where `reuse_freed_arrays` set the thresholds."""
    if _heap is None or _heap.mallinfo2().fordblks < TRIM_THRESHOLD_BYTES:
        return False
    return bool(_heap.malloc_trim(0))
