"""The numba disk cache of a kernel goes stale when any module it compiles in changes."""

from __future__ import annotations

import importlib
import re
import sys
from pathlib import Path
from typing import NamedTuple

import pytest
from numba.core.caching import IndexDataCacheFile

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
    """Every package module whose source declares a cached numba function."""
    names = []
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        if CACHED_KERNEL.search(path.read_text(encoding="utf-8")):
            parts = path.relative_to(PACKAGE_DIR.parent).with_suffix("").parts
            names.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return names


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
