"""The README's first `analyze` cold (empty numba cache: every kernel compiles) against warm.

Runs `python -m logscan analyze sample_logs/quad_imu_bias.mcap --no-report` (or --log) in fresh
processes: "cold" with an empty cache directory, "warm" again on the cache the cold run filled
(best of --warm runs); wall time and CPU time (the process and its children: the background
compile). With --before PYTHON (the interpreter of another checkout's virtual environment, e.g. an
older commit) or --before-tree PATH (another source tree run with this venv, its import forced to
that tree as bench/compare_summaries.py does), the two trees alternate round by round in one
session, so the figures compare under the same machine load. Prints one table; figures go in
bench/README.md.

    python bench/bench_first_run.py --rounds 3
    python bench/bench_first_run.py --rounds 3 --before ../before/.venv/bin/python
    python bench/bench_first_run.py --rounds 2 --log sample_logs/quad_healthy.mcap --before-tree /tmp/before
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SAMPLE = Path(__file__).resolve().parents[1] / "sample_logs" / "quad_imu_bias.mcap"

sys.path.insert(0, str(Path(__file__).resolve().parent))

# runs the CLI of the source tree at argv[1], whatever the venv's editable install points at
from compare_summaries import RUNNER as TREE_RUNNER  # noqa: E402


def command(tree: str) -> list[str]:
    """The command that runs `logscan` of a tree: a python (its own checkout) or a source directory."""
    if Path(tree).is_dir():
        return [sys.executable, "-c", TREE_RUNNER, str(Path(tree).resolve())]
    return [tree, "-m", "logscan"]


def timed_run(tree: str, cwd: Path, cache: Path, log: Path) -> tuple[float, float]:
    """(wall s, CPU s of the process and its children) of one `analyze`."""
    env = {k: v for k, v in os.environ.items() if k not in ("LOGSCAN_CACHE_DIR", "PYTHONPATH")}
    env["NUMBA_CACHE_DIR"] = str(cache)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    result = subprocess.run([*command(tree), "analyze", str(log), "--no-report"], cwd=cwd, env=env, capture_output=True)
    elapsed = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if result.returncode not in (0, 1):
        raise SystemExit(f"{tree}: analyze failed ({result.returncode}):\n{result.stderr.decode()[-2000:]}")
    return elapsed, (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)


def measure(tree: str, warm_runs: int, log: Path) -> tuple[float, float, float]:
    """(cold wall s, cold CPU s, best warm wall s) of one tree, each in a fresh cache directory."""
    with tempfile.TemporaryDirectory(prefix="logscan-cache-") as cache, tempfile.TemporaryDirectory() as cwd:
        cold, cold_cpu = timed_run(tree, Path(cwd), Path(cache), log)
        warm = min(timed_run(tree, Path(cwd), Path(cache), log)[0] for _ in range(warm_runs))
    return cold, cold_cpu, warm


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--warm", type=int, default=3, help="warm runs per round (best is kept)")
    parser.add_argument("--before", help="python of another checkout's venv to compare with")
    parser.add_argument("--before-tree", help="another source tree to compare with (run with this venv)")
    parser.add_argument("--tree", help="the source tree measured as 'this tree' (default: this checkout)")
    parser.add_argument("--log", type=Path, default=SAMPLE, help=f"the log analysed (default {SAMPLE.name})")
    args = parser.parse_args()
    trees = {"this tree": args.tree or sys.executable}
    before_tree = args.before_tree or args.before
    if before_tree:
        trees = {"before": before_tree, **trees}
    figures: dict[str, list[tuple[float, float, float]]] = {name: [] for name in trees}
    for round_no in range(args.rounds):
        for name, tree in trees.items():
            cold, cpu, warm = measure(tree, args.warm, args.log)
            figures[name].append((cold, cpu, warm))
            line = f"round {round_no + 1} {name}: cold {cold:.2f} s ({cpu:.2f} s CPU), warm {warm:.2f} s"
            print(line, file=sys.stderr)
    print(f"`logscan analyze {args.log.name}` ({os.cpu_count()} cores, load {os.getloadavg()[0]:.1f})\n")
    print("| tree | cold s (each round) | cold CPU s (each round) | warm s (each round) | median cold / warm |")
    print("|---|---|---|---|---:|")
    for name, runs in figures.items():
        colds = " / ".join(f"{c:.2f}" for c, _, _ in runs)
        cpus = " / ".join(f"{c:.2f}" for _, c, _ in runs)
        warms = " / ".join(f"{w:.2f}" for _, _, w in runs)
        ratio = statistics.median(c for c, _, _ in runs) / statistics.median(w for _, _, w in runs)
        print(f"| {name} | {colds} | {cpus} | {warms} | {ratio:.1f} |")
    if before_tree:
        for i, what in ((0, "cold run"), (1, "cold CPU")):
            before = statistics.median(r[i] for r in figures["before"])
            after = statistics.median(r[i] for r in figures["this tree"])
            print(f"\n{what}, this tree / before: {after / before:.2f}")


if __name__ == "__main__":
    main()
