"""The first run's compile of the EKF kernel, started before the log is read and run beside it.

numba compiles `ekf_run` once per model (logscan.models.dispatch) and caches it on disk; the first
run on a machine spends most of its time there. `start_compile(model)` tells whether the cache
already holds the model's kernel and, when it does not, compiles it in a forked process while this
one reads and aligns the log (the compile holds the GIL, so a thread would not overlap), and
first compiles here the kernel's model-independent helpers, which the child then loads from the
cache instead of compiling them too (`compile_filter_helpers`): the two cores share the EKF's
compile. The kernels compiled after it (the detectors': `kernel_compilers`) go to whichever
process is free first (`Compile.share`). `wait()` before filtering joins it; the kernel then
loads from the cache. Anything unusual (no fork, threads running, a daemonic worker, the child
failing) just leaves the compile to the first call, as without this module.
"""

from __future__ import annotations

import multiprocessing
import sys
import threading
from collections.abc import Callable, Iterable, Sequence
from functools import partial
from types import FunctionType

import numpy as np
from numba.core import types
from numba.core.dispatcher import Dispatcher

from logscan.align import AlignedGroup, AlignedRun
from logscan.filters import coding, ekf, linalg
from logscan.filters.ekf import ekf_run, run_ekf
from logscan.memory import collector_paused
from logscan.models.base import Model
from logscan.numba_cache import initialise_jit, kernel_cached

COMPILING_NOTE = "compiling numerical kernels (first run only, about 20-60 s)"


def ekf_cached(model: Model) -> bool:
    """True when numba's disk cache holds the EKF kernel for the model's id on this machine (or
    when the cache cannot be inspected: then nothing is said and nothing is started)."""
    return kernel_cached(ekf_run, model.model_id)


class Compile:
    """A background compile of the EKF kernel (or nothing to wait for), with the kernels to compile
    after it (``after``), which either process claims one by one (``claims``: 1 once taken)."""

    def __init__(self, cold: bool, process=None, after: Sequence[Callable[[], None]] = (), claims=None):
        self.cold = cold
        self._process = process
        self._after = tuple(after)
        self._claims = claims

    @property
    def in_background(self) -> bool:
        """Whether the kernel is compiling in its own process (until `wait`)."""
        return self._process is not None

    def share(self) -> None:
        """Compile here those of the kernels ``after`` the other process has not taken yet: this
        process, done with its own work before that one, takes the rest of the list."""
        if self._claims is not None:
            _compile_unclaimed(self._after, self._claims)

    def wait(self) -> None:
        """Join the compiling process, if any (its result is in the disk cache)."""
        if self._process is not None:
            self._process.join()
            self._process = None


def start_compile(model: Model, after: Sequence[Callable[[], None]] = ()) -> Compile:
    """Compile the model's EKF kernel in a forked process when the cache lacks it, then there the
    kernels ``after`` compiles (the detectors': `kernel_compilers`), and the EKF's
    model-independent helpers here meanwhile (`compile_filter_helpers`). The two processes then
    take about as long: this one also reads, aligns and compiles the rest (the observability
    verdict's kernel)."""
    if ekf_cached(model):
        return Compile(cold=False)
    if not _can_fork():
        return Compile(cold=True)
    initialise_jit()  # once, here, inherited by the child: not paid again on the compile's critical path
    try:
        context = multiprocessing.get_context("fork")
        claims = context.Array("b", max(len(after), 1))
        process = context.Process(target=_compile_kernels, args=(model, tuple(after), claims), daemon=True)
        process.start()
    except (OSError, ValueError, AssertionError):  # no process could be started: compile on first use
        return Compile(cold=True)
    with collector_paused():
        compile_filter_helpers()
    return Compile(cold=True, process=process, after=after, claims=claims)


def load_kernels(model: Model | None, users: Iterable[object], notice: Callable[[str], None] | None = None) -> None:
    """Load the EKF kernel of ``model`` (None: no filter runs) and the kernels of ``users`` (the
    detectors: `kernel_compilers`) now, ahead of any log: from numba's disk cache, or on a cold
    cache compiled as the first run does (`start_compile`: the EKF's in a forked process, beside
    this one; ``notice`` hears the first run's note). `--jobs` calls it in the parent before it
    forks its workers (`logscan.pipeline.run.load_kernels_for`), which then inherit the loaded
    machine code instead of each loading (or compiling) it again. A kernel that fails here is left
    to its first call, as without this."""
    compilers = kernel_compilers(users)
    with collector_paused():
        if model is not None:
            compiling = start_compile(model, after=compilers)
            if compiling.cold and notice is not None:
                notice(COMPILING_NOTE)
            compiling.share()
            compiling.wait()
            head_start(partial(_compile_ekf, model))
        for compile_kernels in compilers:
            head_start(compile_kernels)


# The EKF kernel's model-independent helpers, each with the one signature the kernel calls it with
# (its work arrays' types: ekf_pack.EkfWork; "f2" is a C-contiguous 2-d float64 array, "i" an int64,
# "F" float32, "b" bool), in the reverse of the order the kernel's compile meets them. The child
# compiling the kernel starts with the model's own functions; this process compiles these meanwhile
# and caches them, so the child loads each one it reaches after this process is done with it
# instead of compiling it too: the first run's critical path, the EKF's compile, about 3.5 s shorter
# (tests/test_warmup.py checks the signatures against the kernel's).
FILTER_HELPERS = (
    (ekf._store_gain, "i i1 f2 f2 f3 f3 b b"),
    (coding.coded_variance, "f2 i i f1"),
    (linalg.forward_sq, "f2 i f1 i f1"),
    (linalg.all_finite2, "f2"),
    (linalg.joseph, "f2 f2 i2 i1 f2 f2 f2 i2 i1 i i i2 i1 f2 f2 f2 f2"),
    (linalg.short_update, "f2 f2 i i f f2"),
    (linalg.gain_rows, "f2 i f2 f2 f2 i"),
    (linalg.cholesky, "f2 i i f2"),
    (linalg.sparse_mm, "f2 i2 i1 i f2 i f2"),
    (linalg.wrap_angle, "f"),
    (linalg.sparse_rows, "f2 i i i2 i1"),
    (coding.coding_vector_into, "f2 f1 f f1"),
    (ekf._store, "i f1 f2 f2 F2 f3 b"),
    (ekf._restart, "f1 f2 f1 f2 b1"),
    (linalg.fpft_q, "f2 f2 f2 i i2 i1 f2 f2 f2"),
    (linalg.grow_pattern, "f2 i i1 i2 i1"),
    (linalg.pattern_holds, "i1 i1"),
    (linalg.all_finite, "f1"),
)


def helper_signature(codes: str) -> tuple:
    """The numba argument types of a FILTER_HELPERS signature."""
    scalars = {"f": types.float64, "i": types.int64, "b": types.boolean, "F": types.float32}
    return tuple(
        scalars[code[0]] if len(code) == 1 else types.Array(scalars[code[0]], int(code[1:]), "C")
        for code in codes.split()
    )


def compile_filter_helpers() -> None:
    """Compile (or load from the cache) FILTER_HELPERS: the first run, while the EKF kernel
    compiles in its own process. A helper that fails here is left to the kernel's compile."""
    for dispatcher, codes in FILTER_HELPERS:
        head_start(partial(dispatcher.compile, helper_signature(codes)))


def head_start(compile_kernels: Callable[[], object]) -> None:
    """Call ``compile_kernels``: a compile ahead of its first use, so one that fails here is left
    to that use, which meets the error again."""
    try:
        compile_kernels()
    except Exception:  # noqa: BLE001, S110 - see the docstring
        pass


def kernel_compilers(users: Iterable[object]) -> list[Callable[[], None]]:
    """The ``compile_kernels()`` functions (each compiles or loads its module's kernels for the
    types its callers pass) of the modules whose numba kernels ``users`` (e.g. detectors) call:
    their own class's module and the modules it imports kernels or functions from (a numpy
    function around a kernel), each once. The first run calls them in the process that compiles
    the EKF's kernel, after it."""
    modules: dict[str, object] = {}
    for user in users:
        own = sys.modules.get(type(user).__module__)
        if own is None:
            continue
        modules.setdefault(own.__name__, own)
        for value in vars(own).values():
            function = value.py_func if isinstance(value, Dispatcher) else value
            origin = getattr(function, "__module__", None) if isinstance(function, FunctionType) else None
            if origin in sys.modules:
                modules.setdefault(origin, sys.modules[origin])
    compilers = (getattr(module, "compile_kernels", None) for module in modules.values())
    return [compiler for compiler in compilers if callable(compiler)]


def _can_fork() -> bool:
    # fork only where it is the safe default (Linux), from a single-threaded, non-daemonic process
    return (
        sys.platform.startswith("linux")
        and threading.active_count() == 1
        and not multiprocessing.current_process().daemon
    )


def _compile_kernels(model: Model, after: Sequence[Callable[[], None]], claims) -> None:
    """Child process: the EKF kernel of ``model``, then those of the kernels ``after`` compiles that
    the parent has not taken (`Compile.share`), each into the disk cache (one that fails is left to
    its first call in the parent)."""
    with collector_paused():
        _compile_ekf(model)
        _compile_unclaimed(after, claims)


def _compile_unclaimed(compiles: Sequence[Callable[[], None]], claims) -> None:
    """Call each of ``compiles`` whose claim (a shared byte per item) no process has taken, taking
    it first: the two processes of a first run split the list between them, none compiled twice."""
    for index, compile_kernels in enumerate(compiles):
        with claims.get_lock():
            if claims[index]:
                continue
            claims[index] = 1
        head_start(compile_kernels)


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
