"""The README's first `analyze` cold (empty numba cache: every kernel compiles) against warm.

Runs `python -m logscan analyze sample_logs/quad_imu_bias.mcap --no-report` in fresh processes:
"cold" with an empty cache directory, "warm" again on the cache the cold run filled (best of
--warm runs). With --before PYTHON (the interpreter of another checkout's virtual environment,
e.g. an older commit), the two trees alternate round by round in one session, so the figures
compare under the same machine load. Prints one table; figures go in bench/README.md.

    python bench/bench_first_run.py --rounds 3
    python bench/bench_first_run.py --rounds 3 --before ../before/.venv/bin/python
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SAMPLE = Path(__file__).resolve().parents[1] / "sample_logs" / "quad_imu_bias.mcap"


def timed_run(python: str, cwd: Path, cache: Path) -> float:
    env = {k: v for k, v in os.environ.items() if k not in ("LOGSCAN_CACHE_DIR", "PYTHONPATH")}
    env["NUMBA_CACHE_DIR"] = str(cache)
    start = time.perf_counter()
    result = subprocess.run(
        [python, "-m", "logscan", "analyze", str(SAMPLE), "--no-report"], cwd=cwd, env=env, capture_output=True
    )
    elapsed = time.perf_counter() - start
    if result.returncode not in (0, 1):
        raise SystemExit(f"{python}: analyze failed ({result.returncode}):\n{result.stderr.decode()[-2000:]}")
    return elapsed


def measure(python: str, warm_runs: int) -> tuple[float, float]:
    """(cold s, best warm s) of one tree, each in a fresh cache directory."""
    with tempfile.TemporaryDirectory(prefix="logscan-cache-") as cache, tempfile.TemporaryDirectory() as cwd:
        cold = timed_run(python, Path(cwd), Path(cache))
        warm = min(timed_run(python, Path(cwd), Path(cache)) for _ in range(warm_runs))
    return cold, warm


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--warm", type=int, default=3, help="warm runs per round (best is kept)")
    parser.add_argument("--before", help="python of another checkout's venv to compare with")
    args = parser.parse_args()
    trees = {"this tree": sys.executable}
    if args.before:
        trees = {"before": args.before, **trees}
    figures: dict[str, list[tuple[float, float]]] = {name: [] for name in trees}
    for round_no in range(args.rounds):
        for name, python in trees.items():
            cold, warm = measure(python, args.warm)
            figures[name].append((cold, warm))
            print(f"round {round_no + 1} {name}: cold {cold:.2f} s, warm {warm:.2f} s", file=sys.stderr)
    print(f"`logscan analyze {SAMPLE.name}` ({os.cpu_count()} cores, load {os.getloadavg()[0]:.1f})\n")
    print("| tree | cold s (each round) | warm s (each round) | median cold / warm |")
    print("|---|---|---|---:|")
    for name, runs in figures.items():
        colds = " / ".join(f"{c:.2f}" for c, _ in runs)
        warms = " / ".join(f"{w:.2f}" for _, w in runs)
        ratio = statistics.median(c for c, _ in runs) / statistics.median(w for _, w in runs)
        print(f"| {name} | {colds} | {warms} | {ratio:.1f} |")
    if args.before:
        before = statistics.median(c for c, _ in figures["before"])
        after = statistics.median(c for c, _ in figures["this tree"])
        print(f"\ncold run, this tree / before: {after / before:.2f}")


if __name__ == "__main__":
    main()
