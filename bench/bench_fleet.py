"""Wall time of `logscan analyze` over a fleet of N simulated 10-minute quadcopter logs: `--jobs 1`,
`--jobs 2` and `--scheduler local:2` (Dask, a LocalCluster of 2 worker processes started for the run).

Simulates --distinct logs (different seeds; MCAP) into a temporary directory and hard-links them up to
--logs files (simulating is slower than analysing); then each mode runs the real CLI once in a fresh
process, after one warm-up run that fills the numba cache, with `--no-report --json`. The JSON of every
mode must be the same (checked). Prints a markdown table with the speed-up against `--jobs 1`; figures
go in bench/README.md.

    python bench/bench_fleet.py              # 20 logs
    python bench/bench_fleet.py --logs 200   # the issue's figure
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from benchlib import simulate_log  # noqa: E402

MODES = {
    "--jobs 1": ["--jobs", "1"],
    "--jobs 2": ["--jobs", "2"],
    "--scheduler local:2": ["--scheduler", "local:2"],
}


def analyze(logs_dir: Path, json_path: Path, how: list[str]) -> float:
    args = [sys.executable, "-m", "logscan", "analyze", str(logs_dir), "--no-report", "--json", str(json_path)]
    start = time.perf_counter()
    result = subprocess.run([*args, *how, "--exit-zero", "--quiet"], capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    if result.returncode != 0:
        raise SystemExit(f"logscan analyze {' '.join(how)} failed ({result.returncode}):\n{result.stderr}")
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", type=int, default=20, help="number of logs in the fleet (default 20)")
    parser.add_argument("--distinct", type=int, default=4, help="logs simulated (the others are links to them)")
    parser.add_argument("--duration", type=float, default=600.0, help="seconds per log (default 600)")
    parser.add_argument("--keep", help="directory for the modes' JSON when they differ (default: a new one)")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="logscan-bench-fleet-"))
    try:
        fleet = work / "fleet"
        fleet.mkdir()
        t0 = time.perf_counter()
        distinct = [
            simulate_log(
                "quadcopter", str(work / f"seed{seed}.mcap"), "--duration", str(args.duration), "--seed", str(seed)
            )
            for seed in range(min(args.distinct, args.logs))
        ]
        for number in range(args.logs):
            target = fleet / f"quad_{number:04d}.mcap"
            try:
                os.link(distinct[number % len(distinct)], target)
            except OSError:
                shutil.copyfile(distinct[number % len(distinct)], target)
        simulated = time.perf_counter() - t0
        analyze(fleet / "quad_0000.mcap", work / "warm.json", ["--jobs", "1"])  # numba cache filled
        times, documents = {}, {}
        for name, how in MODES.items():
            json_path = work / f"{name.replace(' ', '_').replace(':', '')}.json"
            times[name] = analyze(fleet, json_path, how)
            documents[name] = json_path.read_bytes()
        same = len(set(documents.values())) == 1
        print(
            f"{args.logs} simulated {args.duration / 60:g}-minute quadcopter logs ({len(distinct)} distinct, "
            f"simulated in {simulated:.0f} s); {os.cpu_count()} CPUs, Python {platform.python_version()}; "
            f"JSON identical across modes: {'yes' if same else 'NO'}\n"
        )
        print("| mode | wall time (s) | per log (s) | speed-up vs --jobs 1 |")
        print("|---|---:|---:|---:|")
        for name, seconds in times.items():
            print(f"| `{name}` | {seconds:.1f} | {seconds / args.logs:.2f} | {times['--jobs 1'] / seconds:.2f}x |")
        if not same:
            keep = Path(args.keep or tempfile.mkdtemp(prefix="logscan-bench-fleet-json-"))
            keep.mkdir(parents=True, exist_ok=True)
            for name, document in documents.items():
                (keep / f"{name.replace(' ', '_').replace(':', '')}.json").write_bytes(document)
            raise SystemExit(f"the modes' JSON summaries differ: they are in {keep}")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
