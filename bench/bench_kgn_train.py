"""KGN training time per log-hour: the fit (windows, bins, rho, envelope, blindness probe) on a
simulated quadcopter log, with the pipeline's EKF for the probe (issue 29: "the probe re-filters
the whole faulty run to read one window").

Simulates one quadcopter log of HOURS hours (`logscan simulate quadcopter --duration ... --seed
6200`: hover and figure-eight cycles, 100 Hz), prepares it once (read, align, the EKF with its gain:
not timed, as in `logscan train` the analysis pass is shared by every detector), then times KGN's
`fit` alone, best of 3 in one run, and the probe's share of it (fit minus a fit without the model,
which skips the probe). The before/after ratio in bench/README.md runs this same script on both
commits.

    python bench/bench_kgn_train.py             # 0.5 h log
    python bench/bench_kgn_train.py --hours 1
"""

from __future__ import annotations

import argparse
import os
import subprocess
import tempfile


def main() -> None:
    from benchlib import best_of, simulate_log

    from logscan.pipeline import create_detectors, load_profile_for, needs_of, prepare
    from logscan.pipeline.stages import fit_context

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--hours", type=float, default=0.5)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-kgn-") as root:
        log = os.path.join(root, "quad.mcap")
        simulate_log("quadcopter", log, "--duration", f"{args.hours * 3600:g}", "--seed", "6200")
        profile = os.path.join(root, "kgn.toml")
        with open(profile, "w", encoding="utf-8") as fh:
            fh.write(load_profile_for(log, None).profile.to_toml() + "\n[detectors.kgn]\n")
        loaded = load_profile_for(log, profile)
        (detector,) = create_detectors(loaded, ["kgn"])
        prepared = prepare(log, loaded, needs_of([detector]))
        hours = float(prepared.run.t[-1] - prepared.run.t[0]) / 3600.0
        context = fit_context(detector, prepared.model, prepared.run)

        def fit(**ctx) -> None:
            (fresh,) = create_detectors(loaded, ["kgn"])
            fresh.fit([prepared.run], [prepared.trace], **ctx)

        whole = best_of(3, lambda: fit(**context))
        bare = best_of(3, lambda: fit())  # no model: the probe does not run
    load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    print(f"log: {hours:.2f} h quadcopter at 100 Hz ({load})")
    print(f"kgn fit: {whole:.3f} s = {whole / hours:.2f} s per log-hour (target <= 2 s)")
    print(f"  of which the blindness probe: {whole - bare:.3f} s = {(whole - bare) / hours:.2f} s per log-hour")


if __name__ == "__main__":
    main()
