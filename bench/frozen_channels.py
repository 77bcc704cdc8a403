"""A stuck fault on every measurement channel of both simulated vehicles: detection and latency of
the frozen-sensor check (`frozen`) and of every detector `logscan analyze` runs by default.

bench/evaluate_detectors.py sticks the default target only (the quadcopter's accel.x, the
steer-by-wire's yaw rate); this bench sticks each channel in turn, as that campaign draws its runs
(60 s, the fault's start uniform in [20, 40) s from the run's seed, 5 s long) and scores them the
same way (`logscan.verdict.evaluation.score_groups`, grace 1 s). Seeds, used nowhere else:

    quadcopter     6000 + 100 * channel index + run     (6000 .. 7199)
    steer_by_wire  8000 + 100 * channel index + run     (8000 .. 8299)

    python bench/frozen_channels.py                 # 10 runs per channel, 2 processes
    python bench/frozen_channels.py --runs 3        # a quick look
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from evaluate_detectors import DURATION_S, GRACE_S, RECOVERY_S, Job, code_version, fault_start  # noqa: E402

TARGETS = {
    "quadcopter": [
        "accel.x",
        "accel.y",
        "accel.z",
        "gyro.x",
        "gyro.y",
        "gyro.z",
        "position.x",
        "position.y",
        "position.z",
        "attitude.roll",
        "attitude.pitch",
        "attitude.yaw",
    ],
    "steer_by_wire": ["steering_angle", "yaw_rate", "lateral_accel"],
}
SEED_BASE = {"quadcopter": 6000, "steer_by_wire": 8000}
CHECK = "frozen"


def make_jobs(runs: int) -> list[Job]:
    jobs = []
    for model, targets in TARGETS.items():
        for i, target in enumerate(targets):
            for r in range(runs):
                seed = SEED_BASE[model] + 100 * i + r
                jobs.append(Job(model, target, f"stuck:{target}:{fault_start(seed):.2f}::", seed))
    return jobs


def score_one(job: Job):
    """(job, {"frozen": Score, "any": Score} or error text): the run analysed with the default
    detectors (`frozen` among them)."""
    from logscan.pipeline import analyze_log
    from logscan.simulate import parse_fault, simulate, write_simulation
    from logscan.verdict.evaluation import merge_intervals, score_groups

    try:
        with tempfile.TemporaryDirectory() as directory:
            sim = simulate(job.model, [parse_fault(job.fault)], duration=DURATION_S, seed=job.seed)
            path = os.path.join(directory, f"{job.model}_{job.seed}.mcap")
            write_simulation(sim, path, "mcap-ros2")
            analysis = analyze_log(path, grace_s=GRACE_S)
        alarms = {
            CHECK: [a for r in analysis.results if r.detector == CHECK for a in r.alarms],
            "any": [a for r in analysis.results for a in r.alarms],
        }
        duration = float(analysis.run.t[-1] - analysis.run.t[0])
        spans = {key: merge_intervals(found) for key, found in alarms.items()}
        return job, score_groups(analysis.events, spans, duration_s=duration, grace_s=GRACE_S, recovery_s=RECOVERY_S)
    except Exception as exc:  # noqa: BLE001 - a failed run is reported in the table, not fatal
        return job, f"{type(exc).__name__}: {exc}"


def table(results: list) -> str:
    from logscan.verdict.scoring import aggregate

    lines = [
        f"| model | stuck channel | `{CHECK}`: detected · mean / max latency | within 1 s | any default detector |",
        "|---|---|---|---|---|",
    ]
    for model, targets in TARGETS.items():
        for target in targets:
            mine = [s for job, s in results if job.model == model and job.family == target and not isinstance(s, str)]
            if not mine:
                continue
            check, every = aggregate([s[CHECK] for s in mine]), aggregate([s["any"] for s in mine])
            fast = sum(1 for s in mine for m in s[CHECK].matches if m.detected and m.latency_s <= 1.0)
            latency = (
                "" if check.mean_latency_s is None else f" · {check.mean_latency_s:.2f} / {check.max_latency_s:.2f} s"
            )
            lines.append(
                f"| {model} | {target} | {check.tp}/{check.n_events}{latency} | {fast}/{check.n_events} | "
                f"{every.tp}/{every.n_events} |"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10, help="runs per channel")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes")
    args = parser.parse_args(argv)
    from logscan.fleet import run_many

    started = time.perf_counter()
    jobs = make_jobs(args.runs)
    results = list(run_many(jobs, score_one, jobs=args.jobs, isolate=False))
    failed = [(job, s) for job, s in results if isinstance(s, str)]
    print(
        f"{len(jobs)} runs in {time.perf_counter() - started:.0f} s ({code_version()}, "
        f"`python bench/frozen_channels.py --runs {args.runs}`); {len(failed)} failed.\n"
    )
    print(table(results))
    for job, error in failed:
        print(f"- {job.model}/{job.family}/{job.seed}: {error}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
