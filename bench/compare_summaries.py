"""Are the `--json` summaries of every sample log byte-identical to those of another commit?

    python bench/compare_summaries.py 93bce00            # the commit before a refactoring
    python bench/compare_summaries.py 93bce00 --start 10 --end 40   # each run given these flags too

Checks the other commit out into a temporary git worktree, runs `logscan analyze LOG --no-report
--json OUT` with that commit's code and with this checkout's on every sample log (the .mcap files,
quad_healthy.csv and husky_drive.bag), and compares the files byte for byte. The other commit's
code runs in this venv (its dependencies must be the same); its import is forced to the worktree
(the editable install's finder is left out), and the run checks that it was. Prints one line per
log, and under a differing one the JSON fields that differ (list indices as [*]) with the largest
relative change of their numbers, and exits 1 when any summary differs. A refactoring that moves
code and changes no number leaves every summary identical.
"""

from __future__ import annotations

import filecmp
import json
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
SAMPLES = REPO / "sample_logs"

# runs the CLI of the checkout at argv[1] (a path), whatever the venv's editable install points at
RUNNER = """
import sys
root = sys.argv.pop(1)
sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in (type(f).__name__ + type(f).__module__).lower()]
sys.path.insert(0, root)
import logscan
assert logscan.__file__.startswith(root), logscan.__file__
from logscan.cli.main import main
sys.exit(main(sys.argv[1:]))
"""


def sample_logs() -> list[Path]:
    return sorted(SAMPLES.glob("*.mcap")) + [SAMPLES / "quad_healthy.csv", SAMPLES / "husky_drive.bag"]


def summarise(root: Path, log: Path, out: Path, flags: list[str]) -> None:
    cmd = [sys.executable, "-c", RUNNER, str(root), "analyze", str(log), "--no-report", "--json", str(out), *flags]
    subprocess.run(cmd, capture_output=True, text=True, timeout=900, cwd=REPO)
    if not out.exists():
        raise SystemExit(f"{log.name}: no summary written by {root}")


def differing_fields(old: object, new: object, path: str = "") -> dict[str, float]:
    """The JSON paths where two documents differ, list indices written [*] so that a field that
    differs in every element of a list is one line, each with the largest relative change of its
    numbers (inf where a value is not a number or changed type)."""
    if isinstance(old, dict) and isinstance(new, dict):
        fields: dict[str, float] = {}
        for key in old.keys() | new.keys():
            if key not in old or key not in new:
                fields[f"{path}.{key} ({'only now' if key in new else 'only before'})"] = float("inf")
            else:
                _merge(fields, differing_fields(old[key], new[key], f"{path}.{key}"))
        return fields
    if isinstance(old, list) and isinstance(new, list) and len(old) == len(new):
        fields = {}
        for a, b in zip(old, new, strict=True):
            _merge(fields, differing_fields(a, b, f"{path}[*]"))
        return fields
    if old == new:
        return {}
    numbers = all(isinstance(v, int | float) and not isinstance(v, bool) for v in (old, new))
    change = abs(new - old) / max(abs(old), abs(new)) if numbers else float("inf")  # type: ignore[operator]
    return {path or ".": change}


def _merge(into: dict[str, float], more: dict[str, float]) -> None:
    for name, change in more.items():
        into[name] = max(into.get(name, 0.0), change)


def main(argv: list[str]) -> int:
    if not argv or argv[0].startswith("-"):
        print(__doc__)
        return 2
    base, flags = argv[0], argv[1:]
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "base"
        subprocess.run(["git", "worktree", "add", "-q", "--detach", str(tree), base], cwd=REPO, check=True)
        try:
            differ = 0
            for log in sample_logs():
                old, new = Path(tmp) / f"{log.name}.base.json", Path(tmp) / f"{log.name}.now.json"
                summarise(tree, log, old, flags)
                summarise(REPO, log, new, flags)
                same = filecmp.cmp(old, new, shallow=False)
                differ += not same
                print(f"{'same' if same else 'DIFFERS'}  {log.name}")
                if not same:
                    before, now = (json.loads(path.read_text(encoding="utf-8")) for path in (old, new))
                    for name, change in sorted(differing_fields(before, now).items()):
                        print(f"    {name}  (largest relative change {change:.1e})")
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=REPO, check=False)
    print(f"{len(sample_logs()) - differ} of {len(sample_logs())} summaries byte-identical to {base}")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
