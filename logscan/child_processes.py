"""Worker processes end with their parent, and use their share of the cores.

A `--jobs` worker whose parent is killed (SIGKILL, an out-of-memory kill) must not go on computing,
holding memory and writing temporary files.

Two mechanisms, so that neither a missed signal nor a busy interpreter keeps a worker alive:

- Linux: ``prctl(PR_SET_PDEATHSIG, SIGTERM)`` (through ctypes): the kernel sends the worker SIGTERM
  the moment its parent ends; the worker's SIGTERM handler (`logscan.fleet`) ends its own children
  (the background compile) and exits.
- Everywhere: a daemon thread polls ``os.getppid()`` every `POLL_S` seconds; when the parent is gone
  (the worker was re-parented) it sends the worker SIGTERM, and if the worker still lives
  `GRACE_S` seconds later (its main thread stuck in a compiled kernel that never returns to Python)
  it ends the process with ``os._exit``.

Temporary files a killed worker leaves are removed by the next run writing to that folder
(`logscan.artifacts`: their names carry the pid).

The threads a process starts of its own (a large CSV's parse) fill its share of the cores
(`usable_cores`): its affinity mask, which a container or `taskset` narrows, divided among the
processes beside it on that mask. `--jobs N` workers each get 1/N (`share_cores`), so that N workers
on C cores start C/N threads each instead of C, which would only wait for a core.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time

PR_SET_PDEATHSIG = 1  # <linux/prctl.h>
POLL_S = 1.0
GRACE_S = 5.0
EXIT_CODE = 128 + signal.SIGTERM


def exit_with_parent(parent_pid: int) -> None:
    """Make this process (a worker) end when the process ``parent_pid`` ends."""
    _ask_kernel()
    if os.getppid() != parent_pid:  # the parent ended before the kernel was asked
        os.kill(os.getpid(), signal.SIGTERM)
    thread = threading.Thread(target=_watch, args=(parent_pid,), name="logscan-parent-watch", daemon=True)
    thread.start()


def _ask_kernel() -> bool:
    """prctl(PR_SET_PDEATHSIG, SIGTERM) on Linux; False where it is not available."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _watch(parent_pid: int) -> None:
    while os.getppid() == parent_pid:
        time.sleep(POLL_S)
    try:
        os.kill(os.getpid(), signal.SIGTERM)  # the handler ends the children, then the process
    except OSError:
        pass
    time.sleep(GRACE_S)
    os._exit(EXIT_CODE)


_sharers = 1  # the processes, this one among them, that share the affinity mask (`share_cores`)


def share_cores(processes: int) -> None:
    """This process runs beside ``processes - 1`` others on the same cores (a `--jobs` worker)."""
    global _sharers
    _sharers = max(1, int(processes))


def usable_cores() -> int:
    """This process's share of the cores it may run on (at least one)."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # no affinity call here (macOS, Windows)
        cores = os.cpu_count() or 1
    return max(1, cores // _sharers)
