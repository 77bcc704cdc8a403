"""False alarms per hour of every detector and check over >= 100 healthy simulated hours.

The campaign behind docs/evaluation.md ("The false-alarm budget over 100 hours"): healthy runs of
every simulated model (`--model` picks some): the quadcopter, the steer-by-wire, the Jackal-like UGV
(`dc_motor`: its mode cycle, `--aggressive` holding each speed half as long), the UBIKF paper's
`hover_uav`, the IMU-driven `ins` and the recovery paper's `ground_robot` (its healthy scenario; it
has no aggressive flight), normal and `--aggressive`, equal hours per configuration (100 h over the
11 configurations: 19 logs of 30 min each, 104.5 h in all), no faults and no glitches, so every alarm
is a false alarm. Each log is simulated, written as MCAP (ROS 2 CDR for the quadcopter and the
steer-by-wire, JSON for the others) in a temporary directory and analysed by
`logscan.pipeline.analyze_log` (the reader, pipeline and alarm rules of `logscan analyze`), in
local processes (`logscan.fleet.run_many`).

Detectors: those `logscan analyze` runs by default on these logs (the embedded profile's, else the
registry's defaults), plus every other registered detector that applies to the model: one that
runs without failing on a 60 s healthy probe log of it (a detector that needs another filter or
topics these logs lack is listed as not applicable, with its reason). The trained detectors
(`TRAINED`: atfm, atfm_residual, kgn) get tables from `logscan train` on TRAIN_LOGS healthy normal
logs of TRAIN_S seconds per model (unseen seeds, `TRAIN_SEED`), and every log is analysed with
them and with a profile enabling them (the embedded profile plus their sections): trained on
normal flights, judged on normal and aggressive ones.

Counting is `logscan evaluate`'s: alarms grouped per detector and per check
(`logscan.verdict.evaluation.alarm_groups`), merged into disjoint spans (`merge_intervals`); each span on
a healthy log is one false alarm. Rate = alarms / hours; the 95 % interval is the exact
(Garwood) Poisson interval

    lower = chi2.ppf(0.025, 2 n) / (2 T),     upper = chi2.ppf(0.975, 2 n + 2) / (2 T)

(lower = 0 when n = 0), n alarms over T hours. Seeds (used nowhere else: evaluate_detectors.py
uses 500 .. 4109):

    quadcopter 10000.., aggressive 11000..; steer_by_wire 12000.., aggressive 13000..;
    dc_motor 16000.., aggressive 17000..; hover_uav 18000.., aggressive 19000..; ins 20000..,
    aggressive 21000..; ground_robot 22000..; training: quadcopter 14000.., steer_by_wire 14100..,
    dc_motor 14200.., hover_uav 14300.., ins 14400.., ground_robot 14500..

    python bench/false_alarm_budget.py                       # 100 h, 2 processes
    python bench/false_alarm_budget.py --hours 4 --log-s 600 # a quick look
    python bench/false_alarm_budget.py --table runs.json      # the tables of a (partial) --json
    python bench/false_alarm_budget.py --detector atfm_residual --detector kgn   # only these (where they apply)
    python bench/false_alarm_budget.py --model dc_motor --detector atfm --hours 40   # one model
    python bench/false_alarm_budget.py --model hover_uav --detector chi2 --hours 40 --first-log 40   # 40 more
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import tempfile
import time
from dataclasses import dataclass
from datetime import UTC, datetime

MODELS = ("quadcopter", "steer_by_wire", "dc_motor", "hover_uav", "ins", "ground_robot")
SEED_BASE = {
    ("quadcopter", False): 10000,
    ("quadcopter", True): 11000,
    ("steer_by_wire", False): 12000,
    ("steer_by_wire", True): 13000,
    ("dc_motor", False): 16000,
    ("dc_motor", True): 17000,
    ("hover_uav", False): 18000,
    ("hover_uav", True): 19000,
    ("ins", False): 20000,
    ("ins", True): 21000,
    ("ground_robot", False): 22000,  # its healthy scenario; it has no aggressive flight
}
DEFAULT_MODELS = MODELS  # every simulated model; --model picks some (the 2026-11 figures: the first three)
TRAINED = ("atfm", "atfm_residual", "kgn")  # trained on normal logs (atfm: models with a redundant group)
TRAIN_SEED = {
    "quadcopter": 14000,
    "steer_by_wire": 14100,
    "dc_motor": 14200,
    "hover_uav": 14300,
    "ins": 14400,
    "ground_robot": 14500,
}
ROS2_CDR = ("quadcopter", "steer_by_wire")  # the others' logs are MCAP with JSON (field names CDR refuses)
TRAIN_LOGS, TRAIN_S = 4, 600.0
BUDGET_PER_HOUR = 0.1
PROBE_S = 60.0
PROBE_SEED = 9999
CHUNK = 16  # logs per run_many call (the --json file is rewritten after each)


@dataclass(frozen=True)
class Job:
    model: str
    aggressive: bool
    seed: int
    duration_s: float
    detectors: tuple[str, ...]
    profile: str | None = None  # the embedded profile with the trained detectors enabled
    tables: str | None = None  # their tables (`logscan train` on the model's training logs)


@dataclass(frozen=True)
class Trained:
    """One model's profile enabling the trained detectors, and their tables."""

    profile: str
    tables: str
    detectors: tuple[str, ...]


def poisson_interval(n: int, hours: float, level: float = 0.95) -> tuple[float, float]:
    """Exact (Garwood) two-sided interval of a Poisson rate: n events over ``hours``."""
    from scipy.stats import chi2

    tail = (1.0 - level) / 2.0
    lower = 0.0 if n == 0 else float(chi2.ppf(tail, 2 * n)) / (2.0 * hours)
    upper = float(chi2.ppf(1.0 - tail, 2 * n + 2)) / (2.0 * hours)
    return lower, upper


def _simulate(model: str, aggressive: bool, seed: int, duration_s: float, directory: str) -> str:
    from logscan.simulate import simulate, write_simulation

    if model == "ground_robot":  # no aggressive flight; its anomalies come from a scenario
        sim = simulate(model, duration=duration_s, seed=seed, scenario="healthy")
    else:
        sim = simulate(model, [], duration=duration_s, seed=seed, aggressive=aggressive)
    path = os.path.join(directory, f"{model}_{'aggressive' if aggressive else 'normal'}_{seed}.mcap")
    # e.g. the UGV's input topic has fields no ROS 2 message may have ('Va'): MCAP with JSON there
    write_simulation(sim, path, "mcap-ros2" if model in ROS2_CDR else "mcap-json")
    return path


def train(model: str, directory: str) -> tuple[Trained | None, dict[str, str]]:
    """`logscan train` on TRAIN_LOGS healthy normal logs of ``model`` with a profile enabling the
    trained detectors (atfm only where the profile has a redundant group); those that cannot be
    trained on this model (e.g. atfm_residual without a mode channel) are left out, with the reason."""
    from logscan.pipeline import load_profile_for

    logs = [_simulate(model, False, TRAIN_SEED[model] + k, TRAIN_S, directory) for k in range(TRAIN_LOGS)]
    loaded = load_profile_for(logs[0], None)
    names = [n for n in TRAINED if n != "atfm" or loaded.profile.to_dict().get("redundant")]
    reasons: dict[str, str] = {}
    trained = None
    try:
        trained = _train_with(model, loaded.profile.to_toml(), names, logs, directory)
    except Exception:  # noqa: BLE001 - find which detector cannot be trained here, train the rest
        for name in names:
            try:
                _train_with(model, loaded.profile.to_toml(), [name], logs, directory)
            except Exception as exc:  # noqa: BLE001 - that one does not apply to this model
                reasons[name] = f"not trainable here: {type(exc).__name__}: {exc}"
        rest = [n for n in names if n not in reasons]
        trained = _train_with(model, loaded.profile.to_toml(), rest, logs, directory) if rest else None
    for path in logs:
        os.unlink(path)
    return trained, reasons


def _train_with(model: str, profile_toml: str, names: list[str], logs: list[str], directory: str) -> Trained:
    """Tables of the detectors ``names`` trained on ``logs``, with the profile that enables them."""
    from logscan.artifacts import json_text
    from logscan.training.train import train_logs

    profile = os.path.join(directory, f"{model}.toml")
    with open(profile, "w", encoding="utf-8") as fh:
        fh.write(profile_toml + "".join(f"\n[detectors.{n}]\n" for n in names))
    tables = os.path.join(directory, f"{model}.tables.json")
    with open(tables, "w", encoding="utf-8") as fh:
        fh.write(json_text(train_logs(logs, profile)))
    return Trained(profile, tables, tuple(names))


def probe(model: str, trained: Trained | None, names: list[str]) -> tuple[list[str], dict[str, str]]:
    """(the default detectors on this model's logs, {detector: why it does not apply}) from one
    short healthy log run through each of ``names`` (the trained ones with ``trained``)."""
    from logscan.pipeline import analyze_log, create_detectors, load_profile_for

    reasons: dict[str, str] = {}
    profile, tables = (trained.profile, trained.tables) if trained else (None, None)
    with tempfile.TemporaryDirectory() as directory:
        path = _simulate(model, False, PROBE_SEED, PROBE_S, directory)
        defaults = [d.name for d in create_detectors(load_profile_for(path, None))]
        for name in names:
            try:  # one detector at a time: one that cannot run must not take the others down
                analysis = analyze_log(path, profile, detector_names=[name], tables=tables)
            except Exception as exc:  # noqa: BLE001 - a detector that cannot run here does not apply
                reasons[name] = f"{type(exc).__name__}: {exc}"
                continue
            if analysis.failures:
                reasons[name] = analysis.failures[0].message
    return defaults, reasons


def count_one(job: Job) -> dict:
    """Simulate and analyse one healthy log; its false alarms per detector and check, with each
    alarm's statistic and peak / threshold (a "hair above" crossing reads 1.00)."""
    from logscan.pipeline import analyze_log
    from logscan.verdict.evaluation import alarm_groups, merge_intervals

    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as directory:
        path = _simulate(job.model, job.aggressive, job.seed, job.duration_s, directory)
        analysis = analyze_log(path, job.profile, detector_names=list(job.detectors), tables=job.tables)
    # a hierarchical log's further loops (the ground robot's motors) are judged too: their alarms
    # join their detector's count, their signals naming the loop (`alarm_groups`)
    loops = {name: loop.results for name, loop in analysis.loops.items()}
    groups = alarm_groups(analysis.results, loops)
    alarms = [
        {
            "detector": result.detector,
            "signal": prefix + alarm.signal,
            "start": float(alarm.start),
            "end": float(alarm.end),
            "ratio": None if alarm.peak_ratio is None else float(alarm.peak_ratio),
        }
        for prefix, results in [("", analysis.results), *((f"{n}/", r) for n, r in loops.items())]
        for result in results
        for alarm in result.alarms
    ]
    return {
        "model": job.model,
        "aggressive": job.aggressive,
        "seed": job.seed,
        "hours": float(analysis.run.t[-1] - analysis.run.t[0]) / 3600.0,
        "counts": {key: len(merge_intervals(items)) for key, items in groups.items()},
        "failures": [f"{f.detector}: {f.message}" for f in analysis.failures],
        # what a detector said it did not check (kgn: a flight outside its trained envelope)
        "not_checked": {r.detector: [c.reason for c in r.not_checked] for r in analysis.results if r.not_checked},
        "alarms": alarms,
        "seconds": time.perf_counter() - started,
    }


def make_jobs(
    hours: float,
    log_s: float,
    detectors: dict[str, tuple[str, ...]],
    trained: dict[str, Trained | None],
    first_log: int = 0,
) -> list[Job]:
    """Equal hours per (model, aggressive) configuration of the models in ``detectors``, in logs of
    ``log_s`` seconds; each configuration's seeds from its base + ``first_log`` (a later run that
    extends an earlier one's hours flies unseen seeds)."""
    configs = [c for c in SEED_BASE if c[0] in detectors]
    per_config = max(1, math.ceil(hours * 3600.0 / len(configs) / log_s - 1e-9))  # at least ``hours``
    jobs = []
    for model, aggressive in configs:
        base = SEED_BASE[(model, aggressive)]
        mine = trained.get(model)
        where = (mine.profile, mine.tables) if mine else (None, None)
        seeds = range(base + first_log, base + first_log + per_config)
        jobs += [Job(model, aggressive, seed, log_s, detectors[model], *where) for seed in seeds]
    return jobs


def rate_table(runs: list[dict]) -> str:
    """One row per detector and check: alarms, hours, rate and its 95 % interval, per configuration."""
    configs = _configs_of(runs)
    hours = {c: sum(r["hours"] for r in runs if (r["model"], r["aggressive"]) == c) for c in configs}
    keys = sorted({k for r in runs for k in r["counts"]}, key=lambda k: (k.split(":")[0], ":" in k, k))
    head = " | ".join(f"{m}{' aggressive' if a else ''} ({hours[(m, a)]:.1f} h)" for m, a in configs)
    lines = [
        f"| detector / check | false alarms | hours | rate / h | 95 % interval / h | within {BUDGET_PER_HOUR:g} / h "
        f"(rate; upper end) | {head} |",
        "|---|---:|---:|---:|---|---|" + "---:|" * len(configs),
    ]
    for key in keys:
        mine = [r for r in runs if key in r["counts"]]  # a check counts the hours of the logs it ran on
        n = sum(r["counts"][key] for r in mine)
        key_hours = sum(r["hours"] for r in mine)
        lower, upper = poisson_interval(n, key_hours)
        rate = n / key_hours
        verdict = f"{'yes' if rate <= BUDGET_PER_HOUR else 'NO'}; {'yes' if upper <= BUDGET_PER_HOUR else 'no'}"
        per = " | ".join(_config_count(mine, key, c) for c in configs)
        name = key if ":" not in key else f"&nbsp;&nbsp;{key}"
        lines.append(f"| {name} | {n} | {key_hours:.1f} | {rate:.3f} | {lower:.3f} - {upper:.3f} | {verdict} | {per} |")
    return "\n".join(lines) + "\n"


def _configs_of(runs: list[dict]) -> list[tuple[str, bool]]:
    """The (model, aggressive) configurations the runs cover, in SEED_BASE's order."""
    seen = {(r["model"], r["aggressive"]) for r in runs}
    return [c for c in SEED_BASE if c in seen]


def _config_count(runs: list[dict], key: str, config: tuple[str, bool]) -> str:
    """False alarms of ``key`` on one configuration's logs; "-" where the check did not run."""
    here = [r["counts"][key] for r in runs if (r["model"], r["aggressive"]) == config and key in r["counts"]]
    return str(sum(here)) if here else "-"


def _ratio(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


def not_checked_list(runs: list[dict]) -> str:
    """Per configuration and detector, the logs with a `not checked` line, and the first line."""
    seen: dict[tuple[str, str], list[str]] = {}
    for r in runs:
        for detector, lines in (r.get("not_checked") or {}).items():
            config = f"{r['model']}{' aggressive' if r['aggressive'] else ''}"
            seen.setdefault((config, detector), []).extend(lines[:1])
    if not seen:
        return "Nothing reported as not checked.\n"
    logs = {
        f"{m}{' aggressive' if a else ''}": sum(1 for r in runs if (r["model"], r["aggressive"]) == (m, a))
        for m, a in _configs_of(runs)
    }
    rows = [f"| {c} | {d} | {len(lines)} of {logs[c]} | {lines[0]} |" for (c, d), lines in sorted(seen.items())]
    return "| configuration | detector | logs | first line |\n|---|---|---:|---|\n" + "\n".join(rows) + "\n"


def alarm_list(runs: list[dict]) -> str:
    """Every false alarm: log, statistic, start, length and peak / threshold."""
    rows = [
        f"| {r['model']}{' aggressive' if r['aggressive'] else ''} seed {r['seed']} | {a['detector']} "
        f"{a['signal']} | {a['start']:.2f} s | {a['end'] - a['start']:.2f} s | "
        f"{_ratio(a['ratio'])} |"
        for r in runs
        for a in r["alarms"]
    ]
    if not rows:
        return "No alarm.\n"
    head = "| log | statistic | start | length | peak / threshold |\n|---|---|---:|---:|---:|\n"
    return head + "\n".join(rows) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=100.0, help="healthy hours in all (equal per configuration)")
    parser.add_argument("--log-s", type=float, default=1800.0, help="length of each simulated log (s)")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes")
    parser.add_argument(
        "--first-log",
        type=int,
        default=0,
        help="start each configuration's seeds this many logs past its base (extend an earlier run's hours)",
    )
    parser.add_argument(
        "--detector", action="append", default=None, help="only these detectors, where they apply (repeatable)"
    )
    parser.add_argument(
        "--model",
        action="append",
        default=None,
        choices=MODELS,
        help=f"only these models (repeatable; default: {', '.join(DEFAULT_MODELS)})",
    )
    parser.add_argument("--json", dest="json_path", default=None, help="write every log's counts and alarms here")
    parser.add_argument("--table", default=None, help="only print the tables of a --json file (also a partial one)")
    args = parser.parse_args(argv)
    if args.table:
        import json

        with open(args.table, encoding="utf-8") as handle:
            document = json.load(handle)
        runs = document["runs"]
        hours = sum(r["hours"] for r in runs)
        state = "partial: " if document.get("partial") else ""
        print(f"{state}{len(runs)} logs, {hours:.1f} h, {document['elapsed_s']:.0f} s\n")
        print(rate_table(runs) + "\n" + alarm_list(runs) + "\nNot checked:\n\n" + not_checked_list(runs))
        return 0

    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from evaluate_detectors import code_version

    with tempfile.TemporaryDirectory(prefix="false-alarm-budget-") as directory:
        return campaign(args, directory, code_version())


def campaign(args, directory: str, version: str) -> int:
    """Train, probe and run the healthy logs; print the tables (and write --json)."""
    import logscan
    from logscan.detectors.registry import default_registry
    from logscan.fleet import run_many

    started = time.perf_counter()
    detectors: dict[str, tuple[str, ...]] = {}
    reasons: dict[str, dict[str, str]] = {}
    trained: dict[str, Trained | None] = {}
    wanted = args.detector or default_registry().names()
    models = tuple(dict.fromkeys(args.model or DEFAULT_MODELS))
    for model in models:
        untrainable: dict[str, str] = {}
        if any(n in TRAINED for n in wanted):
            trained[model], untrainable = train(model, directory)
        else:
            trained[model] = None
        defaults, reasons[model] = probe(model, trained[model], [n for n in wanted if n not in untrainable])
        reasons[model].update(untrainable)
        applicable = [n for n in wanted if n not in reasons[model]]
        chosen = (defaults if not args.detector else []) + applicable
        detectors[model] = tuple(dict.fromkeys(chosen))
    jobs = make_jobs(args.hours, args.log_s, detectors, trained, args.first_log)
    runs: list[dict] = []
    # in chunks, the configurations interleaved, so that an interrupted campaign still has a
    # balanced partial result in --json (written after every chunk)
    order = sorted(jobs, key=lambda job: (job.seed % 1000, job.seed))
    for first in range(0, len(order), CHUNK):
        runs += run_many(order[first : first + CHUNK], count_one, jobs=args.jobs, isolate=False)
        if args.json_path:
            _write(args.json_path, time.perf_counter() - started, detectors, reasons, runs, partial=True)
    elapsed = time.perf_counter() - started
    total_hours = sum(r["hours"] for r in runs)
    failures = sorted({f for r in runs for f in r["failures"]})
    per_log = sum(r["seconds"] for r in runs) / max(len(runs), 1)

    lines = [
        f"Measured {datetime.now(UTC):%Y-%m-%d %H:%M} UTC with logscan {logscan.__version__} ({version}), "
        f"`python bench/false_alarm_budget.py --hours {args.hours:g} --log-s {args.log_s:g} --jobs {args.jobs}"
        + (f" --first-log {args.first_log}" if args.first_log else "")
        + "".join(f" --model {m}" for m in args.model or [])
        + "".join(f" --detector {n}" for n in args.detector or [])
        + "`: "
        f"{len(runs)} healthy logs, {total_hours:.1f} h, in {elapsed:.0f} s ({per_log:.1f} s per log: simulate, "
        f"write, analyse; {os.cpu_count()} CPUs, {platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}).",
        "",
        "Detectors run: "
        + "; ".join(f"{model}: {', '.join(detectors[model])}" for model in models)
        + ". Not applicable: "
        + ("; ".join(f"{m}: {n} ({why})" for m in models for n, why in sorted(reasons[m].items())) or "none")
        + ".",
        "",
        rate_table(runs),
        "False alarms:",
        "",
        alarm_list(runs),
        "Not checked:",
        "",
        not_checked_list(runs),
    ]
    if failures:
        lines += ["Detector failures:", ""] + [f"- {f}" for f in failures] + [""]
    print("\n".join(lines))
    if args.json_path:
        _write(args.json_path, elapsed, detectors, reasons, runs, partial=False)
    return 0


def _write(path: str, elapsed: float, detectors: dict, reasons: dict, runs: list[dict], *, partial: bool) -> None:
    from logscan.artifacts import write_json

    document = {"elapsed_s": elapsed, "partial": partial, "detectors": detectors, "reasons": reasons, "runs": runs}
    write_json(path, document)


if __name__ == "__main__":
    sys.exit(main())
