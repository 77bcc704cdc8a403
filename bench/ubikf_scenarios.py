"""The UBIKF chi-square test on the paper's two hover-UAV scenarios, next to the NIS test on the same logs.

The scenarios (`logscan simulate hover_uav`; the UBIKF paper's section IV.B): a
0.1 rad bias on the roll output for samples k in [30, 70], and the total loss of rotor 1 from
k = 31 (k counted from the excitation's start, docs/models.md); RUNS unseen seeds each, and RUNS
healthy runs of --healthy-s seconds for false alarms. Every run flies an off-nominal plant drawn
inside hover_uav's intervals (`logscan simulate --plant-draw`; --nominal: the nominal plant), while
the analysis keeps the nominal model. Each log is analysed by `chi2` (robust alarms; the share of
updates where its upper band straddles delta is reported apart) and by `nis`, with default settings.
"In window": the first alarm starts inside the fault's own window [start, end] (no grace).

Seeds (none used by sample_logs/, the tests or during development, 8000..8219 and 9000..9219): roll
bias 9400.., rotor loss 9500.., healthy 9600..

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

SCENARIOS = {"roll bias (0.1 rad, k 30-70)": ("roll-bias", 9400), "rotor 1 lost (k 31)": ("rotor-loss", 9500)}
HEALTHY_SEED = 9600
DURATION_S = 30.0
DETECTORS = ("chi2", "nis")
DOC = os.path.join(os.path.dirname(__file__), "..", "docs", "evaluation.md")
BEGIN, END = "<!-- ubikf-scenarios:begin -->", "<!-- ubikf-scenarios:end -->"


@dataclass(frozen=True)
class Run:
    fault: str | None
    seed: int
    duration: float = DURATION_S


@dataclass(frozen=True)
class RunTask:
    root: str
    plant_draw: bool = True

    def __call__(self, run: Run) -> dict:
        from logscan.pipeline import analyze_log

        path = os.path.join(self.root, f"run-{run.seed}.mcap")
        fault = ("--fault", run.fault) if run.fault else ()
        draw = ("--plant-draw",) if self.plant_draw else ()
        simulate_log("hover_uav", path, "--duration", str(run.duration), "--seed", str(run.seed), *fault, *draw)
        analysis = analyze_log(path, detector_names=list(DETECTORS), free_series=True)
        window = (analysis.events[0].t_start, analysis.events[0].t_end) if analysis.events else None
        out = {}
        for result in analysis.results:
            name = result.detector
            score = analysis.scores[name]
            starts = sorted(float(a.start) for a in result.alarms)
            first = next((s for s in starts if window and s >= window[0]), None)
            out[name] = {
                "tp": score.tp, "fp": score.fp,
                "latency": score.latencies_s[0] if score.latencies_s else None,
                "in_window": bool(window and first is not None and first <= window[1]),
                "straddles": result.info.get("band_straddles_delta"),
                "hours": run.duration / 3600.0,
            }  # fmt: skip
        os.unlink(path)
        return out


def table(outcomes: dict, runs: int) -> list[str]:
    lines = [
        f"| scenario ({runs} seeds) | `chi2` robust alarm: in window | latency (mean, max) | "
        "`nis`: in window | latency (mean, max) |",
        "|---|---:|---:|---:|---:|",
    ]
    for label, results in outcomes["faults"].items():
        cells = []
        for name in DETECTORS:
            inside = sum(r[name]["in_window"] for r in results)
            latencies = [r[name]["latency"] for r in results if r[name]["latency"] is not None]
            lat = f"{sum(latencies) / len(latencies):.2f} s, {max(latencies):.2f} s" if latencies else "-"
            cells += [f"{inside}/{len(results)}", lat]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    healthy = outcomes["healthy"]
    hours = sum(r["chi2"]["hours"] for r in healthy)
    fa = {name: sum(r[name]["fp"] for r in healthy) for name in DETECTORS}
    straddles = [r["chi2"]["straddles"] for r in healthy if r["chi2"]["straddles"] is not None]
    share = f"{100 * sum(straddles) / len(straddles):.2f} %" if straddles else "-"
    lines += [
        "",
        f"Healthy: {len(healthy)} runs, {hours:.2f} h; false alarms: chi2 {fa['chi2']} "
        f"({fa['chi2'] / hours:.2f} per hour), nis {fa['nis']} ({fa['nis'] / hours:.2f} per hour); chi2's "
        f"upper band straddles delta at {share} of healthy updates (drawn, not counted).",
    ]
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--healthy-s", type=float, default=180.0, help="duration of each healthy run (s)")
    parser.add_argument("--nominal", action="store_true", help="fly the nominal plant instead of a drawn one")
    parser.add_argument("--write-docs", action="store_true")
    parser.add_argument("-q", "--quiet", action="store_true")
    args = parser.parse_args()
    from logscan.fleet import LogFailure, run_many

    started = time.time()
    runs = [Run(fault, seed + r) for fault, seed in SCENARIOS.values() for r in range(args.runs)]
    runs += [Run(None, HEALTHY_SEED + r, args.healthy_s) for r in range(args.runs)]
    with tempfile.TemporaryDirectory(prefix="ubikf-") as root:
        task = RunTask(root, plant_draw=not args.nominal)
        results = run_many(runs, task, jobs=args.jobs, progress=not args.quiet, label="runs", isolate=True)
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
    plant = "nominal plant" if args.nominal else "plants drawn inside the intervals"
    command = f"python bench/ubikf_scenarios.py --runs {args.runs} --healthy-s {args.healthy_s:g}"
    lines.append(f"\n({plant}; `{command}`, {(time.time() - started) / 60:.0f} min.)")
    text = "\n".join(lines)
    publish(text, args.write_docs, DOC, BEGIN, END)


if __name__ == "__main__":
    main()
