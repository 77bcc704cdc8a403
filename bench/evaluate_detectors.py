"""Detection rate, latency and false alarms of the encoded EKF checks vs. the baseline, e_v, NIS and e_s.

The evaluation behind bench/evaluation_notes.md (summarised in docs/evaluation.md), in the layout
of the encoded-EKF paper's Table III:
fresh simulated runs per fault family and model, methods side by side:

  A  time-varying encoded state check: e_x with the adaptive band mu +- rho s, together with the
     rejected-sample checks (`rejected.<group>`) of the same detector (default settings);
  B  the paper's reference [15]: constant coding vector CV_0 and a fixed threshold = max |e_x| over
     10 separate healthy training runs x margin 1.0 (`variant = "baseline"`, trained with `fit`);
     e_x only, as in [15];
  C  the variance check e_v (on-board covariance mode: the simulated logs carry /ekf/variance);
  D  the innovation chi-square test (NIS), any group or the overall test;
  E  the on-board state check e_s = CV_k (x_onboard - x_post) of the same encoded_ekf run (the
     simulated logs carry /ekf/state), band mu +- rho_s s; its alarms are kept out of A;
  F  the two-sided CUSUM on each whitened innovation (`cusum`), any group and axis;
  G  the frozen-sensor check (`frozen`), any measurement channel;
plus supplementary rows (A's e_x alone, the rejected-sample check alone, B with the
rejected-sample checks as the baseline-configured detector reports them, and "any alarm" of
`logscan analyze`'s default detectors).

Every run is 60 s, one fault starting at a uniform time in [20, 40) s (drawn from the run's seed)
with the family's default target, magnitude and length (`logscan simulate --help`); false alarms
per hour come from healthy runs (normal and `--aggressive`). Scoring is `logscan.verdict.scoring`'s
(docs/algorithms.md section 7): an alarm already on at the fault's onset is no detection (cells
count such runs apart), alarms in the recovery window after a detected fault are neither
detections nor false alarms (a row of their own). Seeds (none used by
sample_logs/make_samples.py or the tests; nothing was tuned on them):

  quadcopter fault runs      1000 + 100 * family index + run      (1000 .. 1819)
  steer_by_wire fault runs   2000 + 100 * family index + run      (2000 .. 2819)
  healthy                    quadcopter 3000.., aggressive 3100..; steer_by_wire 3200.., aggressive 3300..
  baseline training          quadcopter 4000 .. 4009, steer_by_wire 4100 .. 4109 (healthy, normal)

Runs go through the Python API (simulate -> MCAP (ROS 2 CDR) in a temporary directory ->
`logscan.pipeline`, the same reader and pipeline as `logscan analyze`) in local processes
(`logscan.fleet.run_many`); the baseline is trained on prepared healthy runs (`logscan.training.train`).

    python bench/evaluate_detectors.py                     # 20 runs per family, 2 processes
    python bench/evaluate_detectors.py --runs 3 --json /tmp/eval.json    # a quick look
    python bench/evaluate_detectors.py --diagnose          # actuator offsets on development seeds
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from dataclasses import dataclass
from datetime import UTC, datetime

import numpy as np

DURATION_S = 60.0
START_RANGE_S = (20.0, 40.0)
GRACE_S = 1.0
RECOVERY_S = 5.0  # logscan.verdict.scoring.DEFAULT_RECOVERY_S
MARGIN = 1.0
N_TRAIN = 10

# (family label, `--fault` kind) per model; targets, magnitudes and lengths are the kinds' defaults
FAMILIES = {
    "quadcopter": [
        ("imu-bias", "imu-bias"),
        ("imu-drift", "imu-drift"),
        ("imu-random", "imu-random"),
        ("imu-bitflip", "imu-bitflip"),
        ("imu-stuck", "imu-stuck"),
        ("motor-offset", "motor-offset"),
        ("lost-motor", "lost-motor"),
        ("cov-corruption", "cov-corruption"),
        ("state-corruption", "state-corruption"),
    ],
    "steer_by_wire": [
        ("bias", "bias"),
        ("drift", "drift"),
        ("random", "random"),
        ("bitflip", "bitflip"),
        ("stuck", "stuck"),
        ("actuator-offset", "actuator-offset"),
        ("lost-actuator", "lost-actuator"),
        ("cov-corruption", "cov-corruption"),
        ("state-corruption", "state-corruption"),
    ],
}
FAULT_SEED_BASE = {"quadcopter": 1000, "steer_by_wire": 2000}
HEALTHY_SEED_BASE = {
    ("quadcopter", False): 3000,
    ("quadcopter", True): 3100,
    ("steer_by_wire", False): 3200,
    ("steer_by_wire", True): 3300,
}
TRAIN_SEED_BASE = {"quadcopter": 4000, "steer_by_wire": 4100}

METHODS = {  # key -> column title
    "A": "A: encoded e_x + rejected (adaptive)",
    "B": "B: constant CV_0, fixed threshold [15]",
    "C": "C: variance check e_v",
    "D": "D: NIS (any group / overall)",
    "E": "E: on-board state check e_s",
    "F": "F: CUSUM (any group and axis)",
    "G": "G: frozen-sensor check (any channel)",
}
SUPPLEMENTARY = {
    "A.e_x": "A's e_x alone",
    "R": "rejected-sample check alone",
    "B+R": "B + rejected-sample check",
    "D+F": "NIS or CUSUM",
    "any": "any alarm (encoded_ekf, nis, cusum or frozen)",
}


@dataclass(frozen=True)
class Job:
    model: str
    family: str  # family label, or "healthy" / "aggressive" / "train"
    fault: str | None  # `--fault` text
    seed: int
    aggressive: bool = False


def fault_start(seed: int) -> float:
    """The run's fault start time: uniform in START_RANGE_S from the run's own seed (10 ms steps)."""
    low, high = START_RANGE_S
    return round(float(np.random.default_rng([seed, 7]).uniform(low, high)), 2)


def make_jobs(runs: int) -> tuple[list[Job], list[Job]]:
    """(training jobs, evaluation jobs)."""
    train = [Job(m, "train", None, TRAIN_SEED_BASE[m] + i) for m in FAMILIES for i in range(N_TRAIN)]
    jobs = []
    for model, families in FAMILIES.items():
        for f, (label, kind) in enumerate(families):
            for r in range(runs):
                seed = FAULT_SEED_BASE[model] + 100 * f + r
                jobs.append(Job(model, label, f"{kind}::{fault_start(seed):.2f}::", seed))
        for aggressive in (False, True):
            base = HEALTHY_SEED_BASE[(model, aggressive)]
            jobs.extend(
                Job(model, "aggressive" if aggressive else "healthy", None, base + r, aggressive) for r in range(runs)
            )
    return train, jobs


def _simulate(job: Job, directory: str) -> str:
    """Simulate and write one run; returns the log's path."""
    from logscan.simulate import parse_fault, simulate, write_simulation

    faults = [parse_fault(job.fault)] if job.fault else []
    sim = simulate(job.model, faults, duration=DURATION_S, seed=job.seed, aggressive=job.aggressive)
    path = os.path.join(directory, f"{job.model}_{job.family}_{job.seed}.mcap")
    write_simulation(sim, path, "mcap-ros2")
    return path


def _analyse(job: Job, directory: str):
    """Simulate, write and analyse one run; returns the Analysis."""
    from logscan.pipeline import analyze_log

    path = _simulate(job, directory)
    try:
        return analyze_log(path, detector_names=["encoded_ekf", "nis", "cusum", "frozen"], grace_s=GRACE_S)
    finally:
        os.unlink(path)


def _baseline(settings: dict):
    from logscan.detectors.registry import default_registry

    return default_registry().create("encoded_ekf", {"variant": "baseline", "margin": MARGIN, **settings})


def train_one(job: Job) -> tuple[str, int, float]:
    """`fit` of the baseline on one prepared healthy run (no detector runs over it):
    (model, seed, margin * max |e_x|)."""
    from logscan.pipeline import load_profile_for, prepare
    from logscan.training.train import fit_detectors

    detector = _baseline({})
    with tempfile.TemporaryDirectory() as directory:
        path = _simulate(job, directory)
        prepared = prepare(path, load_profile_for(path, None), detector.needs)
    fit_detectors([detector], [prepared])
    return job.model, job.seed, float(detector.threshold_)


def evaluate_one(args: tuple[Job, dict[str, float]]):
    """Score one run under every method; returns (job, LogEvaluation or error text, the merged
    alarm spans per method (for rescoring the JSON), seconds)."""
    from logscan.results import events_from_truth
    from logscan.verdict.evaluation import LogEvaluation, merge_intervals, score_groups
    from logscan.verdict.scoring import label_observability

    job, thresholds = args
    started = time.perf_counter()
    spans: dict[str, list] = {}
    try:
        with tempfile.TemporaryDirectory() as directory:
            analysis = _analyse(job, directory)
        baseline = _baseline({})
        baseline.threshold_ = thresholds[job.model]
        base_result = baseline.run(analysis.run, analysis.trace, model=analysis.model)
        encoded = next(r for r in analysis.results if r.detector == "encoded_ekf")
        nis = next(r for r in analysis.results if r.detector == "nis")
        cusum = next(r for r in analysis.results if r.detector == "cusum")
        frozen = next(r for r in analysis.results if r.detector == "frozen")
        rejected = [a for a in encoded.alarms if a.signal.startswith("rejected.")]
        e_x = [a for a in encoded.alarms if a.signal == "e_x"]
        base_e_x = [a for a in base_result.alarms if a.signal == "e_x"]
        groups = {
            "A": e_x + rejected,
            "B": base_e_x,
            "C": [a for a in encoded.alarms if a.signal == "e_v"],
            "D": list(nis.alarms),
            "E": [a for a in encoded.alarms if a.signal == "e_s"],
            "F": list(cusum.alarms),
            "G": list(frozen.alarms),
            "A.e_x": e_x,
            "R": rejected,
            "B+R": base_e_x + rejected,
            "D+F": list(nis.alarms) + list(cusum.alarms),
            "any": list(encoded.alarms) + list(nis.alarms) + list(cusum.alarms) + list(frozen.alarms),
        }
        duration = float(analysis.run.t[-1] - analysis.run.t[0])
        transients = events_from_truth((analysis.log.truth or {}).get("transients") or [])
        spans = {key: merge_intervals(alarms) for key, alarms in groups.items()}
        scores = score_groups(
            analysis.events,
            spans,
            duration_s=duration,
            grace_s=GRACE_S,
            recovery_s=RECOVERY_S,
            transients=transients,
            log=f"{job.model}/{job.family}/{job.seed}",
        )
        # faults wholly where they could not be seen are labelled (logscan.verdict.observability), not excused
        seen = analysis.observability
        verdicts = [seen.event_verdict(e) if seen is not None else None for e in analysis.events]
        for score in scores.values():
            label_observability(score, verdicts)
        result = LogEvaluation(
            f"{job.model}/{job.family}/{job.seed}",
            job.model,
            duration,
            list(analysis.events),
            scores,
            aggressive=job.aggressive,
            transients=transients,
        )
    except Exception as exc:  # noqa: BLE001 - a failed run is reported in the tables, not fatal
        result = f"{type(exc).__name__}: {exc}"
    return job, result, spans, time.perf_counter() - started


# --- tables -----------------------------------------------------------------------------------


def _latency(score) -> str:
    if score.mean_latency_s is None:
        return ""
    return f" · {score.mean_latency_s:.2f} / {score.max_latency_s:.2f} s"


CATEGORIES = (  # the paper's Table III rows, mapped onto the simulator's fault kinds
    ("sensor faults", ("bias", "drift", "random", "bitflip", "stuck")),
    ("actuator faults", ("actuator-offset", "lost-actuator")),
    ("estimator faults", ("cov-corruption", "state-corruption")),
)


def category_table(results: list, methods: dict[str, str]) -> str:
    """The paper's Table III rows: detection accuracy and mean latency per fault category, per
    model, pooled over the families of the category (events detected / events)."""
    from logscan.verdict.scoring import aggregate

    out = ["| model: fault category | " + " | ".join(methods.values()) + " |", "|---|" + "---|" * len(methods)]
    for model in FAMILIES:
        for category, kinds in CATEGORIES:
            chosen = [
                ev
                for job, ev in results
                if job.model == model and not isinstance(ev, str) and ev.events and ev.events[0].kind in kinds
            ]
            if not chosen:
                continue
            cells = []
            for key in methods:
                score = aggregate([ev.scores[key] for ev in chosen])
                rate = 100.0 * score.tp / score.n_events
                onset = f"; {score.at_onset} at onset" if score.at_onset else ""
                latency = "" if score.mean_latency_s is None else f" · {score.mean_latency_s:.2f} s"
                cells.append(f"{rate:.1f} % ({score.tp}/{score.n_events}{onset}){latency}")
            out.append(f"| {model}: {category} | " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


def detected_while_active(scores) -> int:
    """Events whose first alarm came before the fault ended (latency < t_end - t_start); the
    others were detected in the grace period, i.e. by the fault's removal."""
    return sum(
        1
        for score in scores
        for match in score.matches
        if match.detected and (match.event.t_end is None or match.latency_s < match.event.t_end - match.event.t_start)
    )


def family_cell(scores) -> str:
    """detected / runs (detections after the fault ended; runs with an alarm already on at the
    onset; faults wholly where they could not be seen, the misses among them, and the detection
    rate of the others) · mean / max latency."""
    from logscan.verdict.scoring import aggregate

    score = aggregate(scores)
    late = score.tp - detected_while_active(scores)
    notes = []
    if late:
        notes.append(f"{late} only after the fault ended")
    if score.at_onset:
        notes.append(f"{score.at_onset} at onset")
    if score.unobservable:  # docs/algorithms.md section 10
        seen = score.n_events - score.unobservable
        notes.append(
            f"{score.unobservable} unobservable, {score.fn_unobservable} of them missed; "
            f"{score.tp - (score.unobservable - score.fn_unobservable)}/{seen} observable detected"
        )
    note = f" ({', '.join(notes)})" if notes else ""
    return f"{score.tp}/{score.n_events}{note}{_latency(score)}"


def _fa_per_hour(scores) -> str:
    from logscan.verdict.scoring import aggregate

    total = aggregate(scores)
    rate = total.false_alarms_per_hour_healthy
    return "-" if rate is None else f"{rate:.1f} ({total.healthy_fp})"


def family_tables(results: list, methods: dict[str, str], runs: int) -> str:
    """Per model: one row per fault family, one column per method (Table III layout)."""
    from logscan.verdict.scoring import aggregate

    out = []
    for model, families in FAMILIES.items():
        mine = [(job, ev) for job, ev in results if job.model == model and not isinstance(ev, str)]
        out.append(f"#### {model}\n")
        out.append("| fault family (target, magnitude, length) | " + " | ".join(methods.values()) + " |")
        out.append("|---|" + "---|" * len(methods))
        for label, kind in families:
            runs_here = [ev for job, ev in mine if job.family == label]
            if not runs_here:
                continue
            event = runs_here[0].events[0]
            length = (event.t_end - event.t_start) if event.t_end is not None else float("nan")
            cells = [family_cell([ev.scores[key] for ev in runs_here]) for key in methods]
            out.append(
                f"| {label} ({event.target}, {default_magnitude(kind)}, {length:g} s) | " + " | ".join(cells) + " |"
            )
        for family, title in (
            ("healthy", "false alarms / h, healthy"),
            ("aggressive", "false alarms / h, aggressive manoeuvres"),
        ):
            runs_here = [ev for job, ev in mine if job.family == family]
            cells = [_fa_per_hour([ev.scores[key] for ev in runs_here]) for key in methods]
            out.append(f"| {title} ({len(runs_here)} x {DURATION_S:g} s) | " + " | ".join(cells) + " |")
        faulty = [ev for job, ev in mine if job.family not in ("healthy", "aggressive")]
        totals = [aggregate([ev.scores[key] for ev in faulty]) for key in methods]
        n = len(faulty)
        out.append(f"| false alarms on the {n} fault runs | " + " | ".join(str(t.fp) for t in totals) + " |")
        out.append(
            f"| recovery alarms on the {n} fault runs (start within {RECOVERY_S:g} s after a detected fault's "
            f"grace period) | " + " | ".join(str(t.recovery_alarms) for t in totals) + " |"
        )
        if any(ev.transients for _, ev in mine):
            every = [aggregate([ev.scores[key] for _, ev in mine]) for key in methods]
            out.append("| alarms on healthy transients | " + " | ".join(str(t.transient_alarms) for t in every) + " |")
        out.append("")
    return "\n".join(out)


def default_magnitude(kind: str) -> str:
    """The magnitude the simulator gives a fault kind or alias by default (unit per kind)."""
    from logscan.simulate.faults import ALIASES, KIND_DEFAULTS

    return f"{ALIASES[kind][2] if kind in ALIASES else KIND_DEFAULTS[kind][0]:g}"


# --- diagnosis on development seeds (< 1000; never the evaluation seeds) ------------------------

DEV_FAULT_SEEDS = range(500, 508)
DEV_HEALTHY_SEEDS = range(600, 608)
DEV_AGGRESSIVE_SEEDS = range(700, 708)
DEV_RHOS = (2.0, 2.5, 3.0, 3.5, 4.0)


def diagnose_actuator_offsets() -> str:
    """Why A misses actuator offsets: the step of e_x at the fault onset in units of its healthy
    spread, and (for information, not tuning) detections vs. false alarms of A over rho."""
    from logscan.verdict.evaluation import merge_intervals, score_groups

    lines = [
        "| model, fault (start 30 s) | e_x step at onset / healthy std (8 dev runs) | "
        + " | ".join(f"rho {rho:g}: detected, false alarms" for rho in DEV_RHOS)
        + " |",
        "|---|---|" + "---|" * len(DEV_RHOS),
    ]
    for model, kind in (("quadcopter", "motor-offset"), ("steer_by_wire", "actuator-offset")):
        with tempfile.TemporaryDirectory() as directory:
            faulty = [_analyse(Job(model, kind, f"{kind}::30::", s), directory) for s in DEV_FAULT_SEEDS]
            healthy = [_analyse(Job(model, "healthy", None, s), directory) for s in DEV_HEALTHY_SEEDS]
            healthy += [_analyse(Job(model, "aggressive", None, s, True), directory) for s in DEV_AGGRESSIVE_SEEDS]
        steps = []
        for analysis in faulty:
            e_x = next(r for r in analysis.results if r.detector == "encoded_ekf").series["e_x"]
            k = int(np.searchsorted(analysis.run.t, 30.0))
            before, after = e_x[k - 500 : k], e_x[k : k + 50]  # 5 s before, 0.5 s after the onset
            before, after = before[np.isfinite(before)], after[np.isfinite(after)]
            steps.append((after.mean() - before.mean()) / before.std())
        cells = []
        for rho in DEV_RHOS:
            detector = _adaptive(rho)
            detected = false_alarms = 0
            for analysis in faulty + healthy:
                result = detector.run(analysis.run, analysis.trace, model=analysis.model)
                alarms = [a for a in result.alarms if a.signal == "e_x" or a.signal.startswith("rejected.")]
                if analysis.events:
                    detected += score_groups(analysis.events, {"A": alarms}, duration_s=DURATION_S)["A"].tp
                else:
                    false_alarms += len(merge_intervals(alarms))
            cells.append(f"{detected}/{len(faulty)}, {false_alarms}")
        lines.append(
            f"| {model}, {kind} | {np.mean(steps):+.2f} (range {min(steps):+.2f} .. {max(steps):+.2f}) | "
            + " | ".join(cells)
            + " |"
        )
    return (
        f"Development seeds: faults {DEV_FAULT_SEEDS.start}..{DEV_FAULT_SEEDS.stop - 1}, healthy "
        f"{DEV_HEALTHY_SEEDS.start}..{DEV_HEALTHY_SEEDS.stop - 1}, aggressive "
        f"{DEV_AGGRESSIVE_SEEDS.start}..{DEV_AGGRESSIVE_SEEDS.stop - 1} ({len(DEV_HEALTHY_SEEDS) * 2} healthy "
        "minutes); false alarms counted on the healthy and aggressive runs.\n\n" + "\n".join(lines)
    )


def _adaptive(rho: float):
    from logscan.detectors.registry import default_registry

    return default_registry().create("encoded_ekf", {"rho": rho})


def code_version() -> str:
    """The commit the numbers were measured at, and whether the code under test had local edits."""
    import subprocess

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--", "logscan", "detectors"],
            cwd=root,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "an unknown commit (no git checkout)"
    return f"commit {head}" + (" with local edits under logscan/ or detectors/" if dirty else "")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20, help="runs per family and per healthy set")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes")
    parser.add_argument("--json", dest="json_path", default=None, help="write the raw scores here")
    parser.add_argument(
        "--diagnose", action="store_true", help="only the actuator-offset diagnosis on development seeds (< 1000)"
    )
    args = parser.parse_args(argv)
    if args.diagnose:
        started = time.perf_counter()
        print(diagnose_actuator_offsets())
        print(f"\n({time.perf_counter() - started:.0f} s)")
        return 0

    import logscan
    from logscan.fleet import run_many

    started = time.perf_counter()
    train_jobs, jobs = make_jobs(args.runs)
    fits = run_many(train_jobs, train_one, jobs=args.jobs, isolate=False)
    thresholds = {m: max(th for model, _, th in fits if model == m) for m in FAMILIES}
    results = []
    spans = {}
    for job, result, run_spans, _seconds in run_many(
        [(job, thresholds) for job in jobs], evaluate_one, jobs=args.jobs, isolate=False
    ):
        results.append((job, result))
        spans[job] = run_spans
        if isinstance(result, str):
            print(f"run {job.model}/{job.family}/{job.seed} failed: {result}", file=sys.stderr)
    elapsed = time.perf_counter() - started
    failed = [(job, r) for job, r in results if isinstance(r, str)]

    lines = [
        f"Measured {datetime.now(UTC):%Y-%m-%d %H:%M} UTC with logscan {logscan.__version__} "
        f"({code_version()}), "
        f"`python bench/evaluate_detectors.py --runs {args.runs} --jobs {args.jobs}`: "
        f"{len(jobs)} evaluation runs + {len(train_jobs)} training runs in {elapsed:.0f} s "
        f"({os.cpu_count()} CPUs, {platform.processor() or platform.machine()}, Python {platform.python_version()}); "
        f"{len(failed)} run(s) failed.",
        "",
        "Baseline thresholds (max |e_x| over the training runs x margin "
        f"{MARGIN:g}): " + ", ".join(f"{m} {th:.4g}" for m, th in thresholds.items()) + ".",
        "",
        'Cells: detected / runs · mean / max latency (s); "only after the fault ended": detections '
        f"by an alarm that started in the {GRACE_S:g} s grace period after the fault's end (the fault's "
        'removal was seen, not the fault); "at onset": runs where an alarm of the method was already on '
        "when the fault began (not a detection: such a run counts as detected only if a later alarm "
        "started within [onset, end + grace]). False-alarm rows: alarms per hour (count); recovery "
        f"alarms (starting within {RECOVERY_S:g} s after a detected fault's grace period) are counted "
        "apart, not as false alarms.",
        "",
        "### Per fault category (the paper's Table III rows: detection accuracy · mean latency)",
        "",
        category_table(results, METHODS),
        "### Main comparison, per fault family",
        "",
        family_tables(results, METHODS, args.runs),
        "### Supplementary",
        "",
        family_tables(results, SUPPLEMENTARY, args.runs),
    ]
    if failed:
        lines += ["Failed runs:", ""] + [f"- {j.model}/{j.family}/{j.seed}: {r}" for j, r in failed] + [""]
    print("\n".join(lines))

    if args.json_path:
        from logscan.artifacts import write_json

        write_json(
            args.json_path,
            {
                "elapsed_s": elapsed,
                "grace_s": GRACE_S,
                "recovery_s": RECOVERY_S,
                "thresholds": thresholds,
                "training": [{"model": m, "seed": s, "threshold": th} for m, s, th in fits],
                "runs": [
                    {
                        "model": job.model,
                        "family": job.family,
                        "seed": job.seed,
                        "fault": job.fault,
                        "aggressive": job.aggressive,
                        "error": result if isinstance(result, str) else None,
                        "spans": spans.get(job, {}),
                        "events": [] if isinstance(result, str) else [e.to_dict() for e in result.events],
                        "scores": {}
                        if isinstance(result, str)
                        else {
                            k: {key: v for key, v in s.to_dict().items() if key != "log"}
                            for k, s in result.scores.items()
                        },
                    }
                    for job, result in results
                ],
            },
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
