"""The numba disk cache of a kernel goes stale when any module it compiles in changes, and is filed
by those modules' sources, not by where the package lies."""

from __future__ import annotations

import importlib
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import NamedTuple

import pytest
from numba.core.caching import IndexDataCacheFile

import logscan.detectors
from logscan import numba_cache
from logscan.filters import ekf
from logscan.simulate import runner

PACKAGE_DIR = Path(numba_cache.__file__).parent
CACHED_KERNEL = re.compile(r"^@(numba\.)?n?jit\(.*cache=True", re.MULTILINE)
MODEL_KERNEL_MODULES = sorted(
    f"logscan.models.{path.stem}"
    for path in (PACKAGE_DIR / "models").glob("*.py")
    if path.stem.endswith("_kernels") or path.stem in ("rk4", "dispatch")
)


def modules_with_cached_kernels() -> list[str]:
    """Every package module whose source declares a cached numba function (logscan.detectors lives
    in the checkout's detectors/ folder)."""
    names = []
    for folder, prefix in ((PACKAGE_DIR, ()), (Path(logscan.detectors.__path__[0]), ("logscan", "detectors"))):
        for path in sorted(folder.rglob("*.py")):
            if CACHED_KERNEL.search(path.read_text(encoding="utf-8")):
                parts = path.relative_to(folder.parent if not prefix else folder).with_suffix("").parts
                parts = (*prefix, *parts)
                names.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return sorted(set(names))


def names(modules) -> set[str]:
    return {module.__name__ for module in modules}


def test_the_ekf_kernel_depends_on_dispatch_linear_algebra_and_every_model_kernel_module():
    assert len(MODEL_KERNEL_MODULES) >= 5
    expected = {*MODEL_KERNEL_MODULES, "logscan.filters.linalg", "logscan.filters.coding"}
    assert names(numba_cache.kernel_dependencies(ekf)) == expected


def test_the_simulator_kernel_depends_on_the_models_controllers_and_fault_codes():
    expected = {*MODEL_KERNEL_MODULES, "logscan.simulate.controllers", "logscan.simulate.faults"}
    assert names(numba_cache.kernel_dependencies(runner)) == expected


def test_classes_and_python_functions_are_not_kernel_dependencies():
    # ekf.py imports AlignedRun, ModelError, Model, EkfTrace and divergence_episodes too
    found = names(numba_cache.kernel_dependencies(ekf))
    for module in (
        "logscan.align",
        "logscan.errors",
        "logscan.models.base",
        "logscan.traces",
        "logscan.numba_cache",
    ):
        assert module not in found


@pytest.mark.parametrize("module_name", modules_with_cached_kernels())
def test_every_cached_kernel_carries_the_stamp_of_its_dependencies(module_name):
    module = importlib.import_module(module_name)
    dependencies = numba_cache.kernel_dependencies(module)
    dispatchers = numba_cache.cached_dispatchers(module)
    assert dispatchers
    for dispatcher in dispatchers:
        stamp = dispatcher._cache._cache_file._source_stamp
        assert stamp == numba_cache.source_stamp(dispatcher, dependencies), (
            f"{module_name} imports kernels or constants of {names(dependencies)}: "
            "end it with `follow_dependencies(__name__)` (logscan.numba_cache)"
        )


@pytest.mark.parametrize("module_name", modules_with_cached_kernels())
def test_every_cached_kernel_is_filed_by_its_sources_not_by_its_path(module_name):
    module = importlib.import_module(module_name)
    folder = numba_cache.relocated_path(module, numba_cache.kernel_dependencies(module))
    assert os.path.basename(folder).startswith(module_name + "-")
    for dispatcher in numba_cache.cached_dispatchers(module):
        cache = dispatcher._cache
        assert cache._cache_path == cache._cache_file._cache_path == folder, (
            f"{module_name}: end it with `follow_dependencies(__name__)` (logscan.numba_cache)"
        )
        assert os.path.dirname(cache._cache_file._index_path) == folder
        assert cache._impl.locator.get_cache_path() == folder


def test_a_copy_elsewhere_shares_the_folder_and_an_edit_moves_it(tmp_path, monkeypatch):
    """The folder is named by the module and the digest of the sources: the same sources at another
    path (another install) share it; one edited byte in the module or a dependency is another."""
    module = importlib.import_module("logscan.filters.ekf")
    dependencies = numba_cache.kernel_dependencies(module)
    here = numba_cache.relocated_path(module, dependencies)
    copy = tmp_path / "elsewhere" / "ekf.py"
    copy.parent.mkdir()
    shutil.copy2(module.__file__, copy)
    os.utime(copy, (1, 1))  # another install: another path and time, the same bytes
    stamp = numba_cache.source_stamp(module.ekf_run, dependencies)
    monkeypatch.setattr(module, "__file__", str(copy))
    assert numba_cache.relocated_path(module, dependencies) == here
    # and the index's stamp: the bytes, not numba's modification time (numba < 0.6x)
    assert numba_cache.source_stamp(module.ekf_run, dependencies) == stamp
    monkeypatch.setattr(module, "__file__", changed_copy(module, tmp_path))
    assert numba_cache.relocated_path(module, dependencies) != here
    monkeypatch.undo()
    linalg = importlib.import_module("logscan.filters.linalg")
    monkeypatch.setattr(linalg, "__file__", changed_copy(linalg, tmp_path))
    assert numba_cache.relocated_path(module, dependencies) != here


@pytest.mark.slow
def test_a_second_copy_of_the_package_loads_the_kernels_the_first_compiled(tmp_path):
    """Two copies of the package (a checkout and an install, or two venvs) with one cache: a
    kernel the first compiled, the second loads without compiling."""
    code = (
        "import sys; sys.path.insert(0, sys.argv[1]); import logscan.filters.linalg as m;"
        "assert m.__file__.startswith(sys.argv[1]), m.__file__;"
        "m.wrap_angle(1.0); print(len(m.wrap_angle.stats.cache_misses), len(m.wrap_angle.stats.cache_hits))"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}
    env["LOGSCAN_CACHE_DIR"] = str(tmp_path / "cache")
    counts = []
    for copy in ("first", "second"):
        shutil.copytree(PACKAGE_DIR, tmp_path / copy / "logscan", ignore=shutil.ignore_patterns("__pycache__"))
        done = subprocess.run(
            [sys.executable, "-c", code, str(tmp_path / copy)], env=env, cwd=tmp_path, capture_output=True, text=True
        )
        assert done.returncode == 0, done.stderr[-2000:]
        counts.append(done.stdout.split())
    assert counts == [["1", "0"], ["0", "1"]]


def changed_copy(module, tmp_path: Path) -> str:
    """A copy of the module's source with one more comment line: an edited dependency."""
    copy = tmp_path / Path(module.__file__).name
    copy.write_text(Path(module.__file__).read_text(encoding="utf-8") + "# edited\n", encoding="utf-8")
    return str(copy)


@pytest.mark.parametrize(
    ("kernel_module", "kernel", "dependency"),
    [
        ("logscan.filters.ekf", "ekf_run", name)
        for name in (*MODEL_KERNEL_MODULES, "logscan.filters.linalg", "logscan.filters.coding")
    ]
    + [
        ("logscan.simulate.runner", "closed_loop", name)
        for name in (*MODEL_KERNEL_MODULES, "logscan.simulate.controllers", "logscan.simulate.faults")
    ],
)
def test_an_edited_dependency_makes_the_cached_index_stale(kernel_module, kernel, dependency, tmp_path, monkeypatch):
    """numba reads a cached index only when its stamp equals the one the dispatcher carries
    (IndexDataCacheFile._load_index): an index saved before a dependency changed is not used."""
    module = importlib.import_module(kernel_module)
    dispatcher = getattr(module, kernel)
    before = dispatcher._cache._cache_file._source_stamp
    saved = IndexDataCacheFile(str(tmp_path), "kernel", before)
    saved.save(("signature",), "compiled code")
    assert IndexDataCacheFile(str(tmp_path), "kernel", before).load(("signature",)) is not None

    edited = importlib.import_module(dependency)
    monkeypatch.setattr(edited, "__file__", changed_copy(edited, tmp_path))
    try:
        numba_cache.follow_dependencies(kernel_module)
        after = dispatcher._cache._cache_file._source_stamp
        assert after != before
        assert IndexDataCacheFile(str(tmp_path), "kernel", after).load(("signature",)) is None
    finally:
        monkeypatch.undo()
        numba_cache.follow_dependencies(kernel_module)
    assert dispatcher._cache._cache_file._source_stamp == before


class RenamedArgument(NamedTuple):
    """A kernel's NamedTuple argument, renamed (deleted from this module) after a cache was saved."""

    x: int


def test_an_index_naming_a_class_since_renamed_is_stale_not_an_error(tmp_path, monkeypatch):
    saved = IndexDataCacheFile(str(tmp_path), "kernel", "stamp")
    saved.save((RenamedArgument(1),), "compiled code")
    monkeypatch.delattr(sys.modules[__name__], "RenamedArgument")
    with pytest.raises(AttributeError):  # numba alone fails on every load (and save) of the kernel
        IndexDataCacheFile(str(tmp_path), "kernel", "stamp").load(("signature",))
    cache_file = IndexDataCacheFile(str(tmp_path), "kernel", "stamp")
    numba_cache.tolerate_missing_classes(cache_file)
    assert cache_file.load(("signature",)) is None
    cache_file.save(("signature",), "recompiled code")  # the next save rewrites the index
    assert IndexDataCacheFile(str(tmp_path), "kernel", "stamp").load(("signature",)) == "recompiled code"


@pytest.mark.parametrize(
    "module_name", ["logscan.filters.ekf", "logscan.filters.ubikf_kernel", "logscan.verdict.observability_kernel"]
)
def test_kernels_with_namedtuple_arguments_tolerate_a_renamed_class(module_name):
    for dispatcher in numba_cache.cached_dispatchers(importlib.import_module(module_name)):
        assert dispatcher._cache._cache_file._load_index.tolerates_missing_classes


def test_a_function_given_a_level_is_optimised_at_it_and_what_it_compiles_on_its_way_at_numbas():
    """LLVM's module passes of a function given a level run at it; a callee compiled during its
    typing keeps numba's level, and the level in force after the compile is numba's again."""
    import numba
    from numba.core import codegen, config

    @numba.njit
    def callee(x):
        return x + 1.0

    @numba.njit
    def caller(x):
        return callee(x) * 2.0

    numba_cache.optimisation_level(1, caller)
    levels = {}
    optimise = codegen.CPUCodeLibrary._optimize_final_module

    def recorded(library):
        levels[library.name.rsplit(".", 1)[-1]] = int(config.OPT)
        return optimise(library)

    default = config.OPT
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(codegen.CPUCodeLibrary, "_optimize_final_module", recorded)
        assert caller(1.0) == 4.0
    assert levels["caller"] == 1
    assert levels["callee"] == int(default)
    assert config.OPT is default


def test_a_folder_that_cannot_be_written_leaves_numbas_own(tmp_path, monkeypatch):
    """A relocated folder that exists but cannot be written (another user's) is not used: numba's
    own folder stays, so a save cannot fail there."""
    module = importlib.import_module("logscan.filters.linalg")
    dispatcher = module.wrap_angle
    before = dispatcher._cache._cache_path
    locked = tmp_path / "locked"
    locked.mkdir()
    monkeypatch.setattr(os, "access", lambda path, mode: str(path) != str(locked))
    numba_cache.relocate(dispatcher, str(locked))
    assert dispatcher._cache._cache_path == before
    monkeypatch.undo()
    numba_cache.relocate(dispatcher, str(locked))
    assert dispatcher._cache._cache_path == str(locked)
    numba_cache.follow_dependencies("logscan.filters.linalg")
    assert dispatcher._cache._cache_path == before
