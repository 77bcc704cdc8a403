"""Noise calibration (`logscan train --calibrate`) judged on unseen healthy flights: each measurement
group's mean NIS per output and the false alarms per hour, with a deliberately wrong profile alone
and with the tables calibrated on other healthy flights (issue 14).

Flights: healthy simulated `ins` flights (`logscan simulate ins --duration D --seed S`, no faults,
so every alarm is a false alarm): TRAIN training flights (seeds 9101..), TEST unseen ones (seeds
9201..), D = 300 s by default. The wrong profiles are the embedded profile of the first training
flight (`load_profile_for(path, None).text`) with

 - `r5`: every group's noise_std 5x the simulated one (variance 25x), as tests/test_calibration.py;
 - `r5q10`: that, and the process noise 10x the simulated variance: the `ins` model's process-noise
   parameters in [vehicle] params (accel_noise, gyro_noise, accel_bias_rw, gyro_bias_rw,
   baro_offset_rw; the simulator draws its IMU noise and random walks from the same parameters)
   at sqrt(10) times the model's defaults.

For each wrong profile, through the CLI (its `main`, in this process):

    logscan train TRAIN... --profile WRONG --calibrate -o tables.json --no-report -q
    logscan analyze TEST --profile WRONG --tables tables.json --no-report --json out.json -q
    logscan analyze TEST --profile WRONG --no-report --json out.json -q      # the uncalibrated baseline

Mean NIS per output: the JSON summary's `filter.mean_nis` (per group) over the group's size
(`get_model("ins").group(name).size`); the table gives the mean over the test flights and their
min-max (a consistent filter: 1). False alarms: the plain alarm count of each detector the
analysis runs (`detectors[i].n_alarms`, the profile's defaults), not merged per check as
`logscan evaluate` does; hours are the test flights' logged duration; the 95 % upper end is the
exact (Garwood) Poisson one, chi2.ppf(0.975, 2 (k + 1)) / 2 / hours (`false_alarm_budget.py`).

    python bench/calibration_holdout.py                         # 5 training + 20 unseen flights of 300 s
    python bench/calibration_holdout.py --train 2 --test 2 --duration 60 --profiles r5   # a quick look
    python bench/calibration_holdout.py --json runs.json        # also keep every flight's figures
    python bench/calibration_holdout.py --table runs.json       # the tables of a --json again
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import re
import sys
import tempfile
import time

from benchlib import simulate_log  # bench/ is on the path when this script runs
from false_alarm_budget import poisson_interval

MODEL = "ins"
TRAIN_SEED = 9101
TEST_SEED = 9201
R_FACTOR = 5.0  # noise_std x 5
Q_FACTOR = 10.0  # process-noise variance x 10
Q_PARAMS = ("accel_noise", "gyro_noise", "accel_bias_rw", "gyro_bias_rw", "baro_offset_rw")
PROFILES = {
    "r5": f"noise_std {R_FACTOR:g}x",
    "r5q10": f"noise_std {R_FACTOR:g}x, Q {Q_FACTOR:g}x",
}
NIS_BAND = (0.5, 2.0)


def logscan(*args: str) -> int:
    """``logscan ARGS`` in this process (its stdout swallowed); the exit code."""
    from logscan.cli.main import main

    with contextlib.redirect_stdout(io.StringIO()):
        try:
            main(list(args))
        except SystemExit as exc:
            return int(exc.code or 0)
    return 0


def wider_noise(text: str) -> str:
    """The profile with every noise_std R_FACTOR times its own (tests/test_calibration.py's)."""

    def wider(match):
        return "noise_std = [" + ", ".join(f"{R_FACTOR * float(v):g}" for v in match.group(1).split(",")) + "]"

    return re.sub(r"noise_std = \[([^\]]*)\]", wider, text)


def more_process_noise(text: str) -> str:
    """The profile with [vehicle] params putting the ins model's process-noise variance Q_FACTOR
    times the defaults (each std parameter sqrt(Q_FACTOR) times)."""
    from logscan.models.ins import DEFAULTS

    head, sep, rest = text.partition("[vehicle]\n")
    if not sep or re.search(r"^params\s*=", rest.split("\n[", 1)[0], re.M):
        raise SystemExit("the embedded profile has no [vehicle] table, or already sets params")
    values = ", ".join(f"{name} = {DEFAULTS[name] * math.sqrt(Q_FACTOR):.6g}" for name in Q_PARAMS)
    return f"{head}[vehicle]\nparams = {{ {values} }}\n{rest}"


def wrong_profile(name: str, embedded: str) -> str:
    text = wider_noise(embedded)
    return more_process_noise(text) if name == "r5q10" else text


def analyze(log: str, profile: str, tables: str | None, out: str) -> dict:
    """One analysis's figures: mean NIS per output per group, alarms per detector, hours."""
    from logscan.models import get_model

    model = get_model(MODEL)
    extra = ["--tables", tables] if tables else []
    code = logscan("analyze", log, "--profile", profile, *extra, "--no-report", "--json", out, "-q")
    if not os.path.exists(out):
        raise RuntimeError(f"logscan analyze {log} exited {code} without a JSON summary")
    with open(out, encoding="utf-8") as fh:
        entry = json.load(fh)["logs"][0]
    os.unlink(out)
    return {
        "exit_code": code,
        "hours": entry["log"]["duration_s"] / 3600.0,
        "nis": {g: v / model.group(g).size for g, v in entry["filter"]["mean_nis"].items()},
        "alarms": {d["detector"]: d["n_alarms"] for d in entry["detectors"]},
        "n_alarms": entry["n_alarms"],
        "divergence_episodes": entry["filter"]["divergence_episodes"],
        "unchecked": entry["unchecked"],
    }


def calibration_summary(path: str) -> dict:
    """What the tables' calibration holds: per group the noise factor and training NIS, per block Q's scale."""
    with open(path, encoding="utf-8") as fh:
        calibration = json.load(fh)["calibration"]
    groups = {
        name: {
            "factor": e["noise_std"][0] / e["profile_noise_std"][0],
            "before": e["mean_nis_per_output_before"],
            "after": e["mean_nis_per_output_after"],
            "calibrated": e["calibrated"],
        }
        for name, e in calibration["groups"].items()
    }
    blocks = {name: (b["scale"], b["identified"]) for name, b in calibration["process_noise_blocks"].items()}
    return {"iterations": calibration["iterations"], "converged": calibration["converged"]} | {
        "groups": groups,
        "blocks": blocks,
    }


def run(args, say) -> dict:
    started = time.perf_counter()
    results: dict = {"profiles": {}, "args": vars(args) | {"profiles": list(args.profiles)}}
    with tempfile.TemporaryDirectory(prefix="calholdout-") as root:
        duration = ["--duration", f"{args.duration:g}"]
        training = []
        for seed in range(TRAIN_SEED, TRAIN_SEED + args.train):
            say(f"simulate training flight {seed}")
            path = os.path.join(root, f"train-{seed}.mcap")
            training.append(simulate_log(MODEL, path, *duration, "--seed", str(seed)))
        from logscan.pipeline import load_profile_for

        embedded = load_profile_for(training[0], None).text
        setups = {}
        for name in args.profiles:
            profile = os.path.join(root, f"{name}.toml")
            with open(profile, "w", encoding="utf-8") as fh:
                fh.write(wrong_profile(name, embedded))
            tables = os.path.join(root, f"{name}.tables.json")
            say(f"train --calibrate with {name}")
            t0 = time.perf_counter()
            code = logscan("train", *training, "--profile", profile, "--calibrate", "-o", tables, "--no-report", "-q")
            if code != 0:
                raise SystemExit(f"logscan train with {name} exited {code}")
            setups[name] = (profile, tables)
            results["profiles"][name] = {
                "train_s": time.perf_counter() - t0,
                "calibration": calibration_summary(tables),
                "profile": [],
                "tables": [],
            }
        for seed in range(TEST_SEED, TEST_SEED + args.test):
            say(f"unseen flight {seed}")
            log = simulate_log(MODEL, os.path.join(root, f"test-{seed}.mcap"), *duration, "--seed", str(seed))
            for name, (profile, tables) in setups.items():
                out = os.path.join(root, "out.json")
                results["profiles"][name]["profile"].append(analyze(log, profile, None, out) | {"seed": seed})
                results["profiles"][name]["tables"].append(analyze(log, profile, tables, out) | {"seed": seed})
            os.unlink(log)
    results["elapsed_s"] = time.perf_counter() - started
    return results


def _nis_cell(values: list[float]) -> str:
    mean = sum(values) / len(values)
    flag = "" if NIS_BAND[0] <= mean <= NIS_BAND[1] else " *"
    return f"{mean:.3g} ({min(values):.3g}-{max(values):.3g}){flag}"


def nis_table(results: dict) -> str:
    names = list(results["profiles"])
    runs = {n: results["profiles"][n] for n in names}
    groups = list(runs[names[0]]["tables"][0]["nis"])
    head = " | ".join(f"{PROFILES[n]}: profile | {PROFILES[n]}: + tables" for n in names)
    lines = [f"| group (mean NIS per output) | {head} |", "|---|" + "---:|" * (2 * len(names))]
    for group in groups:
        cells = []
        for n in names:
            for kind in ("profile", "tables"):
                cells.append(_nis_cell([r["nis"][group] for r in runs[n][kind]]))
        lines.append(f"| {group} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def alarm_table(results: dict) -> str:
    lines = [
        "| profile | detector | false alarms | flights | hours | per hour | 95 % upper / h |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for n, entry in results["profiles"].items():
        for kind in ("profile", "tables"):
            flights = entry[kind]
            hours = sum(r["hours"] for r in flights)
            detectors = list(dict.fromkeys(d for r in flights for d in r["alarms"]))
            counts = {d: sum(r["alarms"].get(d, 0) for r in flights) for d in detectors}
            counts["all"] = sum(r["n_alarms"] for r in flights)
            label = f"{PROFILES[n]}{' + tables' if kind == 'tables' else ''}"
            for d, k in counts.items():
                upper = poisson_interval(k, hours)[1]
                lines.append(f"| {label} | {d} | {k} | {len(flights)} | {hours:.2f} | {k / hours:.2f} | {upper:.2f} |")
    return "\n".join(lines)


def calibration_lines(results: dict) -> list[str]:
    lines = []
    for n, entry in results["profiles"].items():
        cal = entry["calibration"]
        groups = ", ".join(
            f"{g} {e['factor']:.3g}{'' if e['calibrated'] else ' (not calibrated)'}" for g, e in cal["groups"].items()
        )
        blocks = ", ".join(f"{b} {s:.3g}{'' if ok else ' (n.i.)'}" for b, (s, ok) in cal["blocks"].items())
        state = "converged" if cal["converged"] else "not converged"
        lines.append(
            f"- {PROFILES[n]}: trained in {entry['train_s']:.0f} s, {cal['iterations']} iteration(s), {state}; "
            f"noise_std factor: {groups}; Q scale per block: {blocks}"
        )
    return lines


def notes(results: dict) -> list[str]:
    """Analyses that did not end plainly (exit 2/3, divergence, unchecked parts)."""
    out = []
    for n, entry in results["profiles"].items():
        for kind in ("profile", "tables"):
            for r in entry[kind]:
                if r["exit_code"] not in (0, 1) or r["divergence_episodes"] or r["unchecked"]:
                    out.append(
                        f"- {PROFILES[n]} {kind}, seed {r['seed']}: exit {r['exit_code']}, "
                        f"{r['divergence_episodes']} divergence episode(s), unchecked {r['unchecked']}"
                    )
    return out


def report(results: dict) -> str:
    a = results["args"]
    command = (
        f"python bench/calibration_holdout.py --train {a['train']} --test {a['test']} --duration {a['duration']:g} "
        f"--profiles {' '.join(a['profiles'])}"
    )
    lines = [
        f"Trained on {a['train']} healthy `ins` flights (seeds {TRAIN_SEED}-{TRAIN_SEED + a['train'] - 1}), "
        f"judged on {a['test']} unseen ones (seeds {TEST_SEED}-{TEST_SEED + a['test'] - 1}), {a['duration']:g} s each. "
        f"Mean NIS per output: mean over the unseen flights (min-max); * outside {NIS_BAND[0]:g}-{NIS_BAND[1]:g}.",
        "",
        nis_table(results),
        "",
        "False alarms on the unseen flights (plain alarm count per detector; 95 % exact Poisson upper end):",
        "",
        alarm_table(results),
        "",
        "Calibration on the training flights (noise_std factor against the wrong profile; Q scale per block "
        "against the profile's Q, n.i. = not identifiable):",
        "",
        *calibration_lines(results),
    ]
    odd = notes(results)
    if odd:
        lines += ["", "Analyses that did not end plainly:", "", *odd]
    lines += ["", f"(`{command}`, {results['elapsed_s'] / 60:.1f} min.)"]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--train", type=int, default=5, help="healthy training flights (seeds 9101..)")
    parser.add_argument("--test", type=int, default=20, help="unseen healthy flights (seeds 9201..)")
    parser.add_argument("--duration", type=float, default=300.0, help="seconds per flight")
    parser.add_argument("--profiles", nargs="+", choices=tuple(PROFILES), default=list(PROFILES))
    parser.add_argument("--json", dest="json_path", default=None, help="also write every flight's figures here")
    parser.add_argument("--table", default=None, help="only print the tables of a --json file")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    args = parser.parse_args(argv)
    if args.table:
        with open(args.table, encoding="utf-8") as fh:
            print(report(json.load(fh)))
        return 0

    def say(message: str) -> None:
        if not args.quiet:
            print(message, file=sys.stderr, flush=True)

    results = run(args, say)
    if args.json_path:
        with open(args.json_path, "w", encoding="utf-8") as fh:
            json.dump(results, fh, indent=1)
    print(report(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
