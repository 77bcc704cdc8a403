"""numba's on-disk cache, made stale when any module a cached kernel compiles in changes.

numba keys a cached function on its own source file only (the index's source stamp is a stamp of
that file; a stale index is ignored: `IndexDataCacheFile._load_index`), but a kernel that calls
numba functions of other modules carries their compiled code, and reads their numeric constants as
frozen values: editing a model's kernels would leave the EKF running the old equations from the
cache. `follow_dependencies(__name__)`, called at the end of every module that holds cached kernels,
makes the stamp of each of its cached functions the sha256 of its module's source and of each
dependency's, over the dependencies found transitively (`kernel_dependencies`): the modules it
imports numba functions or constants from. tests/test_numba_cache.py fails for a module that
forgets the call. It also makes each of them read an index that names a class no longer there (a kernel's
NamedTuple argument renamed or moved: numba unpickles the whole index before it compares stamps)
as stale, instead of failing on every load and save of that kernel (`tolerate_missing_classes`).

The same call files each of those kernels by what it compiles, not by where the package is
installed: under ``<NUMBA_CACHE_DIR>/<module>-<digest>``, the digest a sha256 of its module's source
and of every dependency's (`relocate`). numba files a kernel by the absolute path of its source
directory, so a regular install, an editable one of the same tree (the README's two lines), a second
venv or a reinstall of the same version each compiled every kernel again; now they share whatever
kernels have the same source, and a changed module is a new folder (two versions used in turn never
overwrite each other's kernels).

Uses numba internals (`_cache._cache_file`, `_cache._impl._locator`, numba/core/caching.py); a no-op
if they change.

`optimisation_level(level, *functions)` compiles the given kernels with LLVM at another level than
numba's (NUMBA_OPT, 3): for a kernel that runs briefly against its compile, where the lower level
compiles faster and runs as fast (bench/README.md measures each use).
"""

from __future__ import annotations

import ast
import functools
import hashlib
import importlib.util
import os
import pickle
import re
import sys
from types import CodeType, FunctionType, ModuleType
from typing import Any

from numba.core import config, event, types
from numba.core.dispatcher import Dispatcher

PACKAGE = __name__.split(".")[0]


def follow_dependencies(module_name: str) -> None:
    """Key the disk cache of every cached numba function of the module on its own source and on
    the source of every module in `kernel_dependencies` (`source_stamp`), file it by them
    (`relocate`), and let it read an index naming a class since renamed as stale
    (`tolerate_missing_classes`)."""
    module = sys.modules[module_name]
    dependencies = kernel_dependencies(module)
    folder = relocated_path(module, dependencies) if config.CACHE_DIR else ""
    for dispatcher in cached_dispatchers(module):
        cache_file = getattr(dispatcher._cache, "_cache_file", None)
        if cache_file is None:
            continue
        tolerate_missing_classes(cache_file)
        if hasattr(cache_file, "_source_stamp"):
            cache_file._source_stamp = source_stamp(dispatcher, dependencies)
        relocate(dispatcher, folder)


def relocate(dispatcher: Dispatcher, path: str) -> None:
    """File ``dispatcher``'s disk cache in the folder ``path`` (`relocated_path`: its module's name
    and the digest of the sources it compiles in) instead of numba's folder named after the absolute
    path of its source directory, so every copy of the same sources shares it. Left as numba made it
    when ``path`` is "" (numba's cache directory unset) or numba's internals differ."""
    cache: Any = getattr(dispatcher, "_cache", None)
    cache_file: Any = getattr(cache, "_cache_file", None)
    impl: Any = getattr(cache, "_impl", None)
    if not path or not hasattr(cache_file, "_index_name") or not hasattr(impl, "_locator"):
        return
    locator = impl._locator
    original = getattr(locator, "original", locator)
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:  # numba's own folder stays (numba itself says when that cannot be written)
        return
    if not os.access(path, os.W_OK):  # another user's folder, say: a save there would raise
        return
    impl._locator = _RelocatedLocator(original, path)
    cache._cache_path = cache_file._cache_path = path
    cache_file._index_path = os.path.join(path, cache_file._index_name)


def relocated_path(module: ModuleType, dependencies: list[ModuleType]) -> str:
    """``<NUMBA_CACHE_DIR>/<module name>-<digest>``: the digest (16 hex digits) a sha256 over the
    source of ``module`` and of each of ``dependencies``, so a change to any of them is a new
    folder and identical sources anywhere on disk share one."""
    digest = hashlib.sha256()
    for source in (module, *dependencies):
        digest.update(source.__name__.encode())
        digest.update(file_digest(str(source.__file__)).encode())
    return os.path.join(config.CACHE_DIR, f"{module.__name__}-{digest.hexdigest()[:16]}")


class _RelocatedLocator:
    """numba's locator of a kernel (its source stamp, its disambiguator), with the cache folder
    given by `relocate`; numba asks it for that folder again before each save."""

    def __init__(self, original, path: str):
        self.original = original
        self.path = path

    def get_cache_path(self) -> str:
        return self.path

    def ensure_cache_path(self) -> None:
        os.makedirs(self.path, exist_ok=True)

    def __getattr__(self, name):
        return getattr(self.original, name)


def initialise_jit() -> None:
    """Set numba's compiler up now: its typing and target registries (numba.np imports scipy's
    BLAS check among others), which the first kernel a process compiles or loads from the cache
    sets up otherwise, 0.4-1 s once per process. Called before forking workers (`--jobs`), so each
    inherits it instead of paying it again."""
    from numba.core.registry import cpu_target

    cpu_target.typing_context.refresh()
    cpu_target.target_context.refresh()


class OneSignature:
    """A cached numba function that holds one compiled version, for ``argtypes``: compiled (or
    loaded from the disk cache) at the first call, after which the dispatcher compiles nothing
    else, so a call whose arguments convert to those types (a C-contiguous array to an "A" layout
    one, a writable array to a read-only one) runs that version instead of compiling another: a
    cold first run pays one compile, not one per layout its callers happen to pass."""

    def __init__(self, dispatcher: Dispatcher, argtypes: tuple):
        self.dispatcher = dispatcher
        self.argtypes = argtypes

    def __call__(self, *args):
        if self.dispatcher._can_compile:  # the first call (a forked child inherits the state)
            self.dispatcher.compile(self.argtypes)
            self.dispatcher.disable_compile()
        return self.dispatcher(*args)


# the LLVM optimisation level of each function given one (`optimisation_level`), by its code object
_LEVELS: dict[CodeType, int] = {}
_LISTENING: list[bool] = []  # the listener registered (once per process)


def optimisation_level(level: int, *functions) -> None:
    """Compile each of ``functions`` (numba functions, or the Python function an ``@overload``
    returns) with LLVM's optimisation level ``level`` instead of numba's (NUMBA_OPT, 3 by default):
    its IR's function and module passes, which take most of a large kernel's compile (LLVM's code
    generation keeps numba's level). A function it compiles on its way keeps its own level. The
    compiled code computes the same numbers (numba asks LLVM for no fast-math), only its speed may
    differ: given only where bench/README.md measured the kernel as fast."""
    for function in functions:
        _LEVELS[getattr(function, "py_func", function).__code__] = level
    if not _LISTENING:
        event.register("numba:compile", _Levels(config.OPT))
        _LISTENING.append(True)


class _Levels(event.Listener):
    """Sets numba's optimisation level (read by its pass builders as each compile lowers and
    finalises its module) to that of the function compiling: numba compiles one function at a
    time under its compiler lock, and a call's compile nests inside its caller's typing, so a stack
    of the compiles under way says whose module is being optimised."""

    def __init__(self, default):
        self.default = default
        self.levels: list = []

    def on_start(self, event):
        py_func = getattr((event.data or {}).get("dispatcher"), "py_func", None)
        level = _LEVELS.get(getattr(py_func, "__code__", None))
        self.levels.append(self.default if level is None else type(self.default)(level))
        config.OPT = self.levels[-1]

    def on_end(self, event):
        self.levels.pop()
        config.OPT = self.levels[-1] if self.levels else self.default


def tolerate_missing_classes(cache_file) -> None:
    """Read the cache's index as empty (stale) when unpickling it fails on a class or module that
    no longer exists, as numba reads an index with an old stamp; the next save rewrites it. numba
    alone raises there on every load and every save (`IndexDataCacheFile._load_index` unpickles the
    signatures, which name a NamedTuple argument's class, before it compares stamps)."""
    load_index = getattr(cache_file, "_load_index", None)
    if load_index is None or getattr(load_index, "tolerates_missing_classes", False):
        return

    def tolerant_load_index():
        try:
            return load_index()
        except (AttributeError, ImportError, pickle.UnpicklingError):
            return {}

    tolerant_load_index.tolerates_missing_classes = True  # type: ignore[attr-defined]
    cache_file._load_index = tolerant_load_index


def source_stamp(dispatcher: Dispatcher, dependencies: list[ModuleType]) -> tuple[str, ...]:
    """The index stamp the dispatcher's cache should carry: the sha256 of its module's source and of
    each dependency's. numba's own stamp is its file's modification time and size before numba 0.6x
    (a content hash since): a copy of the same source elsewhere would read the index as stale."""
    own = sys.modules[dispatcher.py_func.__module__]
    return tuple(file_digest(str(module.__file__)) for module in (own, *dependencies))


def file_digest(path: str) -> str:
    """sha256 of the file's bytes, read once per process for each (path, size, mtime)."""
    status = os.stat(path)
    return _digest(path, status.st_size, status.st_mtime_ns)


@functools.cache
def _digest(path: str, size: int, mtime_ns: int) -> str:
    with open(path, "rb") as fh:
        return hashlib.sha256(fh.read()).hexdigest()


def cached_dispatchers(module: ModuleType) -> list[Dispatcher]:
    """The numba functions defined in ``module`` with ``cache=True``."""
    return [
        value
        for value in vars(module).values()
        if isinstance(value, Dispatcher)
        and value.py_func.__module__ == module.__name__
        and hasattr(getattr(value, "_cache", None), "_cache_file")
    ]


def kernel_dependencies(module: ModuleType) -> list[ModuleType]:
    """Every package module whose source the kernels of ``module`` may compile in, transitively,
    sorted by name: the modules it imports numba functions or constants from (``from m import
    name``), and those it imports whole (``import m``, ``from package import m``)."""
    found: dict[str, ModuleType] = {}
    todo = [module]
    while todo:
        for dependency in _direct_dependencies(todo.pop()):
            if dependency is not module and dependency.__name__ not in found:
                found[dependency.__name__] = dependency
                todo.append(dependency)
    return [found[name] for name in sorted(found)]


def _direct_dependencies(module: ModuleType) -> list[ModuleType]:
    return [sys.modules[name] for name in _imported_module_names(module)]


# a top-level import statement (kernels see module globals only; imports inside functions or
# under `if` are not theirs), parenthesised names included
_IMPORT = re.compile(r"^(?:from[ \t]+[\w.]+[ \t]+)?import[ \t]+(?:\([^)]*\)|[^\n]*)", re.MULTILINE)


@functools.cache
def _imported_module_names(module: ModuleType) -> tuple[str, ...]:
    """Names of the package modules ``module`` imports something a kernel can read from; classes
    and plain Python functions are skipped (a kernel cannot compile them in). Only the import
    statements are parsed (a whole module's syntax tree costs milliseconds at every start-up)."""
    with open(module.__file__, encoding="utf-8") as fh:
        source = fh.read()
    names = set()
    for statement in _IMPORT.finditer(source):
        try:
            node = ast.parse(statement.group(0)).body[0]
        except SyntaxError:  # an "import ..." line of a docstring
            continue
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            source_name = importlib.util.resolve_name("." * node.level + (node.module or ""), module.__package__ or "")
            for alias in node.names:
                value = vars(module).get(alias.asname or alias.name)
                if isinstance(value, ModuleType):
                    names.add(value.__name__)
                elif isinstance(value, Dispatcher):
                    names.add(value.py_func.__module__)
                elif value is not None and not isinstance(value, (type, FunctionType)):
                    names.add(source_name)
    return tuple(
        sorted(name for name in names if (name == PACKAGE or name.startswith(PACKAGE + ".")) and name in sys.modules)
    )


def kernel_cached(dispatcher, literal_first=None) -> bool:
    """True when numba's disk cache holds a compiled version of the cached ``dispatcher`` for this
    machine (with ``literal_first``: one whose first argument is that literal int); True as well
    when the cache cannot be inspected."""
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
