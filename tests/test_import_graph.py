"""The import graph of logscan, read from the sources' syntax trees: no cycle, also not through an
import inside a function, and an internal import inside a function only where it buys start-up time.

Every module of the mapped packages (pyproject's `package-dir`: logscan/, detectors/ as
`logscan.detectors`, templates/ as `logscan.templates`) is parsed; each import of an internal module,
at module level or inside a function or method, becomes an edge. `from pkg import name` is an edge to
the submodule `pkg.name` when there is one, else to `pkg`; relative imports are resolved the same way.
Importing `a.b.c` also runs the `__init__` of `a.b`, so the target's packages are edges too, except the
importer's own ancestors (Python initialises them before the importer). Imports under
`if TYPE_CHECKING:` never run and are not edges.
"""

from __future__ import annotations

import ast
import fnmatch
import re
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
ROOT = "logscan"

# The modules whose functions may import internal modules (fnmatch patterns), each for start-up time:
FUNCTION_IMPORTS_ALLOWED = (
    # the CLI: a command loads the library only when it runs, so `logscan --help` (and every other
    # command) does not pay for the numba kernels, plotly, scipy and pandas it does not use
    "logscan.cli.*",
    # the format table: a log is read by one reader, and each pulls its own heavy library (the MCAP
    # reader's numba kernels, rosbags, pandas for CSV), so reading one format does not load the others
    "logscan.readers",
    # the per-log analysis task: plotly and the report's modules (~58 MB) load only once the
    # detectors are done, and only for a log that gets a report
    "logscan.tasks",
)

# Shared foundations left flat in logscan/ (everything else lives in a folder per layer), plus
# __init__.py and __main__.py.
MAX_FLAT_MODULES = 17


@dataclass(frozen=True)
class Import:
    importer: str
    target: str
    path: Path
    line: int
    in_function: bool
    for_types: bool = False  # under `if TYPE_CHECKING:`: never run, but still a dependency

    def where(self) -> str:
        source = self.path.read_text(encoding="utf-8").splitlines()[self.line - 1].strip()
        return f"{self.path.relative_to(REPO)}:{self.line}: {source}"


def package_dirs() -> dict[str, Path]:
    config = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
    return {name: REPO / folder for name, folder in config["tool"]["setuptools"]["package-dir"].items()}


def internal_modules() -> dict[str, Path]:
    """Every module of the mapped packages by dotted name (a package under its own name)."""
    modules = {}
    for package, folder in package_dirs().items():
        for path in folder.rglob("*.py"):
            parts = path.relative_to(folder).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join((package, *parts))] = path
    return modules


def ancestors(module: str) -> list[str]:
    parts = module.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


class _ImportVisitor(ast.NodeVisitor):
    def __init__(self, module: str, path: Path, modules: dict[str, Path]):
        self.module, self.path, self.modules = module, path, modules
        self.package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        self.depth = 0
        self.for_types = False
        self.found: list[Import] = []

    def visit_FunctionDef(self, node: ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda) -> None:
        self.depth += 1
        self.generic_visit(node)
        self.depth -= 1

    visit_AsyncFunctionDef = visit_Lambda = visit_FunctionDef

    def visit_If(self, node: ast.If) -> None:
        if is_type_checking(node.test):
            self.for_types = True
            for child in node.body:
                self.visit(child)
            self.for_types = False
            for child in node.orelse:
                self.visit(child)
        else:
            self.generic_visit(node)

    def visit_Import(self, node: ast.Import) -> None:
        for alias in node.names:
            self.add(alias.name, node)

    def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
        base = node.module or ""
        if node.level:
            package = self.package.split(".")
            package = package[: len(package) - node.level + 1]
            base = ".".join([*package, base] if base else package)
        for alias in node.names:
            submodule = f"{base}.{alias.name}"
            self.add(submodule if submodule in self.modules else base, node)

    def add(self, name: str, node: ast.stmt) -> None:
        if name != ROOT and not name.startswith(ROOT + "."):
            return
        while name not in self.modules:  # `import a.b.attr`-like spellings: the longest known module
            name = name.rpartition(".")[0]
        own = {*ancestors(self.module), self.module}
        for target in (*ancestors(name), name):
            edge = Import(self.module, target, self.path, node.lineno, self.depth > 0, self.for_types)
            if target not in own and edge not in self.found:
                self.found.append(edge)


def module_imports(
    module: str, path: Path, modules: dict[str, Path], source: str | None = None, *, for_types: bool = False
) -> list[Import]:
    visitor = _ImportVisitor(module, path, modules)
    visitor.visit(ast.parse(path.read_text(encoding="utf-8") if source is None else source, str(path)))
    return visitor.found if for_types else [edge for edge in visitor.found if not edge.for_types]


def internal_imports(*, for_types: bool = False) -> list[Import]:
    """Every internal import that runs; with ``for_types``, also those only the type checker reads
    (a cycle through them is a cycle all the same: the modules cannot be read apart)."""
    modules = internal_modules()
    return [
        edge
        for module, path in sorted(modules.items())
        for edge in module_imports(module, path, modules, for_types=for_types)
    ]


def strongly_connected(graph: dict[str, set[str]]) -> Iterator[list[str]]:
    """Tarjan's strongly connected components of `graph` (iterative: no recursion limit)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is None:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    yield sorted(component)
            elif child not in index:
                index[child] = low[child] = len(index)
                stack.append(child)
                on_stack.add(child)
                work.append((child, iter(sorted(graph.get(child, ())))))
            elif child in on_stack:
                low[node] = min(low[node], index[child])


def import_cycles(imports: list[Import]) -> list[list[Import]]:
    """The imports inside each cycle of the graph, one list per strongly connected component."""
    graph: dict[str, set[str]] = {}
    for edge in imports:
        graph.setdefault(edge.importer, set()).add(edge.target)
        graph.setdefault(edge.target, set())
    cycles = []
    for component in strongly_connected(graph):
        members = set(component)
        inside = [edge for edge in imports if edge.importer in members and edge.target in members]
        if len(component) > 1 or inside:
            cycles.append(inside)
    return cycles


def allowed_in_function(module: str) -> bool:
    return any(fnmatch.fnmatchcase(module, pattern) for pattern in FUNCTION_IMPORTS_ALLOWED)


def test_imports_are_resolved_to_the_modules_they_run():
    modules = {
        name: Path(f"{name.replace('.', '/')}.py")
        for name in ("logscan", "logscan.a", "logscan.a.b", "logscan.a.c", "logscan.d", "logscan.d.e")
    }
    modules["logscan.a"] = Path("logscan/a/__init__.py")
    source = """
from typing import TYPE_CHECKING
import numpy
from logscan.a import c, helper
from . import b
from ..d.e import thing
if TYPE_CHECKING:
    import logscan.d
def f():
    import logscan.d.e.attr
"""
    found = module_imports("logscan.a.b", Path("logscan/a/b.py"), modules, source)
    assert [(edge.target, edge.line, edge.in_function) for edge in found] == [
        ("logscan.a.c", 4, False),  # a submodule named in a from-import; the own package is no edge
        ("logscan.d", 6, False),  # the target's package runs first
        ("logscan.d.e", 6, False),
        ("logscan.d", 10, True),
        ("logscan.d.e", 10, True),
    ]


def test_the_graph_holds_the_repository_s_imports():
    imports = internal_imports()
    edges = {(edge.importer, edge.target) for edge in imports}
    assert ("logscan.pipeline.run", "logscan.pipeline.stages") in edges
    assert ("logscan.detectors.registry", "logscan.detectors.base") in edges  # detectors/ as logscan.detectors
    assert any(edge.in_function for edge in imports)  # the CLI commands' own imports
    assert len({edge.importer for edge in imports}) > 100


def test_the_cycle_finder_finds_a_cycle_through_a_function_level_import():
    path = REPO / "pyproject.toml"
    imports = [
        Import("logscan.a", "logscan.b", path, 1, False),
        Import("logscan.b", "logscan.c", path, 1, False),
        Import("logscan.c", "logscan.a", path, 1, True),
        Import("logscan.c", "logscan.d", path, 1, False),
    ]
    assert [sorted(edge.importer for edge in cycle) for cycle in import_cycles(imports)] == [
        ["logscan.a", "logscan.b", "logscan.c"]
    ]
    assert import_cycles(imports[:2] + imports[3:]) == []


def test_no_import_cycle_even_through_function_level_imports():
    cycles = import_cycles(internal_imports(for_types=True))
    lines = []
    for cycle in cycles:
        lines.append("cycle: " + " <-> ".join(sorted({edge.importer for edge in cycle})))
        lines.extend("    " + edge.where() for edge in cycle)
    assert not cycles, "\n".join(lines)


def test_internal_imports_inside_functions_only_where_they_save_start_up_time():
    misplaced = [edge for edge in internal_imports() if edge.in_function and not allowed_in_function(edge.importer)]
    assert not misplaced, "move these imports to the top of their module:\n" + "\n".join(
        sorted({edge.where() for edge in misplaced})
    )


def test_only_the_shared_foundations_stay_flat_in_logscan():
    flat = sorted(path.name for path in (REPO / "logscan").glob("*.py"))
    assert len(flat) <= MAX_FLAT_MODULES, f"{len(flat)} flat modules (give each layer its folder): {flat}"


def test_no_package_binds_a_name_that_hides_one_of_its_modules():
    """`from logscan.pipeline.prepare import prepare` in the package's __init__ used to rebind
    `logscan.pipeline.prepare` from the module to the function, so patching the module by its
    dotted path patched the function instead. A package's own names and its modules' differ."""
    modules = internal_modules()
    hidden = []
    for package, path in modules.items():
        if path.name != "__init__.py":
            continue
        bound = set()
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if isinstance(node, ast.ImportFrom):
                bound |= {alias.asname or alias.name for alias in node.names}
            elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                bound.add(node.name)
        hidden += [f"{package}.{name}" for name in sorted(bound) if f"{package}.{name}" in modules]
    assert not hidden, f"package names that hide a module of the same name: {hidden}"


def crossings(importers: str, targets: tuple[str, ...]) -> list[str]:
    """The imports from the modules under ``importers`` into those under any of ``targets``."""

    def under(module: str, package: str) -> bool:
        return module == package or module.startswith(package + ".")

    return sorted(
        {
            edge.where()
            for edge in internal_imports()
            if under(edge.importer, importers) and any(under(edge.target, t) for t in targets)
        }
    )


def test_the_verdicts_run_no_pipeline_fleet_command_or_report():
    # verdict/ judges an analysis it is given (scores, incidents, coverage, suppressions): the
    # per-log work that runs the pipeline over a fleet is logscan.tasks, above it
    crossing = crossings("logscan.verdict", ("logscan.pipeline", "logscan.fleet", "logscan.cli", "logscan.report"))
    assert not crossing, "logscan.verdict reaches above itself:\n" + "\n".join(crossing)


# The filters' pure maths a detector may use itself; the filters that run over a log (ekf, ubikf)
# are the pipeline's, asked for through `Detector.needs` (and `Needs.probes` for re-filtering in fit).
DETECTORS_MAY_IMPORT_FROM_FILTERS = ("logscan.filters.box_chi2",)


def filter_runs_in_detectors(imports: list[Import]) -> list[Import]:
    """The imports (one per source line) by which a module of detectors/ (`logscan.detectors`) would
    run a filter: an import from logscan.filters must name one of the allowed helper modules
    (`from logscan.filters import run_ekf`, whose only edge is the package, is refused too)."""
    per_line: dict[tuple[str, int], list[Import]] = {}
    for edge in imports:
        if edge.importer.startswith("logscan.detectors.") and edge.target.startswith("logscan.filters"):
            per_line.setdefault((edge.importer, edge.line), []).append(edge)
    refused = []
    for edges in per_line.values():
        modules = {edge.target for edge in edges} - {"logscan.filters"}
        if not modules or not modules <= set(DETECTORS_MAY_IMPORT_FROM_FILTERS):
            refused.append(edges[0])
    return refused


def test_the_filter_rule_refuses_a_filter_and_its_package_re_export_not_a_helper():
    path = REPO / "pyproject.toml"

    def line(number: int, *targets: str) -> list[Import]:
        return [Import("logscan.detectors.x", target, path, number, False) for target in targets]

    imports = [
        *line(1, "logscan.filters", "logscan.filters.ekf"),  # from logscan.filters.ekf import run_ekf
        *line(2, "logscan.filters"),  # from logscan.filters import run_ekf
        *line(3, "logscan.filters", "logscan.filters.box_chi2"),  # a maths helper
        Import("logscan.pipeline.stages", "logscan.filters.ekf", path, 4, False),  # the pipeline filters
    ]
    assert [edge.line for edge in filter_runs_in_detectors(imports)] == [1, 2]


def test_detectors_ask_and_the_pipeline_filters():
    refused = sorted({edge.where() for edge in filter_runs_in_detectors(internal_imports())})
    assert not refused, "detectors ask the pipeline for filter traces (Detector.needs):\n" + "\n".join(refused)


LAYERS_DOC = REPO / "docs" / "extending.md"  # its section "Who imports whom"
UNIT = re.compile(r"[a-z_]+(?:/|\.py)")  # a folder (`verdict/`) or a flat module (`tasks.py`)


def unit(module: str, modules: dict[str, Path]) -> str:
    """The folder (``verdict/``) or flat module (``tasks.py``) of logscan a module belongs to; "" for
    the package `logscan` itself."""
    parts = module.split(".")
    if len(parts) == 1:
        return ""
    return f"{parts[1]}/" if len(parts) > 2 or modules[module].name == "__init__.py" else f"{parts[1]}.py"


def documented_layers(text: str) -> tuple[set[str], dict[str, set[str] | None]]:
    """From the section "Who imports whom": the foundations (the ``x.py`` names of its first paragraph)
    and, per folder or flat module of its list, what it may import besides them (None: every folder)."""
    section = text.split("### Who imports whom", 1)[1].split("\n#", 1)[0]
    intro, _, rest = section.partition("\n- ")
    foundations = {name for name in re.findall(r"`([^`]+)`", intro) if UNIT.fullmatch(name) and name.endswith(".py")}
    allowed: dict[str, set[str] | None] = {}
    for item in ("- " + rest).split("\n- "):
        head, _, body = item.removeprefix("- ").partition(": ")
        body = body.split("\n\n", 1)[0]
        names = {name for name in re.findall(r"`([^`]+)`", body) if UNIT.fullmatch(name)}
        allowed[head.strip("`")] = None if "every folder" in body else names
    return foundations, allowed


def test_the_layer_list_is_read_as_written():
    text = """### Who imports whom\n\nFlat in `logscan/`: `a.py`, `b.py` (`tests/x.py` is no unit).\n\n- `one/`: nothing
- `two/`: `one/`, `three/` (only `three/helper.py`)\n- `cli/`: every folder\n\nProse after the list.\n\n## Next"""
    assert documented_layers(text) == ({"a.py", "b.py"}, {"one/": set(), "two/": {"one/", "three/"}, "cli/": None})


def test_every_folder_imports_only_what_docs_extending_md_lists():
    modules = internal_modules()
    foundations, allowed = documented_layers(LAYERS_DOC.read_text(encoding="utf-8"))
    units = {unit(module, modules) for module in modules} - {""}
    unlisted = units - foundations - set(allowed)
    assert not unlisted, f"not in {LAYERS_DOC.name}'s list: {unlisted}"
    assert not set(allowed) - units, f"listed but not in logscan/: {set(allowed) - units}"
    crossing = set()
    for edge in internal_imports():
        importer, target = unit(edge.importer, modules), unit(edge.target, modules)
        if not target or importer == target or target in foundations:
            continue
        may = set() if importer in foundations else allowed[importer]
        if may is not None and target not in may:
            crossing.add(f"{importer} -> {target}: {edge.where()}")
    assert not crossing, f'imports {LAYERS_DOC.name} does not allow ("Who imports whom"):\n' + "\n".join(
        sorted(crossing)
    )


def test_every_allow_list_entry_still_has_an_import_inside_a_function():
    importers = {edge.importer for edge in internal_imports() if edge.in_function}
    stale = [p for p in FUNCTION_IMPORTS_ALLOWED if not any(fnmatch.fnmatchcase(m, p) for m in importers)]
    assert not stale, f"allowed but unused (drop them from the list): {stale}"


def test_the_verdicts_import_nothing_from_the_simulator():
    # the verdicts judge any log, simulated or not: the observability verdict's actuator names and
    # mixers are the model's (`Model.actuators`, which the simulator reads too), not a scenario's
    crossing = [
        edge.where()
        for edge in internal_imports()
        if edge.importer.startswith("logscan.verdict") and edge.target.startswith("logscan.simulate")
    ]
    assert not crossing, "logscan.verdict imports the simulator:\n" + "\n".join(sorted(set(crossing)))
