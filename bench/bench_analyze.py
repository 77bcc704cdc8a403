"""Wall time of `logscan analyze` on a simulated 1-hour 100 Hz quadcopter log, warm and cold.

Simulates the log once per encoding (MCAP JSON, MCAP ROS 2) into a temporary directory, then runs
the real CLI in fresh processes: "cold" with an empty numba cache directory (every kernel compiles),
"warm" with a populated one (best of --repeat runs). Prints a table; figures go in bench/README.md.

    python bench/bench_analyze.py                 # 1 hour, both encodings
    python bench/bench_analyze.py --duration 600  # quicker check
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def run_cli(args: list[str], cache_dir: Path) -> float:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir))
    start = time.perf_counter()
    result = subprocess.run([sys.executable, "-m", "logscan", *args], env=env, capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    if result.returncode not in (0, 1):
        raise SystemExit(f"logscan {' '.join(args)} failed:\n{result.stderr}")
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=3600.0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--formats", default="mcap-ros2,mcap-json")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="logscan-bench-"))
    try:
        warm_cache = work / "numba-warm"
        rows = []
        for fmt in args.formats.split(","):
            log = work / f"quad_{fmt}.mcap"
            t0 = time.perf_counter()
            run_cli(
                [
                    "simulate",
                    "quadcopter",
                    "--duration",
                    str(args.duration),
                    "--seed",
                    "7",
                    "--fault",
                    "imu-bias",
                    "--at",
                    str(args.duration / 2),
                    "--format",
                    fmt,
                    "-o",
                    str(log),
                ],
                warm_cache,
            )
            simulate_s = time.perf_counter() - t0
            command = ["analyze", str(log), "-o", str(work / f"{fmt}.html"), "--json", str(work / f"{fmt}.json"), "-q"]
            cold_cache = work / f"numba-cold-{fmt}"
            cold = run_cli(command, cold_cache)
            shutil.rmtree(cold_cache, ignore_errors=True)
            run_cli(command, warm_cache)  # populate the warm cache
            warm = min(run_cli(command, warm_cache) for _ in range(args.repeat))
            size_mb = log.stat().st_size / 1e6
            report_mb = (work / f"{fmt}.html").stat().st_size / 1e6
            rows.append((fmt, size_mb, simulate_s, cold, warm, report_mb))
        print(
            f"{'format':<10} {'log MB':>8} {'simulate s':>11} {'analyze cold s':>15} "
            f"{'analyze warm s':>15} {'report MB':>10}"
        )
        for fmt, size_mb, sim, cold, warm, report_mb in rows:
            print(f"{fmt:<10} {size_mb:>8.1f} {sim:>11.1f} {cold:>15.2f} {warm:>15.2f} {report_mb:>10.2f}")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
