"""Freed arrays go back to the operating system (glibc's malloc only).

glibc serves a large allocation by mmap, and returns it to the system when it is freed, only above
a threshold that it raises, up to 32 MB, every time such a block is freed. After the first
large arrays of a log are freed, the next ones (a few MB each: one channel, one trace column) land
on the heap, whose freed pages stay with the process: RSS then grows with every phase of the
analysis instead of following what is alive (a 1-hour log: ~150 MB more at the peak). Fixing the
threshold at 128 KiB (its default start) keeps large arrays on mmap for the whole run.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

M_MMAP_THRESHOLD = -3  # mallopt parameter numbers (malloc.h)
MMAP_THRESHOLD_BYTES = 128 * 1024


def return_freed_arrays_to_the_system() -> bool:
    """Fix glibc's mmap threshold; False where there is no glibc (then nothing changes)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        return bool(libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES))
    except (OSError, AttributeError):  # musl and other C libraries have no mallopt
        return False
