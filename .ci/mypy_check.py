"""The type check of CI: mypy over logscan/ and detectors/, a baseline count that may only fall, and
the core modules at 0 errors.

Usage: .venv/bin/python .ci/mypy_check.py [--list] [--lower]
  --list   print every error (by default: only the core's, or all of them when the count rose)
  --lower  write the count to .ci/mypy_baseline.txt when it fell below the baseline

mypy cannot read setuptools' package-dir mapping (detectors/ installs as logscan.detectors,
templates/ as logscan.templates; the editable install maps them with an import hook mypy does not
run), so the check builds the installed layout as a tree of symbolic links in the venv
(``<venv>/mypy/tree``, rebuilt each run, so new modules are seen) and runs ``mypy -p logscan`` there,
with its cache beside it (``<venv>/mypy/cache``: a warm run re-checks only what changed). Paths in
the output are the repository's own (``detectors/kgn.py``, not ``logscan/detectors/kgn.py``).

Exit 1 when the count rose above the baseline or a core module has an error; 2 when mypy itself fails.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASELINE = ROOT / ".ci" / "mypy_baseline.txt"
PACKAGE = "logscan"
# The core: at 0 errors, always (issue 27). A folder covers every module below it; a module that
# becomes a package of the same name stays covered.
CORE = tuple(
    f"logscan/{name}{end}"
    for name in ("pipeline", "filters", "models", "results", "alarms", "log", "align")
    for end in (".py", "/")
)
ERROR = re.compile(r"^(?P<path>[^:\s]+\.pyi?):(?P<line>\d+): error: ")


def package_dirs() -> dict[str, str]:
    """pyproject.toml's package-dir: installed package name -> folder in the repository."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    return project["tool"]["setuptools"]["package-dir"]


def build_tree(tree: Path, mapping: dict[str, str]) -> None:
    """The installed layout of `PACKAGE` under ``tree``, as symbolic links into the repository."""
    if tree.exists():
        shutil.rmtree(tree)  # removes the links, never what they point to
    top = tree / PACKAGE
    top.mkdir(parents=True)
    for entry in sorted((ROOT / mapping[PACKAGE]).iterdir()):
        if entry.name != "__pycache__":
            (top / entry.name).symlink_to(entry)
    for name, folder in sorted(mapping.items()):
        if name == PACKAGE:
            continue
        link = tree.joinpath(*name.split("."))
        if link.exists():
            raise SystemExit(f"package-dir maps {name} to {folder}/, but {link.relative_to(tree)} exists too")
        link.symlink_to(ROOT / folder)


def repository_path(path: str, mapping: dict[str, str]) -> str:
    """``logscan/detectors/kgn.py`` -> ``detectors/kgn.py``: a path in the tree as the repository's."""
    for name, folder in sorted(mapping.items(), key=lambda item: -len(item[0])):
        prefix = name.replace(".", "/") + "/"
        if path.startswith(prefix):
            return folder + "/" + path[len(prefix) :]
    return path


def run_mypy(tree: Path, cache: Path) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-m", "mypy", "--config-file", str(ROOT / "pyproject.toml")]
    command += ["--cache-dir", str(cache), "--no-error-summary", "-p", PACKAGE]
    return subprocess.run(command, cwd=tree, capture_output=True, text=True, check=False)


def read_baseline() -> int:
    lines = [line for line in BASELINE.read_text(encoding="utf-8").splitlines() if not line.startswith("#")]
    return int("".join(lines).strip())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--list", action="store_true", help="print every error")
    parser.add_argument("--lower", action="store_true", help="write a fallen count to the baseline")
    args = parser.parse_args(argv)

    started = time.monotonic()
    mapping = package_dirs()
    work = Path(sys.prefix) / "mypy"
    build_tree(work / "tree", mapping)
    done = run_mypy(work / "tree", work / "cache")
    if done.returncode not in (0, 1):
        print(done.stdout + done.stderr, file=sys.stderr)
        print(f"mypy failed (exit {done.returncode})", file=sys.stderr)
        return 2
    lines = [line for line in done.stdout.splitlines() if line.strip()]
    errors = []
    for index, line in enumerate(lines):
        match = ERROR.match(line)
        if match:
            path = repository_path(match["path"], mapping)
            lines[index] = path + line[len(match["path"]) :]
            errors.append((path, lines[index]))
    core = [line for path, line in errors if path.startswith(CORE)]
    baseline = read_baseline()
    count = len(errors)
    rose = count > baseline

    if args.list or rose:
        print("\n".join(lines))
    elif core:
        print("\n".join(core))
    files = len({path for path, _ in errors})
    print(f"mypy: {count} errors in {files} files (baseline {baseline}), core modules: {len(core)} errors")
    print(f"mypy: {time.monotonic() - started:.1f} s")
    failed = False
    if rose:
        print(f"mypy: {count - baseline} more errors than {BASELINE.relative_to(ROOT)} allows: fix the new ones")
        failed = True
    elif count < baseline:
        if args.lower:
            BASELINE.write_text(f"{count}\n", encoding="utf-8")
            print(f"mypy: {BASELINE.relative_to(ROOT)} lowered to {count}")
        else:
            print(f"mypy: the count fell: lower {BASELINE.relative_to(ROOT)} to {count} (--lower)")
    if core:
        print("mypy: the core modules (pipeline, filters, models, results, alarms, log, align) must have no errors")
        failed = True
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
