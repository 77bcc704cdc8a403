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
pipeline's steps every whole free page inside the heap goes back to the system (`return_freed_pages`).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

M_TRIM_THRESHOLD = -1  # mallopt parameter numbers (malloc.h)
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD_BYTES = 64 * 1024 * 1024
TRIM_THRESHOLD_BYTES = 256 * 1024 * 1024


_heap: ctypes.CDLL | None = None  # glibc, once its thresholds are set (`reuse_freed_arrays`)


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
    if done:  # `return_freed_pages` trims the heap
        _heap = libc
    return done


def return_freed_pages() -> bool:
    """Give the system back the whole free pages inside the heap (glibc's malloc_trim), wherever
    they lie: glibc returns them by itself only from the heap's top past the trim threshold, and
    between the pipeline's steps (and a long log's blocks) the freed read, align and detector
    buffers sit below arrays still alive. Kept, they stay resident whether the next step reuses
    them or not, so a block mode run's peak depended on whether the heap's free bytes happened to
    stand above the trim threshold (the 24-hour log: 431 or 522 MiB, bench/README.md, "page return
    between blocks"); given back, the next step faults in again what it reuses (~0.2 s of system
    time per 30-minute block). True when pages were returned; only where `reuse_freed_arrays` set
    the thresholds."""
    if _heap is None:
        return False
    return bool(_heap.malloc_trim(0))
