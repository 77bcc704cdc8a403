"""Private copies of shared numba functions compiled without numba's reference counting (NRT), for
the UBIKF's step loop (`logscan.filters.ubikf_kernel`).

With the NRT on, every array view a kernel makes (a row ``G[i]``, a slice, a tuple of arrays
unpacked) and every array argument of a call numba does not inline counts a reference up and down,
an atomic add each: that was a third of the UBIKF's time (about 2 us per block per step on the
hover log). A loop that allocates nothing needs none of it: its arrays belong to the caller, which
holds them for the whole call. numba's ``_nrt=False`` option compiles a function so; a function
that would allocate then fails to compile ("NRT required but not enabled", or no typing of the
allocation), so the option also guards the loop against an allocation creeping in.

The copies are private because a numba function keeps one compiled version per argument types,
whatever the caller's options: ``linalg.sparse_mm`` compiled first for the EKF (with the NRT) would
be the one the UBIKF's loop links, and the speed would depend on which filter compiled first in the
process. `nrt_free` compiles the same Python source (and, recursively, every numba function it
calls) as a new function that only the UBIKF calls.
"""

from __future__ import annotations

import types

from numba import njit
from numba.core.dispatcher import Dispatcher

_COPIES: dict[Dispatcher, Dispatcher] = {}


def nrt_free(dispatcher: Dispatcher) -> Dispatcher:
    """A private NRT-free copy of a numba function (see the module docstring): the same Python code
    and options, ``_nrt=False``, not cached itself (a cached kernel that calls it carries its code),
    and every numba function its code names replaced by such a copy, one copy per function."""
    if dispatcher in _COPIES:
        return _COPIES[dispatcher]
    func = dispatcher.py_func
    namespace = dict(func.__globals__)
    copy = types.FunctionType(func.__code__, namespace, func.__name__, func.__defaults__, func.__closure__)
    copy.__qualname__, copy.__doc__ = func.__qualname__, func.__doc__
    options = {key: value for key, value in dispatcher.targetoptions.items() if key != "nopython"}
    private = njit(**options, _nrt=False)(copy)
    _COPIES[dispatcher] = private
    for name in func.__code__.co_names:
        value = namespace.get(name)
        if isinstance(value, Dispatcher):
            namespace[name] = nrt_free(value)
    return private
