"""Training time per log-hour per sensor group: `logscan train` on a 1-hour Jackal-like log.

Simulates a 1-hour dc_motor log (`logscan simulate dc_motor --duration 3600 --glitches 2 --seed
6100`: 20 Hz encoders, 10 Hz GPS speed, the six speed modes in turn), then times, best of 3 in one
run: the A-TFM fit alone (errors, e(eps, w) for 4 windows x 201 eps, knees, envelope; one redundant
group of 3 sensors), and the whole `logscan train` (read, align, fit, tables JSON, training report).
Target (the A-TFM issue): <= 1 s per log-hour per sensor group for the fit.

    python bench/bench_train.py
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile


def main() -> None:
    from benchlib import best_of, simulate_log

    from logscan.pipeline import create_detectors, load_profile_for, needs_of, prepare
    from logscan.training.train import fit_detectors

    with tempfile.TemporaryDirectory(prefix="bench-train-") as root:
        log = os.path.join(root, "hour.mcap")
        simulate_log("dc_motor", log, "--duration", "3600", "--glitches", "2", "--seed", "6100")
        loaded = load_profile_for(log, None)
        prepared = prepare(log, loaded, needs_of(create_detectors(loaded, ["atfm"])))
        hours = float(prepared.run.t[-1] - prepared.run.t[0]) / 3600.0
        groups = len(prepared.run.redundant)
        fit = best_of(3, lambda: fit_detectors(create_detectors(loaded, ["atfm"]), [prepared]))
        tables = os.path.join(root, "t.json")
        command = [sys.executable, "-m", "logscan", "train", log, "-o", tables, "-q"]
        whole = best_of(3, lambda: subprocess.run(command, check=True))
    print(f"log: {hours:.2f} h, {groups} redundant group(s) of 3 sensors")
    print(f"A-TFM fit: {fit:.3f} s = {fit / hours / groups:.3f} s per log-hour per sensor group (target <= 1 s)")
    print(f"logscan train, whole command (python start, read, align, fit, JSON, report): {whole:.2f} s")


if __name__ == "__main__":
    main()
