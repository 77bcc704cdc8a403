"""Wall time of `logscan analyze` on a simulated 1-hour 100 Hz quadcopter log, warm and cold.

Simulates the log once per encoding (MCAP JSON, MCAP ROS 2) into a temporary directory, then runs
the real CLI in fresh processes: "cold" with an empty numba cache directory (every kernel compiles),
"warm" with a populated one (best of --repeat runs). Prints a table; figures go in bench/README.md.

    python bench/bench_analyze.py                 # 1 hour, both encodings
    python bench/bench_analyze.py --duration 600  # quicker check

Memory per log length (`--hours`): a warm `analyze` of a ROS 2 MCAP log of each length, its wall time
and the peak RSS of the analysing process (`os.wait4`), and the growth per log-hour between the two
longest; `--logs DIR` keeps the simulated logs (``quad_<seconds>.mcap``) for the next run, `--tree`
runs another checkout's code in this venv (`compare_summaries.RUNNER`) for a before/after:

    python bench/bench_analyze.py --hours 0.25,1,4,8 --logs /tmp/logs [--tree ../before]
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

from benchlib import installed_environment
from compare_summaries import RUNNER


def run_cli(args: list[str], cache_dir: Path) -> float:
    return measured_cli(args, cache_dir)[0]


def measured_cli(args: list[str], cache_dir: Path, tree: Path | None = None) -> tuple[float, float]:
    """(wall seconds, peak RSS in MB = 1e6 bytes) of ``logscan ARGS`` in a fresh process; ``tree``:
    another checkout's code, run in this venv."""
    env = installed_environment(NUMBA_CACHE_DIR=str(cache_dir))
    command = [sys.executable, "-m", "logscan"] if tree is None else [sys.executable, "-c", RUNNER, str(tree)]
    start = time.perf_counter()
    with tempfile.TemporaryFile() as err:
        process = subprocess.Popen([*command, *args], env=env, stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(process.pid, 0)
        elapsed = time.perf_counter() - start
        process.returncode = os.waitstatus_to_exitcode(status)
        if process.returncode not in (0, 1):
            err.seek(0)
            raise SystemExit(f"logscan {' '.join(args)} failed:\n{err.read().decode(errors='replace')}")
    return elapsed, usage.ru_maxrss * 1024 / 1e6  # ru_maxrss: KiB on Linux


def simulate(seconds: float, fmt: str, path: Path, cache_dir: Path) -> float:
    """Simulate the benchmark's quadcopter log (imu-bias half way) unless ``path`` exists; seconds taken."""
    if path.exists():
        return 0.0
    args = ["quadcopter", "--duration", str(seconds), "--seed", "7", "--fault", "imu-bias"]
    return run_cli(["simulate", *args, "--at", str(seconds / 2), "--format", fmt, "-o", str(path)], cache_dir)


def memory_table(hours: list[float], logs: Path, repeat: int, tree: Path | None) -> str:
    """Wall time (best of ``repeat``) and peak RSS (largest of them) of a warm analyze per log length."""
    cache = logs / "numba-cache"
    rows, rss = [], {}
    for h in hours:
        seconds = round(h * 3600.0)
        log = logs / f"quad_{seconds}.mcap"
        simulate(seconds, "mcap-ros2", log, cache)
        command = ["analyze", str(log), "-o", str(logs / "report.html"), "--json", str(logs / "summary.json"), "-q"]
        measured_cli(command, cache, tree)  # populate the cache
        runs = [measured_cli(command, cache, tree) for _ in range(repeat)]
        rss[h] = max(r[1] for r in runs)
        size, wall = log.stat().st_size / 1e6, min(r[0] for r in runs)
        rows.append(f"| {h:g} h | {size:,.0f} MB | {wall:.1f} s | {rss[h]:,.0f} MB |")
    lines = ["| log | size | analyze, warm | peak RSS |", "|---|---:|---:|---:|", *rows]
    if len(hours) > 1:
        a, b = sorted(hours)[-2:]
        lines.append(f"\npeak RSS growth per log-hour ({b:g} h - {a:g} h): {(rss[b] - rss[a]) / (b - a):,.0f} MB")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=3600.0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--formats", default="mcap-ros2,mcap-json")
    parser.add_argument("--hours", help="memory per log length instead: comma-separated log-hours")
    parser.add_argument("--logs", type=Path, help="with --hours: where the logs are kept (default: a temporary dir)")
    parser.add_argument("--tree", type=Path, help="with --hours: run this checkout's code instead")
    args = parser.parse_args()
    if args.hours:
        logs = args.logs or Path(tempfile.mkdtemp(prefix="logscan-bench-"))
        logs.mkdir(parents=True, exist_ok=True)
        try:
            hours = [float(h) for h in args.hours.split(",")]
            print(memory_table(hours, logs, args.repeat, args.tree and args.tree.resolve()))
        finally:
            if args.logs is None:
                shutil.rmtree(logs, ignore_errors=True)
        return
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
