"""Wall time of `logscan analyze` over a fleet of N simulated 10-minute quadcopter logs: `--jobs 1`,
`--jobs 2` and `--scheduler local:2` (Dask, a LocalCluster of 2 worker processes started for the run).

Simulates --distinct logs (different seeds; MCAP) into a temporary directory and hard-links them up to
--logs files (simulating is slower than analysing); then each mode runs the real CLI in a fresh
process (--rounds times, the modes alternating; best kept), after one warm-up run that fills the numba
cache, with `--no-report --json`. The JSON of every mode must be the same (checked). Prints a markdown
table with the speed-up against `--jobs 1` and each mode's CPU seconds (the CLI and its workers: on a
shared machine the CPU a mode spends is steadier than its wall time), then each round's speed-up and
CPU ratio against the same round's `--jobs 1`, and the load average; figures go in bench/README.md.
The CLI runs as an installed logscan does, Python's bytecode cache on (`benchlib.installed_environment`).

    python bench/bench_fleet.py              # 20 logs
    python bench/bench_fleet.py --logs 200   # the issue's figure
    python bench/bench_fleet.py --rounds 3 --modes "--jobs 1,--jobs 2"
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_first_run import command  # noqa: E402
from benchlib import installed_environment, simulate_log  # noqa: E402

MODES = {
    "--jobs 1": ["--jobs", "1"],
    "--jobs 2": ["--jobs", "2"],
    "--scheduler local:2": ["--scheduler", "local:2"],
}


def analyze(logs_dir: Path, json_path: Path, how: list[str], tree: str = sys.executable) -> tuple[float, float]:
    """(wall s, CPU s of the CLI process and all its workers) of one run of the tree's logscan (a python
    or a source directory, `bench_first_run.command`)."""
    args = [*command(tree), "analyze", str(logs_dir), "--no-report", "--json", str(json_path)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    result = subprocess.run(
        [*args, *how, "--exit-zero", "--quiet"], capture_output=True, text=True, env=installed_environment()
    )
    elapsed = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if result.returncode != 0:
        raise SystemExit(f"logscan analyze {' '.join(how)} failed ({result.returncode}):\n{result.stderr}")
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    return elapsed, cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", type=int, default=20, help="number of logs in the fleet (default 20)")
    parser.add_argument("--distinct", type=int, default=4, help="logs simulated (the others are links to them)")
    parser.add_argument("--duration", type=float, default=600.0, help="seconds per log (default 600)")
    parser.add_argument("--rounds", type=int, default=1, help="runs of each mode, alternating (best kept)")
    parser.add_argument("--modes", default=",".join(MODES), help="comma-separated modes to run (default: all)")
    parser.add_argument(
        "--trees", help="NAME=PATH,...: source trees to compare (run with this venv), alternating; default this one"
    )
    parser.add_argument("--simulated", help="directory of the simulated logs, kept and reused (default: a new one)")
    parser.add_argument("--keep", help="directory for the modes' JSON when they differ (default: a new one)")
    args = parser.parse_args()
    modes = {name: MODES[name] for name in ["--jobs 1", *(m for m in args.modes.split(",") if m != "--jobs 1")]}
    trees = dict(item.split("=", 1) for item in args.trees.split(",")) if args.trees else {"": sys.executable}
    work = Path(tempfile.mkdtemp(prefix="logscan-bench-fleet-"))
    try:
        fleet = work / "fleet"
        fleet.mkdir()
        t0 = time.perf_counter()
        simulated_dir = Path(args.simulated) if args.simulated else work
        simulated_dir.mkdir(parents=True, exist_ok=True)
        distinct = [
            str(path)
            if (path := simulated_dir / f"quad_{args.duration:g}s_seed{seed}.mcap").exists()
            else simulate_log("quadcopter", str(path), "--duration", str(args.duration), "--seed", str(seed))
            for seed in range(min(args.distinct, args.logs))
        ]
        for number in range(args.logs):
            target = fleet / f"quad_{number:04d}.mcap"
            try:
                os.link(distinct[number % len(distinct)], target)
            except OSError:
                shutil.copyfile(distinct[number % len(distinct)], target)
        simulated = time.perf_counter() - t0
        for tree in trees.values():
            analyze(fleet / "quad_0000.mcap", work / "warm.json", ["--jobs", "1"], tree)  # numba cache filled
        load_start = os.getloadavg()[0]
        times: dict[tuple[str, str], list[tuple[float, float]]] = {(t, m): [] for t in trees for m in modes}
        documents = {}
        for _ in range(args.rounds):  # trees and modes alternate round by round; the best round of each is kept
            for label, tree in trees.items():
                for name, how in modes.items():
                    json_path = work / f"{label}{name.replace(' ', '_').replace(':', '')}.json"
                    times[label, name].append(analyze(fleet, json_path, how, tree))
                    documents[label, name] = json_path.read_bytes()
        same = all(len({documents[label, name] for name in modes}) == 1 for label in trees)  # per tree
        print(
            f"{args.logs} simulated {args.duration / 60:g}-minute quadcopter logs ({len(distinct)} distinct, "
            f"simulated in {simulated:.0f} s); {os.cpu_count()} CPUs, Python {platform.python_version()}; "
            f"JSON identical across modes: {'yes' if same else 'NO'}\n"
        )
        print(
            f"best of {args.rounds} rounds; CPU: the CLI process and its workers (user + system)\n\n"
            "| mode | wall time (s) | per log (s) | speed-up vs --jobs 1 | CPU s | CPU / --jobs 1's |"
        )
        print("|---|---:|---:|---:|---:|---:|")
        wall = {key: min(w for w, _ in runs) for key, runs in times.items()}
        cpu = {key: min(c for _, c in runs) for key, runs in times.items()}
        for label, name in times:
            one = (label, "--jobs 1")
            print(
                f"| {label} `{name}` | {wall[label, name]:.1f} | {wall[label, name] / args.logs:.2f} | "
                f"{wall[one] / wall[label, name]:.2f}x | {cpu[label, name]:.1f} | {cpu[label, name] / cpu[one]:.2f} |"
            )
        for label in trees:
            for name in modes:
                if name != "--jobs 1":
                    pairs = list(zip(times[label, "--jobs 1"], times[label, name]))
                    print(
                        f"\n{label} `{name}` per round: speed-up "
                        + ", ".join(f"{one[0] / many[0]:.2f}x" for one, many in pairs)
                        + "; CPU / --jobs 1's "
                        + ", ".join(f"{many[1] / one[1]:.2f}" for one, many in pairs)
                    )
        print(f"\nload average (1 min): {load_start:.1f} at the start, {os.getloadavg()[0]:.1f} at the end")
        if not same:
            keep = Path(args.keep or tempfile.mkdtemp(prefix="logscan-bench-fleet-json-"))
            keep.mkdir(parents=True, exist_ok=True)
            for (label, name), document in documents.items():
                (keep / f"{label}{name.replace(' ', '_').replace(':', '')}.json").write_bytes(document)
            raise SystemExit(f"the modes' JSON summaries differ: they are in {keep}")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
