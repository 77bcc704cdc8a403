"""The encoded state check e_x on the quadcopter's motor offset: -10 % thrust against -10 % speed.

docs/algorithms.md section 1.10: the encoded-EKF paper's actuator fault is an offset of the motor
speed, the simulator's `motor-offset` one of the thrust (thrust goes with the speed squared, so
the paper's -10 % is -19 % thrust). Per magnitude, 20 runs of 60 s (seeds 5100 .. 5119, used by no
other measurement), the fault on motor 1 from 30 s for 10 s, `encoded_ekf` with its defaults:
the step of e_x at the onset (mean over 0.5 s after, minus the mean over 5 s before, over the std
of those 5 s) and the e_x alarms scored as `logscan evaluate` scores them.

    python bench/ex_motor_offset.py             # 2 processes, about a minute
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile

import numpy as np

START_S = 30.0
SEEDS = range(5100, 5120)
MAGNITUDES = {-0.10: "-10 % thrust (the simulator's motor-offset)", -0.19: "-10 % speed = -19 % thrust (the paper's)"}


def one(job: tuple[float, int]) -> tuple[float, int, float, int, float | None]:
    """(magnitude, seed, e_x step in healthy std, detected 0/1, latency s or None)."""
    from logscan.pipeline import analyze_log
    from logscan.simulate import parse_fault, simulate, write_simulation
    from logscan.verdict.evaluation import score_groups

    magnitude, seed = job
    with tempfile.TemporaryDirectory() as directory:
        path = os.path.join(directory, f"offset_{seed}.mcap")
        fault = parse_fault(f"motor-offset::{START_S}::{magnitude}")
        write_simulation(simulate("quadcopter", [fault], duration=60.0, seed=seed), path, "mcap-ros2")
        analysis = analyze_log(path, detector_names=["encoded_ekf"])
    (result,) = analysis.results
    e_x = result.series["e_x"]
    k = int(np.searchsorted(analysis.run.t, START_S))
    before, after = e_x[k - 500 : k], e_x[k : k + 50]
    before, after = before[np.isfinite(before)], after[np.isfinite(after)]
    alarms = [a for a in result.alarms if a.signal == "e_x"]
    score = score_groups(analysis.events, {"e_x": alarms}, duration_s=60.0)["e_x"]
    return magnitude, seed, float((after.mean() - before.mean()) / before.std()), score.tp, score.mean_latency_s


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=2, help="worker processes")
    args = parser.parse_args(argv)
    from logscan.fleet import run_many

    rows = run_many([(m, s) for m in MAGNITUDES for s in SEEDS], one, jobs=args.jobs, isolate=False)
    print("| fault on motor 1 | e_x step / healthy std | e_x detected | mean / max latency |")
    print("|---|---|---|---|")
    for magnitude, label in MAGNITUDES.items():
        mine = [r for r in rows if r[0] == magnitude]
        steps = [r[2] for r in mine]
        latencies = [r[4] for r in mine if r[3] and r[4] is not None]
        timing = f"{np.mean(latencies):.2f} / {max(latencies):.2f} s" if latencies else "-"
        print(
            f"| {label} | {np.mean(steps):+.2f} ({min(steps):+.2f} .. {max(steps):+.2f}) | "
            f"{sum(r[3] for r in mine)}/{len(mine)} | {timing} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
