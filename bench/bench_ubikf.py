"""UBIKF steps per second next to the point EKF, on the same 12-state hover-UAV log.

Simulates a 300 s healthy `hover_uav` log (100 Hz, position, velocity and attitude at 100 Hz: 9
measurements per step; seed 8300), aligns it once, then times in one run, best of 3 each: the
point EKF (`logscan.filters.ekf.run_ekf`, default trace) and the UBIKF (`logscan.filters.ubikf.
run_ubikf`: the weighted covariance bound, the zonotope state set (each step's new deviations boxed
on entry, every 10 steps' together, those older than 60 steps together), one block of states at a
time, the innovation box and S+ stored per step), and the chi-square bounds over the box
(`logscan.filters.box_chi2.box_chi2_bounds`). Kernels are compiled before timing. CPU time
(process_time), so other jobs on the machine slow it less than the wall clock.

    python bench/bench_ubikf.py
"""

from __future__ import annotations

import os
import tempfile


def main() -> None:
    import time

    from benchlib import best_of, simulate_log

    from logscan.align import align
    from logscan.filters.box_chi2 import box_chi2_bounds
    from logscan.filters.ekf import run_ekf
    from logscan.filters.ubikf import run_ubikf
    from logscan.models import get_model
    from logscan.pipeline import load_profile_for
    from logscan.readers import read_log

    with tempfile.TemporaryDirectory(prefix="bench-ubikf-") as root:
        log_path = os.path.join(root, "hover.mcap")
        simulate_log("hover_uav", log_path, "--duration", "300", "--seed", "8300")
        loaded = load_profile_for(log_path, None)
        profile = loaded.profile
        model = get_model(profile.vehicle.model, profile.vehicle.params)
        log = read_log(log_path, topics=profile.topics())
        run = align(log, profile)
    interval = model.interval_model(run.dt)
    run_ekf(model, run, store_gain=False, store_S=False, store_innovations=False)  # compile
    trace = run_ubikf(interval, run)
    box_chi2_bounds(trace.r_mid, trace.r_rad, trace.S)
    n = run.n_steps

    def cpu_best(runs: int, work) -> float:
        return best_of(runs, work, clock=time.process_time)

    ekf = cpu_best(3, lambda: run_ekf(model, run, store_gain=False, store_S=False, store_innovations=False))
    ubikf = cpu_best(3, lambda: run_ubikf(interval, run))
    box = cpu_best(3, lambda: box_chi2_bounds(trace.r_mid, trace.r_rad, trace.S))
    print(f"{n} steps, 12 states, 9 measurements per step")
    print(f"point EKF:  {n / ekf:,.0f} steps/s ({ekf / n * 1e6:.2f} us per step)")
    per_step = ubikf / n * 1e6
    print(f"UBIKF:      {n / ubikf:,.0f} steps/s ({per_step:.2f} us per step, {ubikf / ekf:.1f}x the EKF's time)")
    print(f"chi2 bounds over the box: {n / box:,.0f} steps/s")


if __name__ == "__main__":
    main()
