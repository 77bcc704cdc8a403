"""Issue 29's table in one run: every row measured back to back on this machine, `uptime` beside.

Each row is a ratio its own benchmark takes within itself (logscan against a library or a reference,
`--jobs 2` against `--jobs 1`, cold against warm), so rows measured minutes apart stay comparable;
with --before TREE the whole-analysis rows (the 1-hour log's CPU and peak memory at each length, the
first run) alternate with another checkout's code run in this venv (`compare_summaries.RUNNER`).

    python bench/bench_issue29.py --logs /tmp/logs [--before ../before] [--rows analyze,memory,...]

--logs holds the quadcopter logs of `bench_analyze.py --hours` (``quad_<seconds>.mcap``, simulated
there when missing). Prints each benchmark's own table under a heading; figures go in
bench/README.md.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_analyze import simulate
from benchlib import installed_environment
from compare_summaries import RUNNER

BENCH = Path(__file__).resolve().parent
ROWS = ("analyze", "memory", "window", "ekf", "readers", "first_run", "report", "jobs", "ubikf", "kgn")


def uptime() -> str:
    with open("/proc/loadavg", encoding="ascii") as fh:
        return "load average " + ", ".join(fh.read().split()[:3])


def cli_usage(args: list[str], tree: Path | None) -> tuple[float, float, float]:
    """(CPU s of the process and its children, wall s, peak RSS MiB) of ``logscan ARGS``."""
    command = [sys.executable, "-m", "logscan"] if tree is None else [sys.executable, "-c", RUNNER, str(tree)]
    start = time.perf_counter()
    process = subprocess.Popen(
        [*command, *args], env=installed_environment(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status) not in (0, 1):
        raise SystemExit(f"logscan {' '.join(args)} failed: {process.stderr.read().decode(errors='replace')}")
    # the background compile is a child of the CLI: its CPU is counted once the CLI waited for it
    return usage.ru_utime + usage.ru_stime, wall, usage.ru_maxrss / 1024


def analyze_rows(logs: Path, hours: list[float], trees: dict[str, Path | None], repeat: int) -> None:
    """CPU, wall and peak RSS of `analyze LOG -o R.html --json S.json` per log length and tree."""
    print("| log | tree | CPU s (best) | wall s (best) | peak RSS MiB |\n|---|---|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for h in hours:
            seconds = round(h * 3600)
            log = logs / f"quad_{seconds}.mcap"
            simulate(seconds, "mcap-ros2", log, Path(tmp) / "cache")
            runs: dict[str, list[tuple[float, float, float]]] = {name: [] for name in trees}
            for _ in range(repeat):  # the trees alternate
                for name, tree in trees.items():
                    args = ["analyze", str(log), "-o", f"{tmp}/r.html", "--json", f"{tmp}/s.json", "-q"]
                    runs[name].append(cli_usage(args, tree))
            for name, usages in runs.items():
                cpu, wall, rss = min(u[0] for u in usages), min(u[1] for u in usages), max(u[2] for u in usages)
                print(f"| {h:g} h | {name} | {cpu:.2f} | {wall:.2f} | {rss:.0f} |")
    print(f"\n{uptime()}")


def window_rows(logs: Path, hours: list[float], trees: dict[str, Path | None]) -> None:
    """CPU, wall and peak RSS of `analyze LOG --start S --end S+600` (its middle ten minutes) per
    log length and tree; a 24-hour log is used when it is there, not simulated (hours of work)."""
    print("| log | window | tree | CPU s | wall s | peak RSS MiB |\n|---|---|---|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for h in hours:
            seconds = round(h * 3600)
            log = logs / f"quad_{seconds}.mcap"
            if seconds > 8 * 3600 and not log.exists():
                print(f"| {h:g} h | - | - | not simulated here | | |")
                continue
            simulate(seconds, "mcap-ros2", log, Path(tmp) / "cache")
            start = seconds // 2
            for name, tree in trees.items():
                args = ["analyze", str(log), "--start", str(start), "--end", str(start + 600), "--no-report", "-q"]
                cpu, wall, rss = cli_usage([*args, "--json", f"{tmp}/s.json"], tree)
                print(f"| {h:g} h | {start}-{start + 600} s | {name} | {cpu:.2f} | {wall:.2f} | {rss:.0f} |")
    print(f"\n{uptime()}")


def bench(script: str, *args: str) -> None:
    """Another benchmark of this folder, its output as it prints it."""
    subprocess.run([sys.executable, str(BENCH / script), *args], check=False)
    print(f"\n{uptime()}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", type=Path, required=True)
    parser.add_argument("--before", type=Path, help="another checkout to compare the whole-analysis rows with")
    parser.add_argument("--rows", default=",".join(ROWS))
    parser.add_argument("--repeat", type=int, default=2)
    options = parser.parse_args()
    options.logs.mkdir(parents=True, exist_ok=True)
    trees: dict[str, Path | None] = {"this tree": None}
    if options.before is not None:
        trees = {"before": options.before, **trees}
    rows = options.rows.split(",")
    unknown = sorted(set(rows) - set(ROWS))
    if unknown:
        raise SystemExit(f"unknown rows {unknown}; rows: {', '.join(ROWS)}")
    first = str(options.logs / "quad_3600.mcap")
    steps = {
        "analyze": lambda: analyze_rows(options.logs, [0.25, 1.0], trees, options.repeat),
        "memory": lambda: analyze_rows(options.logs, [4.0, 8.0], trees, 1),
        "window": lambda: window_rows(options.logs, [1.0, 8.0, 24.0], trees),
        "ekf": lambda: bench("bench_ekf.py", "--steps", "100000", "--reps", "5", "--no-phases"),
        "readers": lambda: bench("bench_readers.py"),
        "first_run": lambda: bench(
            "bench_first_run.py", "--rounds", "1", *(["--before-tree", str(options.before)] if options.before else [])
        ),
        "report": lambda: bench("bench_report_page.py", first),
        "jobs": lambda: bench("bench_fleet.py", "--logs", "20", "--rounds", "2", "--modes", "--jobs 1,--jobs 2"),
        "ubikf": lambda: bench("bench_ubikf.py"),
        "kgn": lambda: bench("bench_kgn_train.py", "--hours", "1"),
    }
    for row in rows:
        print(f"\n## {row} ({time.strftime('%H:%M:%S')}, {uptime()})\n", flush=True)
        steps[row]()
        sys.stdout.flush()


if __name__ == "__main__":
    main()
