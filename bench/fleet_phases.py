"""Where the CPU of `logscan analyze DIR --jobs N` goes, against `--jobs 1`: the parent's start (imports),
its set-up before forking, each log's CPU in its process (first log of a process against the others),
the kernels loaded from numba's disk cache in each log, the pickled size of what a log sends back,
the workers' CPU outside their logs (start, pickling, the pool's queues), and the parent's merge and
outputs after the logs.

Each run is the real CLI in a fresh process (`--no-report --json`), with a prelude that wraps
`AnalyzeTask.__call__` (the per-log work; forked workers inherit the wrap), numba's
`Dispatcher.compile` (where a process loads a cached kernel: outermost calls only) and `run_many`,
and writes one JSON line per event to a file. Modes and trees alternate round by round (the machine
is shared: compare within a round). The numba cache must be warm (a first run fills it). Runs as an
installed logscan does: Python's bytecode cache on (`benchlib.installed_environment`).

    python bench/fleet_phases.py DIR --rounds 3
    python bench/fleet_phases.py DIR --trees before=/tmp/x/before,after=. --modes 1,2
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from benchlib import installed_environment  # noqa: E402

PRELUDE = r"""
import json, os, pickle, resource, sys, threading, time
root, record = sys.argv.pop(1), sys.argv.pop(1)
if root != "-":
    sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in (type(f).__name__ + type(f).__module__).lower()]
    sys.path.insert(0, root)
def emit(**fields):
    with open(record, "a") as fh:
        fh.write(json.dumps({"pid": os.getpid(), **fields}) + "\n")
import logscan.cli.main
import logscan.tasks
import logscan.fleet.local as local
from numba.core.dispatcher import Dispatcher
emit(event="imported", cpu=time.process_time())
state = threading.local()
loads = {"n": 0, "cpu": 0.0}
original_compile = Dispatcher.compile
def compile(self, sig):
    if getattr(state, "depth", 0):
        return original_compile(self, sig)
    state.depth = 1
    start = time.process_time()
    try:
        return original_compile(self, sig)
    finally:
        state.depth = 0
        loads["n"] += 1
        loads["cpu"] += time.process_time() - start
Dispatcher.compile = compile
original_call = logscan.tasks.AnalyzeTask.__call__
def call(self, item):
    start, n, cpu = time.process_time(), loads["n"], loads["cpu"]
    usage = resource.getrusage(resource.RUSAGE_SELF)
    outcome = original_call(self, item)
    after = resource.getrusage(resource.RUSAGE_SELF)
    emit(event="log", log=os.path.basename(item[0]), cpu=time.process_time() - start, loads=loads["n"] - n,
         load_cpu=loads["cpu"] - cpu, pickled=len(pickle.dumps(outcome)), sys=after.ru_stime - usage.ru_stime,
         faults=after.ru_minflt - usage.ru_minflt)
    return outcome
logscan.tasks.AnalyzeTask.__call__ = call
original_run_many = local.run_many
def run_many(*args, **kwargs):
    start, children = time.process_time(), resource.getrusage(resource.RUSAGE_CHILDREN)
    emit(event="run_many", cpu=start)
    try:
        return original_run_many(*args, **kwargs)
    finally:
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        workers = (after.ru_utime + after.ru_stime) - (children.ru_utime + children.ru_stime)
        emit(event="logs_done", cpu=time.process_time(), parent_cpu=time.process_time() - start, workers_cpu=workers)
import logscan.fleet
logscan.fleet.run_many = run_many
import atexit
atexit.register(lambda: emit(event="exit", cpu=time.process_time()))
sys.exit(logscan.cli.main.main(sys.argv[1:]))
"""


def run(tree: str, fleet: Path, jobs: int, record: Path, json_path: Path) -> dict:
    """One CLI run; its events, wall time and CPU (the process and its workers)."""
    record.unlink(missing_ok=True)
    root = "-" if tree == "-" else str(Path(tree).resolve())
    cmd = [sys.executable, "-c", PRELUDE, root, str(record), "analyze", str(fleet), "--no-report"]
    cmd += ["--json", str(json_path), "--jobs", str(jobs), "--exit-zero", "--quiet"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    result = subprocess.run(cmd, capture_output=True, text=True, env=installed_environment())
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if result.returncode != 0:
        raise SystemExit(f"analyze --jobs {jobs} failed ({result.returncode}):\n{result.stderr[-3000:]}")
    events = [json.loads(line) for line in record.read_text().splitlines()]
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    return {"wall": wall, "cpu": cpu, "events": events}


def phases(measured: dict) -> dict:
    """The run's CPU by phase (s)."""
    events = measured["events"]
    parent = events[0]["pid"]
    first = {e["event"]: e for e in events if e["pid"] == parent and e["event"] != "log"}
    logs = [e for e in events if e["event"] == "log"]
    by_process: dict[int, list[dict]] = {}
    for e in logs:
        by_process.setdefault(e["pid"], []).append(e)
    firsts = [entries[0] for entries in by_process.values()]
    rest = [e for entries in by_process.values() for e in entries[1:]]
    workers = first["logs_done"]["workers_cpu"]
    in_logs = sum(e["cpu"] for e in logs)
    in_workers = sum(e["cpu"] for e in logs if e["pid"] != parent)
    return {
        "wall": measured["wall"],
        "cpu": measured["cpu"],
        "imports": first["imported"]["cpu"],
        "before_logs": first["run_many"]["cpu"] - first["imported"]["cpu"],
        "parent_during_logs": first["logs_done"]["parent_cpu"] - sum(e["cpu"] for e in logs if e["pid"] == parent),
        "after_logs": first["exit"]["cpu"] - first["logs_done"]["cpu"],
        "logs": in_logs,
        "processes": len(by_process),
        "first_log": statistics.mean(e["cpu"] for e in firsts),
        "other_logs": statistics.median(e["cpu"] for e in rest) if rest else float("nan"),
        "loads_first": statistics.mean(e["load_cpu"] for e in firsts),
        "loads_n_first": statistics.mean(e["loads"] for e in firsts),
        "loads_other": statistics.mean(e["load_cpu"] for e in rest) if rest else 0.0,
        "other_sys": statistics.median(e["sys"] for e in rest) if rest else float("nan"),
        "other_faults": statistics.median(e["faults"] for e in rest) / 1000 if rest else float("nan"),
        "pickled_kb": statistics.mean(e["pickled"] for e in logs) / 1024,
        "workers_outside_logs": workers - in_workers,
    }


ROWS = (
    ("wall", "wall s"),
    ("cpu", "CPU s (all processes)"),
    ("imports", "parent: start and imports"),
    ("before_logs", "parent: options to the first log (set-up, fork)"),
    ("parent_during_logs", "parent while the logs run (not in a log)"),
    ("after_logs", "parent: merge and outputs"),
    ("logs", "sum of the logs' CPU"),
    ("first_log", "first log of a process (mean)"),
    ("other_logs", "other logs (median)"),
    ("loads_first", "kernels loaded in a first log, CPU (mean)"),
    ("loads_n_first", "kernels loaded in a first log, count"),
    ("loads_other", "kernels loaded in another log, CPU (mean)"),
    ("other_sys", "other logs: system CPU (median)"),
    ("other_faults", "other logs: minor page faults, thousands (median)"),
    ("pickled_kb", "what a log sends back, pickled KB"),
    ("workers_outside_logs", "workers' CPU outside their logs"),
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("fleet", type=Path, help="directory of logs (e.g. bench_fleet.py's simulated ones)")
    parser.add_argument("--modes", default="1,2", help="--jobs values, comma-separated (default 1,2)")
    parser.add_argument("--rounds", type=int, default=2, help="rounds, modes and trees alternating (default 2)")
    parser.add_argument("--trees", help="NAME=DIR,...: source trees run with this venv (default: the installed one)")
    args = parser.parse_args()
    modes = [int(m) for m in args.modes.split(",")]
    trees = dict(item.split("=", 1) for item in args.trees.split(",")) if args.trees else {"": "-"}
    work = Path(tempfile.mkdtemp(prefix="logscan-fleet-phases-"))
    results: dict[tuple[str, int], list[dict]] = {(t, m): [] for t in trees for m in modes}
    documents: dict[tuple[str, int], bytes] = {}
    for tree in trees.values():  # the numba cache filled for each tree
        run(tree, next(iter(sorted(args.fleet.iterdir()))), 1, work / "record.jsonl", work / "warm.json")
    print(f"load {os.getloadavg()[0]:.1f} at the start", flush=True)
    for number in range(args.rounds):
        for label, tree in trees.items():
            for jobs in modes:
                json_path = work / f"{label}{jobs}.json"
                measured = phases(run(tree, args.fleet, jobs, work / "record.jsonl", json_path))
                documents[label, jobs] = json_path.read_bytes()
                results[label, jobs].append(measured)
                print(
                    f"round {number + 1} {label or 'this tree'} --jobs {jobs}: {measured['wall']:.2f} s wall, "
                    f"{measured['cpu']:.2f} s CPU (load {os.getloadavg()[0]:.1f})",
                    flush=True,
                )
    same = len(set(documents.values())) == 1
    print(f"\nload {os.getloadavg()[0]:.1f} at the end; JSON identical across modes and trees: {same}\n")
    header = [f"{label or 'this tree'} --jobs {jobs}" for label, jobs in results]
    print("| median of the rounds | " + " | ".join(header) + " |")
    print("|---|" + "---:|" * len(header))
    for key, name in ROWS:
        cells = [statistics.median(r[key] for r in runs) for runs in results.values()]
        print(f"| {name} | " + " | ".join(f"{c:.3g}" if key == "loads_n_first" else f"{c:.2f}" for c in cells) + " |")
    for label in trees:
        for jobs in modes[1:]:
            ratios = [one["wall"] / many["wall"] for one, many in zip(results[label, modes[0]], results[label, jobs])]
            cpus = [many["cpu"] / one["cpu"] for one, many in zip(results[label, modes[0]], results[label, jobs])]
            print(
                f"\n{label or 'this tree'}: --jobs {jobs} speed-up per round "
                + ", ".join(f"{r:.2f}x" for r in ratios)
                + "; CPU / --jobs 1 "
                + ", ".join(f"{c:.2f}" for c in cpus)
            )


if __name__ == "__main__":
    main()
