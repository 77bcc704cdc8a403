"""`logscan analyze` with every call of `return_freed_pages` traced: which step called it, the heap
(glibc's mallinfo2: arena, bytes in use, free, free at the top), the RSS before and after, whether
pages went back and how long the trim took. One line a call to TRACE (bench/README.md, "Page
return between blocks").

    TRACE=out.trace python bench/trace_page_return.py analyze LOG --json OUT --no-report
    PYTHONPATH=../before TRACE=... TRIM=all python bench/trace_page_return.py analyze ...

TRIM=all trims at every call, TRIM=block at a block's end only, whatever the tree's function does
(to measure a tree that trims from a threshold as if it did not); unset, the tree's own function.
glibc 2.33 or later (mallinfo2).
"""

from __future__ import annotations

import ctypes
import os
import sys
import time

import logscan.memory
import logscan.pipeline.blocks
import logscan.pipeline.detection
import logscan.pipeline.preparation
from logscan.cli.main import main


class _MallInfo2(ctypes.Structure):
    _fields_ = [
        (name, ctypes.c_size_t)
        for name in ("arena", "ordblks", "smblks", "hblks", "hblkhd")
        + ("usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")
    ]


_LIBC = ctypes.CDLL("libc.so.6")
_LIBC.mallinfo2.restype = _MallInfo2
_OWN = logscan.memory.return_freed_pages
_OUT = open(os.environ["TRACE"], "w", buffering=1)  # noqa: SIM115 - open for the whole run
_T0 = time.perf_counter()


def _rss_mib() -> tuple[int, int]:
    with open("/proc/self/status") as fh:
        status = {line.split(":")[0]: int(line.split()[1]) // 1024 for line in fh if line.startswith("Vm")}
    return status["VmRSS"], status["VmHWM"]


def traced() -> bool:
    frame = sys._getframe(1)
    where = f"{os.path.basename(frame.f_code.co_filename)}:{frame.f_lineno}"
    heap, (rss, _) = _LIBC.mallinfo2(), _rss_mib()
    mode, start = os.environ.get("TRIM", ""), time.perf_counter()
    if mode == "all" or (mode == "block" and where.startswith("blocks.py")):
        returned = bool(_LIBC.malloc_trim(0))
    else:
        returned = _OWN()
    took_ms = (time.perf_counter() - start) * 1000
    after, hwm = _rss_mib()
    mib = [round(b / 2**20) for b in (heap.arena, heap.uordblks, heap.fordblks, heap.keepcost, heap.hblkhd)]
    _OUT.write(
        f"{time.perf_counter() - _T0:8.1f} {where:18s} arena {mib[0]:6d} used {mib[1]:6d} free {mib[2]:6d} "
        f"top {mib[3]:6d} mmap {mib[4]:6d} rss {rss:5d}->{after:5d} hwm {hwm:5d} "
        f"trim {int(returned)} {took_ms:7.1f} ms\n"
    )
    return returned


for module in (logscan.memory, logscan.pipeline.blocks, logscan.pipeline.detection, logscan.pipeline.preparation):
    module.return_freed_pages = traced  # type: ignore[attr-defined]
sys.argv = ["logscan", *sys.argv[1:]]
main()
