"""Benchmark of the shared EKF core on the IMU-driven `ins` model at PX4's IMU rates (200, 250 Hz).

The truth is the model's own strapdown step driven by a smooth manoeuvre (the body turning and
tilting, the vehicle accelerating); the logged IMU adds bias and the model's per-sample noise. GNSS
position and velocity at 10 Hz, barometer at 25 Hz and an external attitude at 50 Hz come from the
truth through the model's h plus noise. Reported: steps/s of `run_ekf` (best of --reps, CPU time)
with the full trace (K and S stored) and with the light one, and the estimate's errors against the
truth (a check that the run is a real, converged filter, not an empty loop).

    python bench/bench_ins.py                  # 10 minutes of log at each rate
    python bench/bench_ins.py --seconds 300    # quick check
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time

import numpy as np

from logscan.align import AlignedGroup, AlignedRun
from logscan.filters import run_ekf
from logscan.models import get_model

SENSORS = {"gnss_position": 10.0, "gnss_velocity": 10.0, "baro": 25.0, "attitude": 50.0}


def make_run(seconds: float, rate: float, seed: int = 0):
    """(model, AlignedRun, true states) of a manoeuvring flight logged at ``rate`` Hz."""
    model = get_model("ins")
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate
    N = int(seconds * rate)
    t = np.arange(N) * dt
    g = model.p["g"]
    # true IMU: slow turns and tilts, accelerations of up to 1 m/s^2
    omega = np.column_stack([0.2 * np.sin(0.3 * t), 0.2 * np.cos(0.23 * t), 0.1 * np.sin(0.05 * t)])
    accel = np.column_stack([np.sin(0.1 * t), np.cos(0.13 * t), -g + 0.5 * np.sin(0.07 * t)])
    u_true = np.hstack([omega, accel])
    x = np.zeros((N, model.n_states))
    x[0, 2] = -10.0
    x[0, 15] = 250.0
    for k in range(N - 1):  # the bench's own truth; run once, outside the timing
        x[k + 1] = model.f(x[k], u_true[k], dt)
    bias = np.r_[rng.normal(0, 0.003, 3), rng.normal(0, 0.05, 3)]
    noise = np.r_[[model.p["gyro_noise"]] * 3, [model.p["accel_noise"]] * 3]
    u = u_true + bias + rng.normal(size=(N, 6)) * noise
    groups = {}
    for name, hz in SENSORS.items():
        spec = model.groups[name]
        ratio = int(round(rate / hz))
        fresh = np.zeros(N, bool)
        fresh[::ratio] = True
        z = np.full((N, spec.size), np.nan)
        for k in np.flatnonzero(fresh):
            z[k] = model.h(name, x[k], u_true[k])
        z[fresh] += rng.normal(size=(int(fresh.sum()), spec.size)) * np.asarray(spec.noise_std)
        if name == "attitude":
            z[fresh] = (z[fresh] + np.pi) % (2 * np.pi) - np.pi
        z = np.where(fresh[:, None], z, np.nan)
        groups[name] = AlignedGroup(name, list(spec.outputs), z, fresh)
    run = AlignedRun(
        t=t,
        dt=dt,
        start_ns=0,
        u=u,
        u_fresh=np.ones(N, bool),
        input_channels=list(model.input_names),
        groups=groups,
    )
    return model, run, x


def best_cpu(fun, reps: int) -> tuple[object, float]:
    best, result = np.inf, None
    for _ in range(reps):
        c0 = time.process_time()
        result = fun()
        best = min(best, time.process_time() - c0)
    return result, best


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=600.0, help="log length per rate")
    ap.add_argument("--reps", type=int, default=3)
    args = ap.parse_args(argv)
    print(
        f"# {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"load average {os.getloadavg()[0]:.1f}"
    )
    print(
        "| IMU rate | steps | full trace: CPU s | steps/s | light trace: CPU s | steps/s | position RMSE "
        "| attitude RMSE |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    ok = True
    for rate in (200.0, 250.0):
        model, run, truth = make_run(args.seconds, rate)
        run_ekf(model, run)  # compile / load from the cache outside the timing
        full, cpu_full = best_cpu(lambda model=model, run=run: run_ekf(model, run), args.reps)
        light, cpu_light = best_cpu(
            lambda model=model, run=run: run_ekf(model, run, store_gain=False, store_S=False), args.reps
        )
        half = run.n_steps // 2  # after convergence
        pos = np.sqrt(np.mean((full.x_post[half:, :3] - truth[half:, :3]) ** 2))
        att_err = (full.x_post[half:, 6:9] - truth[half:, 6:9] + np.pi) % (2 * np.pi) - np.pi
        att = np.sqrt(np.mean(att_err**2))
        ok &= bool(pos < 1.0 and att < 0.05 and np.array_equal(full.x_post, light.x_post))
        N = run.n_steps
        print(
            f"| {rate:.0f} Hz | {N:,} | {cpu_full:.2f} | {N / cpu_full:,.0f} | {cpu_light:.2f} | "
            f"{N / cpu_light:,.0f} | {pos:.2f} m | {att:.4f} rad |"
        )
    print("check (converged estimate, light trace equal to the full one):", "PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
