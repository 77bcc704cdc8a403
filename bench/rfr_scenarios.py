"""Checkpointing and roll-forward recovery (RFR) on the paper's ground robot over unseen seeds:
the recovered x-position error during the anomalies against the shared EKF's, and the bound's
coverage.

The scenario is the checkpointing paper's (`logscan simulate ground_robot --scenario paper`, 15 s):
+[5, 5, 0] on the mocap and +20000 rad/s on both encoders over 3.25-5 s, the negatives over
8.25-10 s. Each log is analysed with its embedded profile plus a [recovery] table per variant:

 - oracle: the anomalies are the ground truth's, first alarmed `detection_time_s` = 0.25 s after
   each start (the paper's detection time), with the attacked groups as targets;
 - a real detector (`nis`, `encoded_ekf`): its alarms on every loop drive recovery (its own
   detection time, so the profile's default detection_time_s; each alarm shows its anomaly until
   its end minus the statistic's declared end delay, `Detector.end_delays`);

each with the methods `rollforward` (the paper's: no measurement while the anomaly lasts) and
`refilter` (the default: the flagged groups excluded, the healthy ones still used).

Measured against the true states the simulator logs (/truth/state, /truth/motors, held onto each
loop's grid: their stamps are the grid's), over the anomaly windows of the truth (the union of
the events' [start, end) intervals on the outer, 10 Hz grid):
 - RMS of the x error of the shared EKF (outer loop `x_post`) and of each variant (inside an
   anomaly window where recovery gave nothing the EKF's value counts, and "covered" is the
   fraction of anomaly samples that recovery did give);
 - bound coverage: the fraction of recovered samples (every loop and state with a finite bound)
   where |truth - x_recovered| <= bound (k-sigma of the recovery's covariance), with the median
   k-sigma and worst-case (Proposition 5.1) bounds of the outer x beside it;
 - mean roll-forward length (recovered end - checkpoint), anomalies kept past the detector's alarm,
   and anomalies that outlasted T_max (allowed error --allowed-error m on the outer x and y).

After the attacks (a second table): the grid steps after the first attack's end that lie in no
attack ([5, 8.25) and [10, 15) s), where a user reads the recovered estimate inside its spans and
the shared EKF's elsewhere, against the shared EKF alone; with the seconds per seed that recovery
ran past the attacks and the anomalies whose recovery ended because the recovered estimate did
not re-agree with a sensor that no longer showed the anomaly (docs/algorithms.md 5.4).

The figures pool every seed's samples (one RMS over all anomaly samples of all seeds). Beside
each RMS, a 95 % bootstrap interval over the seeds: 2000 resamples of the seeds with replacement
(a fixed RNG seed, the same resamples for every row), each pooling its seeds' squared errors as
the RMS does; the 2.5 and 97.5 percentiles of the resampled RMS. And the seeds' own RMS: median,
90th percentile and largest (a pooled RMS follows the few seeds that drift most).

--plant-without-noise: the same seeds simulated with the plant's process noise off
(`simulate_ground_robot(..., process_noise=False)`: the same attacks, the same sensor noise, the
sensors keep theirs), to separate the recovery's own error from the plant's random walk, which no
roll-forward can know (Q_o = 0.1^2 per 0.1 s outer step on x, y and theta).

Seeds 101.. (the sample logs use 16 and 17, the tests 0-9 and 101).

    python bench/rfr_scenarios.py                    # 100 seeds (about 3 min on one core)
    python bench/rfr_scenarios.py --seeds 3          # a quick look
    python bench/rfr_scenarios.py --write-docs       # also rewrite the table in docs/evaluation.md
    python bench/rfr_scenarios.py --plant-without-noise --detectors oracle --no-diagnostic
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from dataclasses import dataclass

import numpy as np
from benchlib import publish, simulate_log  # bench/ is on the path when this script runs

FIRST_SEED = 101
DETECTION_TIME_S = 0.25  # the paper's detection time (the oracle's delay after each truth start)
ORACLE = "oracle"  # [recovery] detector = "oracle": anomalies from the ground truth
DETECTORS = (ORACLE, "nis", "encoded_ekf")
METHODS = ("rollforward", "refilter")
PRIMARY = "outer"  # the simulated robot's primary loop ([vehicle] loop)
ANGLES = ("theta",)  # states whose error is wrapped to [-pi, pi) (the unicycle's heading is not wrapped)
BOUND_STATES = ("x", "y")  # the outer states whose T_max is computed (allowed error --allowed-error)
DOC = os.path.join(os.path.dirname(__file__), "..", "docs", "evaluation.md")
MARKERS = ("<!-- rfr-scenarios:begin -->", "<!-- rfr-scenarios:end -->")
# the prototype of docs/algorithms.md section 5: x RMS error during the attacks (m)
PROTOTYPE = {"ekf": 4.98, (ORACLE, "rollforward"): 1.01, (ORACLE, "refilter"): 0.36, ("nis", "rollforward"): 1.01}
BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 20240  # fixed: the interval is reproducible (and the resamples are the same for every row)


@dataclass(frozen=True)
class Variant:
    detector: str
    method: str
    shifted: bool = False  # the input-timing contrast (`shifted_recovery`)

    @property
    def label(self) -> str:
        early = ', inputs one step early (contrast: without [inputs] stamp = "start")'
        return f"{self.detector} / {self.method}" + (early if self.shifted else "")


def variants(detectors=DETECTORS, methods=METHODS, diagnose: bool = True) -> list[Variant]:
    """Every detector x method; with ``diagnose``, the oracle's again with the inputs shifted."""
    chosen = [Variant(d, m) for d in detectors for m in methods]
    return chosen + ([Variant(ORACLE, m, True) for m in methods] if diagnose else [])


def simulate(path: str, seed: int, process_noise: bool = True) -> str:
    """The paper's scenario with ``seed`` (`logscan simulate ground_robot --scenario paper`).
    ``process_noise`` False: the plant without its process noise, through the CLI's own functions
    (`simulate_ground_robot` and `write_simulation`, the CLI's default duration and MCAP format)."""
    if process_noise:
        return simulate_log("ground_robot", path, "--scenario", "paper", "--seed", str(seed))
    from logscan.simulate import write_simulation
    from logscan.simulate.ground_robot_sim import PAPER_DURATION_S, simulate_ground_robot

    sim = simulate_ground_robot("paper", duration=PAPER_DURATION_S, seed=seed, process_noise=False)
    write_simulation(sim, path)
    return path


def profile_text(log_path: str, variant: Variant, allowed_error_m: float) -> str:
    """The log's embedded profile with a [recovery] table for ``variant``."""
    from dataclasses import replace

    from logscan.pipeline import load_profile_for

    profile = load_profile_for(log_path, None).profile
    base = replace(profile, recovery=None).to_toml()  # the log's own [recovery] replaced
    lines = ["", "[recovery]", f'detector = "{variant.detector}"', f'method = "{variant.method}"']
    if variant.detector == ORACLE:
        lines.append(f"detection_time_s = {DETECTION_TIME_S}")
    errors = ", ".join(f'"{PRIMARY}.{s}" = {allowed_error_m}' for s in BOUND_STATES)
    lines.append(f"allowed_error = {{ {errors} }}")
    return base + "\n".join(lines) + "\n"


def true_states(path: str, truth: dict, loop: str, start_ns: int, t: np.ndarray) -> np.ndarray:
    """(N, n) true states of ``loop`` held onto its grid ``t`` (seconds since ``start_ns``)."""
    from logscan.readers import read_log

    channels = truth["loops"][loop]["true_state_channels"]
    log = read_log(path, channels)
    columns = []
    for name in channels:
        ch = log.channel(name)
        ts = (ch.t - start_ns) / 1e9
        # the simulator stamps the true state of step k at t_k, the grid's own times
        i = np.clip(np.searchsorted(ts, t + 1e-6, side="right") - 1, 0, ts.size - 1)
        if np.max(np.abs(ts[i] - t)) > 1e-6:
            raise RuntimeError(f"{name}: truth stamps are off {loop}'s grid by {np.max(np.abs(ts[i] - t)):.3g} s")
        columns.append(ch.values[i])
    return np.column_stack(columns)


def anomaly_mask(events, t: np.ndarray) -> np.ndarray:
    """(N,) bool: grid steps inside any truth event's [start, end)."""
    mask = np.zeros(t.size, dtype=bool)
    for event in events:
        mask |= (t >= event.t_start) & (t < event.end_or_inf)
    return mask


def post_attack_mask(events, t: np.ndarray, during: np.ndarray) -> np.ndarray:
    """(N,) bool: grid steps after the first attack's end that lie in no attack (the paper's
    scenario: [5, 8.25) and [10, 15) s, to the end of the log)."""
    ends = [event.t_end for event in events if event.t_end is not None]
    if not ends:
        return np.zeros(t.size, dtype=bool)
    return ~during & (t >= min(ends))


def state_error(names, estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """estimate - truth, angles wrapped to [-pi, pi)."""
    error = estimate - truth
    for j, name in enumerate(names):
        if name in ANGLES:
            error[:, j] = (error[:, j] + np.pi) % (2 * np.pi) - np.pi
    return error


def measure_variant(path: str, profile: str, truths: dict | None = None, shifted: bool = False) -> dict:
    """One analysis with ``profile``'s [recovery]: sums for the pooled figures (see the module's
    docstring). ``truths``: loop -> true states on its grid, read once per log (filled here).
    ``shifted``: the diagnostic instead (`shifted_recovery`)."""
    from logscan.pipeline import analyze_log

    analysis = analyze_log(path, profile)
    recovery, prepared = analysis.recovery, analysis.prepared
    if recovery is None:
        raise RuntimeError(f"{path}: no recovery ({'; '.join(analysis.warnings)})")
    truths = {} if truths is None else truths
    for name, loop in recovery.loops.items():
        if name not in truths:
            truths[name] = true_states(path, prepared.log.truth, name, prepared.run.start_ns, loop.t)
    ekf_x_post = prepared.trace.x_post
    if shifted:
        recovery, ekf_x_post = shifted_recovery(analysis)
    return figures(recovery, ekf_x_post, analysis.events, truths)


def shifted_recovery(analysis):
    """CONTRAST, not the pipeline: the same recovery with every loop's inputs one step early
    (u[k] := u[k+1]) and the shared EKF re-run on them: what a profile without `[inputs] stamp =
    "start"` gives. The simulator applies the input it logs at t_k over [t_k, t_k+1); held at step k,
    the EKF would read it as the input of the step that ENDS at t_k. Returns (Recovery, outer x_post)."""
    from dataclasses import replace

    from logscan.filters.ekf import run_ekf
    from logscan.pipeline.loops import loop_runs
    from logscan.recovery import LoopRun, RecoverySettings, anomalies_from_truth, recover

    loops = []
    for loop in loop_runs(analysis.prepared):
        u = np.asarray(loop.run.u)
        run = replace(loop.run, u=np.vstack([u[1:], u[-1:]]))
        loops.append(LoopRun(loop.name, loop.model, run, run_ekf(loop.model, run, full_P=True)))
    settings = RecoverySettings(**analysis.profile.recovery.settings)
    anomalies = anomalies_from_truth(analysis.events, settings.detection_time_s, loops)
    return recover(loops, anomalies, settings), loops[0].trace.x_post


def figures(recovery, ekf_x_post: np.ndarray, events, truths: dict) -> dict:
    """One log's sums for the pooled figures, against ``truths`` (loop -> true states)."""
    outer = recovery.loops[PRIMARY]
    mask = anomaly_mask(events, outer.t)
    ix = outer.state_names.index("x")
    ekf_x = ekf_x_post[:, ix]
    rec_x = outer.x_recovered[:, ix]
    covered = mask & np.isfinite(rec_x)
    filled = np.where(np.isfinite(rec_x), rec_x, ekf_x)  # the recovered estimate, the EKF's outside its spans
    truth_x = truths[PRIMARY][:, ix]
    post = post_attack_mask(events, outer.t, mask)
    inside = within = 0
    for name, loop in recovery.loops.items():
        error = state_error(loop.state_names, loop.x_recovered, truths[name])
        judged = np.isfinite(error) & np.isfinite(loop.bound)
        inside += int(judged.sum())
        within += int((np.abs(error[judged]) <= loop.bound[judged]).sum())
    judged_x = np.isfinite(rec_x) & np.isfinite(outer.bound[:, ix])
    worst_x = outer.worst_case[judged_x, ix]
    records = recovery.anomalies
    return {
        "n": int(mask.sum()),
        "covered": int(covered.sum()),
        "ekf_sq": float(np.sum((ekf_x[mask] - truth_x[mask]) ** 2)),
        "rec_sq": float(np.sum((filled[mask] - truth_x[mask]) ** 2)),
        "post_n": int(post.sum()),
        "post_ekf_sq": float(np.sum((ekf_x[post] - truth_x[post]) ** 2)),
        "post_rec_sq": float(np.sum((filled[post] - truth_x[post]) ** 2)),
        "post_recovered_s": float(np.sum(post & np.isfinite(rec_x)) * np.median(np.diff(outer.t))),
        "not_reagreed": sum(r.end_reason.startswith("did not re-agree") for r in records),
        "bound_judged": inside,
        "bound_within": within,
        "bound_x": outer.bound[judged_x, ix].tolist(),
        "worst_x": worst_x[np.isfinite(worst_x)].tolist(),
        "rollforward_s": [r.rollforward_s for r in records if r.rollforward_s is not None],
        "anomalies": len(records),
        "kept": sum(r.alarm_kept for r in records),
        "outlasted": sum(bool(r.outlasted) for r in records),
    }


@dataclass(frozen=True)
class SeedTask:
    """Simulate one seed and measure every variant on it."""

    root: str
    variants: tuple[Variant, ...]
    allowed_error_m: float = 1.0
    process_noise: bool = True

    def __call__(self, seed: int) -> dict:
        path = simulate(os.path.join(self.root, f"robot-{seed}.mcap"), seed, self.process_noise)
        truths: dict = {}
        out = {}
        for variant in self.variants:
            profile = os.path.join(self.root, f"robot-{seed}-{variant.detector}-{variant.method}.toml")
            with open(profile, "w", encoding="utf-8") as fh:
                fh.write(profile_text(path, variant, self.allowed_error_m))
            out[variant.label] = measure_variant(path, profile, truths, variant.shifted)
            os.unlink(profile)
        os.unlink(path)
        return out


def bootstrap_rms(sq, n, resamples: int = BOOTSTRAP_RESAMPLES, seed: int = BOOTSTRAP_SEED) -> tuple[float, float]:
    """95 % percentile interval of the pooled RMS sqrt(sum sq / sum n) with the seeds resampled
    with replacement (``sq``, ``n``: each seed's sum of squared errors and its sample count)."""
    sq, n = np.asarray(sq, dtype=float), np.asarray(n, dtype=float)
    pick = np.random.default_rng(seed).integers(0, sq.size, size=(resamples, sq.size))
    rms = np.sqrt(sq[pick].sum(axis=1) / n[pick].sum(axis=1))
    low, high = np.percentile(rms, [2.5, 97.5])
    return float(low), float(high)


def per_seed(sq, n) -> dict:
    """Median, 90th percentile and largest of the seeds' own RMS (``sq``, ``n``: each seed's sum of
    squared errors and its sample count): what a pooled RMS hides."""
    rms = np.sqrt(np.asarray(sq, dtype=float) / np.maximum(np.asarray(n, dtype=float), 1))
    return {"median": float(np.median(rms)), "p90": float(np.percentile(rms, 90)), "max": float(np.max(rms))}


def pooled(results: list[dict], label: str) -> dict:
    """The figures of one variant pooled over every seed's samples."""
    rows = [r[label] for r in results]
    n = sum(r["n"] for r in rows)
    counts = [r["n"] for r in rows]
    post_counts = [r["post_n"] for r in rows]
    post_n = max(sum(post_counts), 1)
    bound_x = np.concatenate([r["bound_x"] for r in rows])
    worst_x = np.concatenate([r["worst_x"] for r in rows])
    lengths = [s for r in rows for s in r["rollforward_s"]]
    judged = sum(r["bound_judged"] for r in rows)
    column = lambda key: [r[key] for r in rows]  # noqa: E731
    return {
        "ekf": np.sqrt(sum(column("ekf_sq")) / n),
        "rec": np.sqrt(sum(column("rec_sq")) / n),
        "ekf_interval": bootstrap_rms(column("ekf_sq"), counts),
        "rec_interval": bootstrap_rms(column("rec_sq"), counts),
        "ekf_seeds": per_seed(column("ekf_sq"), counts),
        "rec_seeds": per_seed(column("rec_sq"), counts),
        "post_ekf": np.sqrt(sum(column("post_ekf_sq")) / post_n),
        "post_rec": np.sqrt(sum(column("post_rec_sq")) / post_n),
        "post_ekf_interval": bootstrap_rms(column("post_ekf_sq"), post_counts),
        "post_rec_interval": bootstrap_rms(column("post_rec_sq"), post_counts),
        "post_ekf_seeds": per_seed(column("post_ekf_sq"), post_counts),
        "post_rec_seeds": per_seed(column("post_rec_sq"), post_counts),
        "post_recovered_s": (float(np.mean(column("post_recovered_s"))), float(np.max(column("post_recovered_s")))),
        "not_reagreed": sum(column("not_reagreed")),
        "covered": sum(column("covered")) / n,
        "coverage": sum(column("bound_within")) / judged if judged else float("nan"),
        "bound_x": float(np.median(bound_x)) if bound_x.size else float("nan"),
        "worst_x": float(np.median(worst_x)) if worst_x.size else float("nan"),
        "rollforward_s": float(np.mean(lengths)) if lengths else float("nan"),
        "anomalies": sum(column("anomalies")),
        "kept": sum(column("kept")),
        "outlasted": sum(column("outlasted")),
    }


def _seeds(f: dict) -> str:
    return f"{f['median']:.2f} / {f['p90']:.2f} / {f['max']:.2f}"


def table(results: list[dict], chosen: list[Variant], process_noise: bool = True) -> list[str]:
    """The attack windows' table, then the post-attack table."""
    seeds = len(results)
    figures = {v.label: pooled(results, v.label) for v in chosen}
    first = next(iter(figures.values()))
    ekf, ekf_low, ekf_high = first["ekf"], *first["ekf_interval"]
    plant = "" if process_noise else ", plant without process noise"
    lines = [
        f"| x error during the anomalies ({seeds} seeds{plant}) | RMS pooled (m) | 95 % interval (seeds resampled) "
        "| per seed median / p90 / max (m) | prototype (m) | covered "
        "| bound coverage | median bound x (m) | median worst case x (m) | mean roll-forward (s) "
        "| anomalies: kept / outlasted T_max |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        f"| shared EKF (no recovery) | {ekf:.2f} | {ekf_low:.2f}-{ekf_high:.2f} | {_seeds(first['ekf_seeds'])} "
        f"| {PROTOTYPE['ekf']:.2f} | | | | | | |",
    ]
    for v in chosen:
        f = figures[v.label]
        proto = PROTOTYPE.get((v.detector, v.method))
        low, high = f["rec_interval"]
        lines.append(
            f"| {v.label} | {f['rec']:.2f} | {low:.2f}-{high:.2f} | {_seeds(f['rec_seeds'])} "
            f"| {'-' if proto is None else f'{proto:.2f}'} | {f['covered']:.1%} | {f['coverage']:.1%} "
            f"| {f['bound_x']:.2f} | {f['worst_x']:.3g} | {f['rollforward_s']:.2f} "
            f"| {f['anomalies']}: {f['kept']} / {f['outlasted']} |"
        )
    return lines + [""] + post_table(figures, seeds, plant)


def post_table(figures: dict, seeds: int, plant: str) -> list[str]:
    """After the attacks: the estimate a user reads (the recovered one inside its spans, the shared
    EKF's elsewhere) against the shared EKF alone."""
    first = next(iter(figures.values()))
    low, high = first["post_ekf_interval"]
    lines = [
        f"| x error after the attacks ({seeds} seeds{plant}) | RMS pooled (m) | 95 % interval (seeds resampled) "
        "| per seed median / p90 / max (m) | recovered past the attacks, s per seed: mean / max "
        "| anomalies ended: did not re-agree |",
        "|---|---:|---:|---:|---:|---:|",
        f"| shared EKF (no recovery) | {first['post_ekf']:.2f} | {low:.2f}-{high:.2f} "
        f"| {_seeds(first['post_ekf_seeds'])} | | |",
    ]
    for label, f in figures.items():
        low, high = f["post_rec_interval"]
        mean_s, max_s = f["post_recovered_s"]
        lines.append(
            f"| {label} | {f['post_rec']:.2f} | {low:.2f}-{high:.2f} | {_seeds(f['post_rec_seeds'])} "
            f"| {mean_s:.2f} / {max_s:.2f} | {f['not_reagreed']} of {f['anomalies']} |"
        )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=100, help="unseen seeds from --first-seed")
    parser.add_argument("--first-seed", type=int, default=FIRST_SEED)
    parser.add_argument("--detectors", default=",".join(DETECTORS), help="comma-separated, 'oracle' for the truth")
    parser.add_argument("--allowed-error", type=float, default=1.0, help="allowed error E (m) of the outer x and y")
    parser.add_argument("--no-diagnostic", action="store_true", help="skip the input-timing contrast rows")
    parser.add_argument(
        "--plant-without-noise",
        action="store_true",
        help="simulate the seeds without the plant's process noise (the sensors keep theirs): the recovery's "
        "own error apart from the plant's random walk; not with --write-docs",
    )
    parser.add_argument("--write-docs", action="store_true", help="rewrite the table in docs/evaluation.md")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("-q", "--quiet", action="store_true")
    args = parser.parse_args()
    if args.plant_without_noise and args.write_docs:
        parser.error("--plant-without-noise is a contrast: the documented table is the noisy plant's")
    from logscan.fleet import LogFailure, run_many

    started = time.time()
    chosen = variants(tuple(d.strip() for d in args.detectors.split(",") if d.strip()), diagnose=not args.no_diagnostic)
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    with tempfile.TemporaryDirectory(prefix="rfr-") as root:
        task = SeedTask(root, tuple(chosen), args.allowed_error, not args.plant_without_noise)
        results = run_many(seeds, task, jobs=args.jobs, progress=not args.quiet, label="seeds", isolate=True)
    broken = [r for r in results if isinstance(r, LogFailure)]
    if broken:
        raise SystemExit(f"{len(broken)} seed(s) failed, first: {broken[0].message}")
    lines = table(results, chosen, not args.plant_without_noise)
    minutes = (time.time() - started) / 60
    command = f"python bench/rfr_scenarios.py --seeds {args.seeds} --first-seed {args.first_seed}"
    if args.detectors != ",".join(DETECTORS):
        command += f" --detectors {args.detectors}"
    for flag in ("no_diagnostic", "plant_without_noise"):
        if getattr(args, flag):
            command += " --" + flag.replace("_", "-")
    lines += ["", f"(`{command}`, seeds {seeds[0]}-{seeds[-1]}, {minutes:.1f} min.)"]
    publish("\n".join(lines), args.write_docs, DOC, *MARKERS)


if __name__ == "__main__":
    main()
