"""The encoded state check e_x on the quadcopter's motor offset, and the paper's Tables III/IV, per e_x statistic.

docs/algorithms.md sections 1.2 and 1.10: the encoded-EKF paper's actuator fault is an offset of the
motor speed, the simulator's `motor-offset` one of the thrust (thrust goes with the speed squared,
so the paper's -10 % is -19 % thrust). Per row, 20 runs of 60 s (seeds 5100 .. 5119, used by no
other measurement), the fault on motor 1 from 30 s for 10 s, `encoded_ekf` at its defaults but for
``ex_statistic``: the step of e_x at the onset (raw e_x, mean over 0.5 s after, minus the mean over
5 s before, over the std of those 5 s) and the e_x alarms (with the rejected-sample checks, as
`logscan evaluate` scores `encoded_ekf:e_x`) of each statistic (`--variant`: raw, normalised,
window_sum, or all, the default), each run filtered once and judged by every statistic. A
`healthy` row (the same seeds without a fault) counts the false alarms.

`--table3` adds the paper's Table III comparison on the same runs (docs/evaluation.md): the
baseline of its reference [15] (`variant = "baseline"`, the paper's CV_0, `rejected_checks =
false`, its threshold the largest |e_x| of 10 healthy 60 s runs, seeds 5200 .. 5209) and two more
rows: a sensor fault (accel.x bit flips for 1.2 s) and a control-program fault (`control-fault`
on the thrust, +50 % for 2 s), both from 30 s.

    python bench/ex_motor_offset.py             # 2 processes, about a minute
    python bench/ex_motor_offset.py --table3    # and the baseline, sensor and control rows
    python bench/ex_motor_offset.py --model steer_by_wire    # the same comparison (Table IV)
    python bench/ex_motor_offset.py --variant window_sum     # one statistic only
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile

import numpy as np

SEEDS = range(5100, 5120)
TRAIN_SEEDS = range(5200, 5210)
VARIANTS = ("raw", "normalised", "window_sum")
# key -> (fault spec or None, label, fault start s)
QUAD = {
    "-0.10": ("motor-offset::30::-0.10", "-10 % thrust (the simulator's motor-offset)", 30.0),
    "-0.19": ("motor-offset::30::-0.19", "-10 % speed = -19 % thrust (the paper's)", 30.0),
    "healthy": (None, "healthy (false alarms)", 30.0),
}
# --table3's further rows: the paper's sensor fault (bit flips, its section VI.A) and control-program fault
TABLE3 = {
    "sensor": ("bitflip:accel.x:30:31.2:1.0", "sensor: accel.x bit flips for 1.2 s (`imu-bitflip`)", 30.0),
    "control": ("control-fault:thrust:30:32:0.5", "control program: thrust x 1.5 for 2 s (`control-fault`)", 30.0),
}
# --model steer_by_wire (the paper's Table IV): the steering motor's torque -10 % in straight driving
# (30-40 s) and from the start of a double lane change (20-30 s: the lane change of 20-24 s makes
# it observable), yaw-rate bit flips, the sliding-mode controller's output x 1.5 in straight
# driving and in a lane change
SBW = {
    "actuator": ("motor-offset::30::-0.1", "actuator: steering-motor torque -10 %, 30-40 s (straight)", 30.0),
    "actuator-lane": ("motor-offset::20::-0.1", "actuator: the same, 20-30 s (lane change 20-24 s)", 20.0),
    "sensor": ("bitflip:yaw_rate:30:31.2:1.0", "sensor: yaw-rate bit flips for 1.2 s", 30.0),
    "control": ("control-fault:tau_eq:30:32:0.5", "control program: steering torque x 1.5, 30-32 s", 30.0),
    "control-lane": ("control-fault:tau_eq:20:22:0.5", "control program: the same, 20-22 s (lane change)", 20.0),
    "healthy": (None, "healthy (false alarms)", 30.0),
}


def _prepared(fault: str | None, seed: int, model: str):
    """A 60 s run of ``model`` read and filtered once (with K and S for the normalised statistics)."""
    from logscan.needs import Needs
    from logscan.pipeline import load_profile_for, prepare
    from logscan.simulate import parse_fault, simulate, write_simulation

    faults = [parse_fault(fault)] if fault else []
    with tempfile.TemporaryDirectory() as directory:
        path = os.path.join(directory, f"run_{seed}.mcap")
        write_simulation(simulate(model, faults, duration=60.0, seed=seed), path, "mcap-ros2")
        return prepare(path, load_profile_for(path, None), Needs.of(ekf=("K", "S")))


def healthy_peak(job: tuple[str, int]) -> float:
    """max |e_x| of the baseline (constant CV_0) on a healthy run (model, seed): its training."""
    from logscan.detectors.encoded_ekf import EncodedEkfDetector

    model, seed = job
    prepared = _prepared(None, seed, model)
    e_x, defined, _ = EncodedEkfDetector(variant="baseline").state_check(prepared.trace, prepared.model, None)
    return float(np.nanmax(np.abs(e_x[defined])))


def _rows(model: str, table3: bool) -> dict:
    if model == "steer_by_wire":
        return SBW
    return {**QUAD, **TABLE3} if table3 else QUAD


def one(job: tuple) -> dict:
    """One run judged by each statistic (and the baseline with its threshold): {"key", "seed",
    "step": e_x step in healthy std, name: (detected 0/1, latency s or None, false alarms)}."""
    from logscan.detectors.encoded_ekf import EncodedEkfDetector
    from logscan.results import events_from_truth
    from logscan.verdict.evaluation import score_groups

    key, seed, threshold, model, variants = job
    fault, _, start = _rows(model, True)[key]
    prepared = _prepared(fault, seed, model)
    run, trace = prepared.run, prepared.trace
    events = events_from_truth((prepared.log.truth or {}).get("events", []), path=prepared.path)
    detectors = {v: EncodedEkfDetector(ex_statistic=v) for v in variants}
    if threshold is not None:
        detectors["baseline"] = EncodedEkfDetector(variant="baseline", threshold=threshold, rejected_checks=False)
    groups = {}
    for name, detector in detectors.items():
        result = detector.run(run, trace, model=prepared.model)
        # e_x with the rejected-sample checks, as `logscan evaluate` scores encoded_ekf:e_x
        groups[name] = [a for a in result.alarms if a.signal == "e_x" or a.signal.startswith("rejected.")]
    scores = score_groups(events, groups, duration_s=60.0)
    e_x, defined, _ = EncodedEkfDetector(ex_statistic="raw").state_check(trace, prepared.model, None)
    e_x = np.where(defined, e_x, np.nan)
    k = int(np.searchsorted(run.t, start))
    before, after = e_x[k - 500 : k], e_x[k : k + 50]
    before, after = before[np.isfinite(before)], after[np.isfinite(after)]
    out = {"key": key, "seed": seed, "step": float((after.mean() - before.mean()) / before.std())}
    for name, s in scores.items():
        out[name] = (s.tp, s.mean_latency_s, s.fp)
    return out


def _cell(rows: list[dict], name: str, healthy: bool) -> str:
    if healthy:
        return f"{sum(r[name][2] for r in rows)} false alarms"
    hits = [r[name] for r in rows if r[name][0]]
    latencies = [h[1] for h in hits if h[1] is not None]
    timing = f" · {np.mean(latencies):.2f} s (max {max(latencies):.2f})" if latencies else ""
    fp = sum(r[name][2] for r in rows)
    return f"{len(hits)}/{len(rows)}{timing}" + (f", {fp} FP" if fp else "")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=2, help="worker processes")
    parser.add_argument("--table3", action="store_true", help="also the baseline, sensor and control-program rows")
    parser.add_argument("--model", choices=("quadcopter", "steer_by_wire"), default="quadcopter")
    parser.add_argument("--variant", choices=(*VARIANTS, "all"), default="all", help="the e_x statistic(s)")
    parser.add_argument("--seeds", type=int, default=len(SEEDS), help="runs per row (the first of 5100 ..)")
    args = parser.parse_args(argv)
    args.table3 = args.table3 or args.model == "steer_by_wire"
    variants = VARIANTS if args.variant == "all" else (args.variant,)
    from logscan.fleet import run_many

    threshold = None
    if args.table3:
        training = [(args.model, s) for s in TRAIN_SEEDS]
        threshold = max(run_many(training, healthy_peak, jobs=args.jobs, isolate=False))
        print(f"baseline threshold (max |e_x| over {len(TRAIN_SEEDS)} healthy runs): {threshold:.4g}")
    rows = _rows(args.model, args.table3)
    seeds = SEEDS[: args.seeds]
    jobs = [(key, s, threshold, args.model, variants) for key in rows for s in seeds]
    results = run_many(jobs, one, jobs=args.jobs, isolate=False)
    names = [*variants] + (["baseline"] if threshold is not None else [])
    print("| fault | raw e_x step / healthy std | " + " | ".join(f"`{n}`" for n in names) + " |")
    print("|---|---|" + "---|" * len(names))
    for key, (fault, label, _) in rows.items():
        mine = [r for r in results if r["key"] == key]
        steps = [r["step"] for r in mine]
        step = f"{np.mean(steps):+.2f} ({min(steps):+.2f} .. {max(steps):+.2f})" if fault else "-"
        cells = " | ".join(_cell(mine, n, fault is None) for n in names)
        print(f"| {label} | {step} | {cells} |")
    print(f"cells: detected of {len(seeds)} runs (within the fault + 1 s) · mean latency (max); FP: false alarms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
