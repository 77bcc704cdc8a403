"""The UBIKF chi-square test on the paper's two hover-UAV scenarios, next to the NIS test on the same logs.

The scenarios (`logscan simulate hover_uav`; the UBIKF paper's section IV.B): a
0.1 rad bias on the roll output for samples k in [30, 70], and the total loss of rotor 1 from
k = 31 (k counted from the excitation's start, docs/models.md); RUNS unseen seeds each, and RUNS
healthy runs for false alarms. Each log is analysed by `chi2` (robust alarms, and "possible fault"
warnings counted apart) and by `nis`, with default settings. Scoring is `logscan.verdict.scoring`'s: an
alarm detects a fault when it starts between the fault's start and 1 s after its end.

Seeds (none used by sample_logs/ or the tests): roll bias 8000.., rotor loss 8100.., healthy 8200..

    python bench/ubikf_scenarios.py                    # 20 runs per scenario
    python bench/ubikf_scenarios.py --runs 3           # a quick look
    python bench/ubikf_scenarios.py --write-docs       # also rewrite the table in docs/evaluation.md
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from dataclasses import dataclass

from benchlib import publish, simulate_log  # bench/ is on the path when this script runs

SCENARIOS = {"roll bias (0.1 rad, k 30-70)": ("roll-bias", 8000), "rotor 1 lost (k 31)": ("rotor-loss", 8100)}
HEALTHY_SEED = 8200
DURATION_S = 30.0
DETECTORS = ("chi2", "nis")
DOC = os.path.join(os.path.dirname(__file__), "..", "docs", "evaluation.md")
BEGIN, END = "<!-- ubikf-scenarios:begin -->", "<!-- ubikf-scenarios:end -->"


@dataclass(frozen=True)
class Run:
    fault: str | None
    seed: int


@dataclass(frozen=True)
class RunTask:
    root: str

    def __call__(self, run: Run) -> dict:
        from logscan.pipeline import analyze_log

        path = os.path.join(self.root, f"run-{run.seed}.mcap")
        fault = ("--fault", run.fault) if run.fault else ()
        simulate_log("hover_uav", path, "--duration", str(DURATION_S), "--seed", str(run.seed), *fault)
        analysis = analyze_log(path, detector_names=list(DETECTORS), free_series=True)
        out = {}
        for name in DETECTORS:
            score = analysis.scores[name]
            possible = [p for r in analysis.results if r.detector == name for p in r.possible]
            out[name] = {
                "tp": score.tp, "fp": score.fp,
                "latency": score.latencies_s[0] if score.latencies_s else None,
                "possible": len(possible),
            }  # fmt: skip
        os.unlink(path)
        return out


def table(outcomes: dict, runs: int) -> list[str]:
    lines = [
        f"| scenario ({runs} seeds) | `chi2` robust alarm: detected | latency | `nis`: detected | latency |",
        "|---|---:|---:|---:|---:|",
    ]
    for label, results in outcomes["faults"].items():
        cells = []
        for name in DETECTORS:
            tp = sum(r[name]["tp"] for r in results)
            latencies = [r[name]["latency"] for r in results if r[name]["latency"] is not None]
            lat = f"{sum(latencies) / len(latencies):.2f} s" if latencies else "-"
            cells += [f"{tp}/{len(results)}", lat]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    healthy = outcomes["healthy"]
    fa = {name: sum(r[name]["fp"] for r in healthy) for name in DETECTORS}
    possible = sum(r["chi2"]["possible"] for r in healthy)
    lines += [
        "",
        f"Healthy: {len(healthy)} runs of {DURATION_S:g} s; false alarms: chi2 {fa['chi2']}, nis {fa['nis']}; "
        f"chi2 possible-fault warnings: {possible}.",
    ]
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--write-docs", action="store_true")
    parser.add_argument("-q", "--quiet", action="store_true")
    args = parser.parse_args()
    from logscan.fleet import LogFailure, run_many

    started = time.time()
    runs = [Run(fault, seed + r) for fault, seed in SCENARIOS.values() for r in range(args.runs)]
    runs += [Run(None, HEALTHY_SEED + r) for r in range(args.runs)]
    with tempfile.TemporaryDirectory(prefix="ubikf-") as root:
        results = run_many(runs, RunTask(root), jobs=args.jobs, progress=not args.quiet, label="runs", isolate=True)
    failed = [r for r in results if isinstance(r, LogFailure)]
    if failed:
        raise SystemExit(f"{len(failed)} run(s) failed, first: {failed[0].message}")
    outcomes: dict = {"faults": {}, "healthy": []}
    labels = {fault: label for label, (fault, _) in SCENARIOS.items()}
    for run, result in zip(runs, results):
        if run.fault is None:
            outcomes["healthy"].append(result)
        else:
            outcomes["faults"].setdefault(labels[run.fault], []).append(result)
    lines = table(outcomes, args.runs)
    lines.append(f"\n(`python bench/ubikf_scenarios.py --runs {args.runs}`, {(time.time() - started) / 60:.0f} min.)")
    text = "\n".join(lines)
    publish(text, args.write_docs, DOC, BEGIN, END)


if __name__ == "__main__":
    main()
