"""A-TFM on the thesis's motivating family: adaptive lookup table vs a fixed row, and healthy hours.

The family (docs/algorithms.md section 4; the thesis's motivating example): the Jackal-like UGV
commanded 1.0 m/s, then 0.4 m/s from 30 s; an attack on one speed sensor in the slow part (50-80 s):
bias +m, or uniform random in [-m, m], m = 0.11, 0.22, 0.33 m/s, on the left encoder, the right
encoder and the GPS speed; RUNS unseen seeds each. Each run is analysed by `atfm` with the adaptive
table (rows selected by speed) and with the table's 1.0 m/s row throughout (the fixed row that
covers the whole run: the most conservative row the run needs), as the prototype compared them.
Healthy hours: random speed profiles with healthy transients (encoder slips, GPS glitches),
counting false alarms and alarms on the transients.

With ``--residual``, the hybrid KF + A-TFM (`atfm_residual`, thesis chapter IV) on its own
scenario: 1.3 m/s, then 0.4 m/s from 50 s, an attack in the slow part (70-90 s) of the thesis's
magnitudes 0.06, 0.12, 0.18 m/s (bias and uniform random) on each speed sensor; the adaptive table
against the table's 1.3 m/s row throughout (the thesis's fixed high threshold, Fig. 31a); the same
training logs and healthy runs.

Everything is made here with the installed CLI's code (`logscan simulate`, `logscan train`,
`logscan.pipeline`), in local processes. Seeds (none used by sample_logs/ or the tests):

  training      6000 .. 6007  (6 x 180 s mode cycles and 2 x 180 s random profiles, 2 glitches/min)
  family        5000 + 100 * case + run   (case: kind x magnitude x sensor, 18 cases)
  residual      8000 + 100 * case + run   (--residual: the chapter IV family, 18 cases)
  healthy       7000 ..        (RUNS_HEALTHY x 960 s random profiles, 2 glitches/min)

    python bench/atfm_family.py                       # 20 runs per case, 20 healthy runs (5.3 h)
    python bench/atfm_family.py --runs 3 --healthy 2  # a quick look
    python bench/atfm_family.py --write-docs          # also rewrite the table in docs/evaluation.md
    python bench/atfm_family.py --residual            # the hybrid KF + A-TFM on chapter IV's family
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from dataclasses import dataclass

from benchlib import publish, simulate_log  # bench/ is on the path when this script runs

KINDS = ("bias", "random")
MAGNITUDES = (0.11, 0.22, 0.33)
SENSORS = {"left encoder": "/enc/left.v", "right encoder": "/enc/right.v", "GPS speed": "/gps/speed"}
SPEEDS, DURATION_S, ATTACK_S = "1.0,0.4@30", 100.0, (50.0, 80.0)
FIXED_ROW = 1.0
# the hybrid KF + A-TFM (--residual): thesis chapter IV, section 3.2.3
RESIDUAL = {
    "detector": "atfm_residual", "magnitudes": (0.06, 0.12, 0.18), "speeds": "1.3,0.4@50",
    "attack": (70.0, 90.0), "fixed_row": 1.3, "seed": 8000,
}  # fmt: skip
FAMILY = {
    "detector": "atfm",
    "magnitudes": MAGNITUDES,
    "speeds": SPEEDS,
    "attack": ATTACK_S,
    "fixed_row": FIXED_ROW,
    "seed": 5000,
}
HEALTHY_S = 960.0
DOC = os.path.join(os.path.dirname(__file__), "..", "docs", "evaluation.md")
BEGIN, END = "<!-- atfm-family:begin -->", "<!-- atfm-family:end -->"


def simulate(path: str, seed: int, *args: str) -> str:
    return simulate_log("dc_motor", path, "--seed", str(seed), *args)


@dataclass(frozen=True)
class Case:
    kind: str
    magnitude: float
    sensor: str
    seed: int


@dataclass(frozen=True)
class RunTask:
    """Simulate one run and analyse it with both tables (picklable for local processes)."""

    root: str
    tables: str
    profiles: tuple[str, str]  # adaptive, fixed
    family: dict

    def __call__(self, case: Case) -> dict:
        from logscan.pipeline import analyze_log

        path = os.path.join(self.root, f"run-{case.seed}.mcap")
        family = self.family
        if case.kind == "healthy":
            simulate(path, case.seed, "--speed", "random", "--duration", str(HEALTHY_S), "--glitches", "2")
        else:
            start, end = family["attack"]
            fault = f"{case.kind}:{SENSORS[case.sensor]}:{start}:{end}:{case.magnitude}"
            simulate(path, case.seed, "--speed", family["speeds"], "--duration", str(DURATION_S), "--fault", fault)
        out = {}
        detector = family["detector"]
        for name, profile in zip(("adaptive", "fixed"), self.profiles):
            analysis = analyze_log(path, profile, detector_names=[detector], tables=self.tables, free_series=True)
            score = analysis.scores[detector]
            out[name] = {
                "tp": score.tp, "fn": score.fn, "fp": score.fp, "at_onset": score.at_onset,
                "transient": score.transient_alarms, "latency": score.latencies_s[0] if score.latencies_s else None,
            }  # fmt: skip
        os.unlink(path)
        return out


def train(root: str, quiet: bool, family: dict) -> tuple[str, tuple[str, str]]:
    """Tables from 8 healthy training logs, and the adaptive and fixed-row profiles (both enabling
    ``family``'s detector, so that training fits it)."""
    from logscan.pipeline import load_profile_for
    from logscan.training.train import train_logs

    logs = []
    for k in range(8):
        path = os.path.join(root, f"train-{k}.mcap")
        extra = ("--speed", "random") if k >= 6 else ("--noise", "speed")
        logs.append(simulate(path, 6000 + k, "--duration", "180", "--glitches", "2", *extra))
    base = load_profile_for(logs[0], None).profile.to_toml()
    profiles = []
    for name, extra in (("adaptive", ""), ("fixed", f"row = {family['fixed_row']}\n")):
        path = os.path.join(root, f"{name}.toml")
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(base + f"\n[detectors.{family['detector']}]\n{extra}")
        profiles.append(path)
    progress = None if quiet else (lambda m: print(f"  {m}", file=sys.stderr))
    document = train_logs(logs, profiles[0], progress=progress)
    tables = os.path.join(root, "tables.json")
    from logscan.artifacts import json_text

    with open(tables, "w", encoding="utf-8") as fh:
        fh.write(json_text(document))
    return tables, (profiles[0], profiles[1])


def table_rows(document: dict, runs: int, fixed_row: float) -> list[str]:
    """The markdown table: per case, detection rate and mean latency, adaptive | fixed."""
    lines = [
        f"| attack (slow part, {runs} seeds) | sensor | adaptive: detected | latency "
        f"| fixed {fixed_row:g} row: detected | latency |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for key, results in document["cases"].items():
        kind, magnitude, sensor = key.split("|")
        cells = []
        for method in ("adaptive", "fixed"):
            found = [r[method] for r in results]
            tp = sum(r["tp"] for r in found)
            latencies = [r["latency"] for r in found if r["latency"] is not None]
            lat = f"{sum(latencies) / len(latencies):.1f} s" if latencies else "-"
            cells += [f"{100 * tp / len(found):.0f} %", lat]
        lines.append(f"| {kind} {magnitude} m/s | {sensor} | " + " | ".join(cells) + " |")
    return lines


def healthy_line(document: dict) -> str:
    healthy = document["healthy"]
    hours = len(healthy) * HEALTHY_S / 3600.0
    parts = []
    for method in ("adaptive", "fixed"):
        fp = sum(r[method]["fp"] for r in healthy)
        transient = sum(r[method]["transient"] for r in healthy)
        parts.append(f"{method}: {fp} false alarm(s), {transient} alarm(s) on healthy transients")
    return (
        f"Healthy: {len(healthy)} runs, {hours:.1f} h of random speed profiles with transients; "
        + "; ".join(parts)
        + "."
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=20, help="seeds per case (default 20)")
    parser.add_argument("--healthy", type=int, default=20, help="healthy runs of 16 min (default 20: 5.3 h)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--write-docs", action="store_true", help="rewrite the table in docs/evaluation.md")
    parser.add_argument("--residual", action="store_true", help="the hybrid KF + A-TFM on chapter IV's family")
    parser.add_argument("-q", "--quiet", action="store_true")
    args = parser.parse_args()
    from logscan.fleet import LogFailure, run_many

    if args.residual and args.write_docs:
        raise SystemExit("--write-docs rewrites the atfm table only")
    family = RESIDUAL if args.residual else FAMILY
    started = time.time()
    with tempfile.TemporaryDirectory(prefix="atfm-family-") as root:
        tables, profiles = train(root, args.quiet, family)
        cases = []
        kinds = ((k, m, s) for k in KINDS for m in family["magnitudes"] for s in SENSORS)
        for c, (kind, magnitude, sensor) in enumerate(kinds):
            cases += [Case(kind, magnitude, sensor, family["seed"] + 100 * c + r) for r in range(args.runs)]
        cases += [Case("healthy", 0.0, "", 7000 + r) for r in range(args.healthy)]
        task = RunTask(root, tables, profiles, family)
        outcomes = run_many(cases, task, jobs=args.jobs, progress=not args.quiet, label="runs", isolate=True)
    failed = [o for o in outcomes if isinstance(o, LogFailure)]
    if failed:
        raise SystemExit(f"{len(failed)} run(s) failed, first: {failed[0].message}")
    document: dict = {"cases": {}, "healthy": []}
    for case, outcome in zip(cases, outcomes):
        if case.kind == "healthy":
            document["healthy"].append(outcome)
        else:
            document["cases"].setdefault(f"{case.kind}|{case.magnitude}|{case.sensor}", []).append(outcome)
    lines = table_rows(document, args.runs, family["fixed_row"]) + ["", healthy_line(document)]
    minutes = (time.time() - started) / 60.0
    flag = " --residual" if args.residual else ""
    lines.append(
        f"\n(`python bench/atfm_family.py{flag} --runs {args.runs} --healthy {args.healthy}`, {minutes:.0f} min.)"
    )
    text = "\n".join(lines)
    publish(text, args.write_docs, DOC, BEGIN, END)


if __name__ == "__main__":
    main()
