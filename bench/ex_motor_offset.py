"""The encoded state check e_x on the quadcopter's motor offset: -10 % thrust against -10 % speed.

docs/algorithms.md section 1.10: the encoded-EKF paper's actuator fault is an offset of the motor
speed, the simulator's `motor-offset` one of the thrust (thrust goes with the speed squared, so
the paper's -10 % is -19 % thrust). Per magnitude, 20 runs of 60 s (seeds 5100 .. 5119, used by no
other measurement), the fault on motor 1 from 30 s for 10 s, `encoded_ekf` with its defaults:
the step of e_x at the onset (mean over 0.5 s after, minus the mean over 5 s before, over the std
of those 5 s) and the e_x alarms scored as `logscan evaluate` scores them.

`--table3` adds the paper's Table III comparison on the same runs (docs/evaluation.md): the
baseline of its reference [15] (`variant = "baseline"`, the paper's CV_0, `rejected_checks =
false`, its threshold the largest |e_x| of 10 healthy 60 s runs, seeds 5200 .. 5209) beside the
proposed e_x (with the rejected-sample checks, as `logscan evaluate` scores it), and two more
rows: a sensor fault (accel.x bit flips for 1.2 s) and a control-program fault (`control-fault`
on the thrust, +50 % for 2 s), both from 30 s.

    python bench/ex_motor_offset.py             # 2 processes, about a minute
    python bench/ex_motor_offset.py --table3    # and the baseline and control rows, about 2 minutes
    python bench/ex_motor_offset.py --model steer_by_wire    # the same comparison (Table IV)
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile

import numpy as np

START_S = 30.0
SEEDS = range(5100, 5120)
TRAIN_SEEDS = range(5200, 5210)
MAGNITUDES = {-0.10: "-10 % thrust (the simulator's motor-offset)", -0.19: "-10 % speed = -19 % thrust (the paper's)"}
FAULTS = {m: f"motor-offset::{START_S}::{m}" for m in MAGNITUDES}
# --table3's further rows: the paper's sensor fault (bit flips, its section VI.A) and control-program fault
TABLE3 = {
    "sensor": ("bitflip:accel.x:30:31.2:1.0", "sensor: accel.x bit flips for 1.2 s (`imu-bitflip`)"),
    "control": ("control-fault:thrust:30:32:0.5", "control program: thrust output x 1.5 for 2 s (`control-fault`)"),
}
# --model steer_by_wire (the paper's Table IV): the steering motor's torque -10 %, yaw-rate bit
# flips, the sliding-mode controller's output x 1.5
SBW = {
    "actuator": ("motor-offset::30::-0.1", "actuator: steering-motor torque -10 % for 10 s (`motor-offset`)"),
    "sensor": ("bitflip:yaw_rate:30:31.2:1.0", "sensor: yaw-rate bit flips for 1.2 s"),
    "control": ("control-fault:tau_eq:30:32:0.5", "control program: steering torque output x 1.5 for 2 s"),
}


def _analysed(fault: str | None, seed: int, model: str = "quadcopter"):
    """The `logscan analyze` analysis (encoded_ekf alone) of a 60 s run of ``model``."""
    from logscan.pipeline import analyze_log
    from logscan.simulate import parse_fault, simulate, write_simulation

    faults = [parse_fault(fault)] if fault else []
    with tempfile.TemporaryDirectory() as directory:
        path = os.path.join(directory, f"run_{seed}.mcap")
        write_simulation(simulate(model, faults, duration=60.0, seed=seed), path, "mcap-ros2")
        return analyze_log(path, detector_names=["encoded_ekf"])


def healthy_peak(job: tuple[str, int]) -> float:
    """max |e_x| of the baseline (constant CV_0) on a healthy run (model, seed): its training."""
    from logscan.detectors.encoded_ekf import EncodedEkfDetector

    model, seed = job
    prepared = _analysed(None, seed, model).prepared
    e_x, defined, _ = EncodedEkfDetector(variant="baseline").state_check(prepared.trace, prepared.model, None)
    return float(np.nanmax(np.abs(e_x[defined])))


def one(job: tuple) -> tuple:
    """(fault key, seed, e_x step in healthy std, detected 0/1, latency s or None, and with a
    baseline threshold: the baseline's detected 0/1, latency, false alarms)."""
    from logscan.detectors.encoded_ekf import EncodedEkfDetector
    from logscan.verdict.evaluation import score_groups

    key, seed, threshold, model = job
    fault = SBW[key][0] if model == "steer_by_wire" else FAULTS[key] if key in FAULTS else TABLE3[key][0]
    analysis = _analysed(fault, seed, model)
    (result,) = analysis.results
    e_x = result.series["e_x"]
    k = int(np.searchsorted(analysis.run.t, START_S))
    before, after = e_x[k - 500 : k], e_x[k : k + 50]
    before, after = before[np.isfinite(before)], after[np.isfinite(after)]
    # e_x with the rejected-sample checks, as `logscan evaluate` scores encoded_ekf:e_x
    groups = {"e_x": [a for a in result.alarms if a.signal == "e_x" or a.signal.startswith("rejected.")]}
    if threshold is not None:
        prepared = analysis.prepared
        baseline = EncodedEkfDetector(variant="baseline", threshold=threshold, rejected_checks=False)
        groups["baseline"] = baseline.run(prepared.run, prepared.trace, model=prepared.model).alarms
    scores = score_groups(analysis.events, groups, duration_s=60.0)
    step = float((after.mean() - before.mean()) / before.std())
    out = (key, seed, step, scores["e_x"].tp, scores["e_x"].mean_latency_s)
    if threshold is None:
        return out
    b = scores["baseline"]
    return out + (b.tp, b.mean_latency_s, b.fp)


def _timing(latencies: list) -> str:
    return f"{np.mean(latencies):.2f} / {max(latencies):.2f} s" if latencies else "-"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=2, help="worker processes")
    parser.add_argument("--table3", action="store_true", help="also the baseline and the control-program fault")
    parser.add_argument("--model", choices=("quadcopter", "steer_by_wire"), default="quadcopter")
    args = parser.parse_args(argv)
    args.table3 = args.table3 or args.model == "steer_by_wire"
    from logscan.fleet import run_many

    threshold = None
    labels: dict = dict(MAGNITUDES)
    if args.model == "steer_by_wire":
        labels = {key: label for key, (_, label) in SBW.items()}
    if args.table3:
        training = [(args.model, s) for s in TRAIN_SEEDS]
        threshold = max(run_many(training, healthy_peak, jobs=args.jobs, isolate=False))
        if args.model == "quadcopter":
            labels.update({key: label for key, (_, label) in TABLE3.items()})
        print(f"baseline threshold (max |e_x| over {len(TRAIN_SEEDS)} healthy runs): {threshold:.4g}")
    jobs = [(m, s, threshold, args.model) for m in labels for s in SEEDS]
    rows = run_many(jobs, one, jobs=args.jobs, isolate=False)
    head = "| fault | e_x step / healthy std | e_x detected | mean / max latency |"
    print(head + (" baseline detected | its mean / max latency | its false alarms |" if args.table3 else ""))
    print("|---|---|---|---|" + ("---|---|---|" if args.table3 else ""))
    for key, label in labels.items():
        mine = [r for r in rows if r[0] == key]
        steps = [r[2] for r in mine]
        line = (
            f"| {label} | {np.mean(steps):+.2f} ({min(steps):+.2f} .. {max(steps):+.2f}) | "
            f"{sum(r[3] for r in mine)}/{len(mine)} | {_timing([r[4] for r in mine if r[3] and r[4] is not None])} |"
        )
        if args.table3:
            base = _timing([r[6] for r in mine if r[5] and r[6] is not None])
            line += f" {sum(r[5] for r in mine)}/{len(mine)} | {base} | {sum(r[7] for r in mine)} |"
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
