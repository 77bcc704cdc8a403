"""The first run's compile of the EKF kernel, started before the log is read and run beside it.

numba compiles `ekf_run` once per model (logscan.models.dispatch) and caches it on disk; the first
run on a machine spends most of its time there (about 7 s of 10 s for the README's sample log,
2 cores). `start_compile(model)` tells whether the cache already holds the model's kernel and,
when it does not, compiles it in a forked process while this one reads and aligns the log (the
compile holds the GIL, so a thread would not overlap). `wait()` before filtering joins it; the
kernel then loads from the cache. Anything unusual (no fork, threads running, a daemonic worker,
the child failing) just leaves the compile to the first call, as without this module.
"""

from __future__ import annotations

import multiprocessing
import sys
import threading
from collections.abc import Callable, Iterable

import numpy as np
from numba.core.dispatcher import Dispatcher

from logscan.align import AlignedGroup, AlignedRun
from logscan.filters.ekf import ekf_run, run_ekf
from logscan.models.base import Model
from logscan.numba_cache import initialise_jit

COMPILING_NOTE = "compiling numerical kernels (first run only, 10-20 s)"


def ekf_cached(model: Model) -> bool:
    """True when numba's disk cache holds the EKF kernel for the model's id on this machine (or
    when the cache cannot be inspected: then nothing is said and nothing is started)."""
    return kernel_cached(ekf_run, model.model_id)


def kernel_cached(dispatcher, literal_first=None) -> bool:
    """True when numba's disk cache holds a compiled version of the cached ``dispatcher`` for this
    machine (with ``literal_first``: one whose first argument is that literal int); True as well
    when the cache cannot be inspected."""
    from numba.core import types

    try:
        cache_file = dispatcher._cache._cache_file
        magic = dispatcher.targetctx.codegen().magic_tuple()
        # keys: (signature, codegen magic, code hashes); _load_index is {} when the file is missing
        # or its source stamp is stale (numba/core/caching.py)
        for key in cache_file._load_index():
            if key[1] != magic:
                continue
            if literal_first is None:
                return True
            first = key[0][0] if len(key[0]) else None
            if isinstance(first, types.IntegerLiteral) and first.literal_value == literal_first:
                return True
        return False
    except Exception:  # noqa: BLE001 - numba internals changed: behave as before this module
        return True


class Compile:
    """A background compile of the EKF kernel (or nothing to wait for)."""

    def __init__(self, cold: bool, process=None):
        self.cold = cold
        self._process = process

    @property
    def in_background(self) -> bool:
        """Whether the kernel is compiling in its own process (until `wait`)."""
        return self._process is not None

    def wait(self) -> None:
        """Join the compiling process, if any (its result is in the disk cache)."""
        if self._process is not None:
            self._process.join()
            self._process = None


def start_compile(model: Model) -> Compile:
    """Compile the model's EKF kernel in a forked process when the cache lacks it."""
    if ekf_cached(model):
        return Compile(cold=False)
    if not _can_fork():
        return Compile(cold=True)
    initialise_jit()  # once, here, inherited by the child: not paid again on the compile's critical path
    try:
        process = multiprocessing.get_context("fork").Process(target=_compile_ekf, args=(model,), daemon=True)
        process.start()
    except (OSError, ValueError, AssertionError):  # no process could be started: compile on first use
        return Compile(cold=True)
    return Compile(cold=True, process=process)


def kernel_compilers(users: Iterable[object]) -> list[Callable[[], None]]:
    """The ``compile_kernels()`` functions (each compiles or loads its module's kernels for the
    types its callers pass) of the modules whose numba kernels ``users`` (e.g. detectors) call:
    their own class's module and the modules it imports kernels from, each once. The first run
    calls them while the EKF's kernel compiles in its own process."""
    modules: dict[str, object] = {}
    for user in users:
        own = sys.modules.get(type(user).__module__)
        if own is None:
            continue
        modules.setdefault(own.__name__, own)
        for value in vars(own).values():
            if isinstance(value, Dispatcher) and value.py_func.__module__ in sys.modules:
                modules.setdefault(value.py_func.__module__, sys.modules[value.py_func.__module__])
    compilers = (getattr(module, "compile_kernels", None) for module in modules.values())
    return [compiler for compiler in compilers if callable(compiler)]


def _can_fork() -> bool:
    # fork only where it is the safe default (Linux), from a single-threaded, non-daemonic process
    return (
        sys.platform.startswith("linux")
        and threading.active_count() == 1
        and not multiprocessing.current_process().daemon
    )


def _compile_ekf(model: Model) -> None:
    """Child process: run the EKF on two empty steps of the model (the kernel's signature depends
    on array ranks and dtypes only), which compiles and caches it."""
    name, spec = next(iter(model.groups.items()))
    steps = 2
    run = AlignedRun(
        t=np.arange(steps, dtype=np.float64) * 0.01,
        dt=0.01,
        start_ns=0,
        u=np.zeros((steps, model.n_inputs)),
        u_fresh=np.ones(steps, dtype=bool),
        input_channels=list(model.input_names),
        groups={
            name: AlignedGroup(
                name=name,
                channels=list(spec.outputs),
                z=np.full((steps, spec.size), np.nan),
                fresh=np.zeros(steps, dtype=bool),
            )
        },
    )
    run_ekf(model, run)
