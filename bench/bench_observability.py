"""Cost of the observability verdict (docs/algorithms.md section 10) against the EKF whose run it reads.

A quadcopter log (`logscan simulate quadcopter`, default 600 s at 100 Hz: accel, gyro, attitude and
position, 4 motors, so 4 actuator and 12 sensor fault directions) is prepared as `logscan analyze`
prepares it (its built-in profile, the default detectors' needs); then, in one process and
alternating, the EKF is re-run on the aligned run exactly as the pipeline ran it and the verdict
is computed from its trace. Printed: CPU us per step of each (best of ``--repeat``), their ratio,
seconds per log-hour, and `uptime`. Timings on the shared 2-core machine are noisy: read the ratio.

``--cold`` also times the verdict's first call with an empty numba cache (a subprocess with a
fresh cache directory; the EKF's compile is done before the timer starts).

    python bench/bench_observability.py                # 600 s log, best of 3
    python bench/bench_observability.py --seconds 120 --cold
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchlib import best_of, simulate_log

import logscan

# run against the logscan tree the bench itself imports (argv[1]), not the venv's editable install
COLD = """
import sys
import time
sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in (type(f).__name__ + type(f).__module__).lower()]
sys.path.insert(0, sys.argv[1])
from bench_ekf import make_run
from logscan.filters import run_ekf
from logscan.verdict.observability import observability_of
model, run, _ = make_run(2000)
trace = run_ekf(model, run, store_gain=False, store_S=False)
start = time.process_time()
observability_of(model, run, trace)
print(time.process_time() - start)
"""


def cpu_best(n: int, fn) -> float:
    """The shortest of ``n`` process CPU times of ``fn()``, seconds."""
    return best_of(n, fn, clock=time.process_time)


def prepared_log(path: str):
    from logscan.pipeline.preparation import load_profile_for, prepare
    from logscan.pipeline.stages import create_detectors, needs_of

    loaded = load_profile_for(path, None)
    return prepare(path, loaded, needs_of(create_detectors(loaded)))


def cold_compile() -> float:
    """CPU s of the verdict's first call with an empty numba cache (its kernel for the quadcopter)."""
    with tempfile.TemporaryDirectory() as cache:
        env = {k: v for k, v in os.environ.items() if k not in ("LOGSCAN_CACHE_DIR", "PYTHONPATH")}
        env["NUMBA_CACHE_DIR"] = cache
        env["PYTHONPATH"] = str(Path(__file__).resolve().parent)
        root = str(Path(logscan.__file__).resolve().parents[1])
        command = [sys.executable, "-c", COLD, root]
        out = subprocess.run(command, env=env, capture_output=True, text=True, check=True)
        return float(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=600.0, help="length of the simulated log (s)")
    parser.add_argument("--repeat", type=int, default=3, help="best of this many runs of each")
    parser.add_argument("--cold", action="store_true", help="also time the verdict's cold compile")
    args = parser.parse_args()

    from logscan.filters import run_ekf
    from logscan.verdict.observability import observability_of

    with tempfile.TemporaryDirectory() as tmp:
        path = simulate_log("quadcopter", os.path.join(tmp, "quad.mcap"), "--duration", f"{args.seconds:g}")
        prepared = prepared_log(path)
    model, run, trace = prepared.model, prepared.run, prepared.trace
    stored = {"store_gain": trace.K is not None, "store_S": trace.S is not None}
    stored["store_innovations"] = trace.y is not None
    observability_of(model, run, trace)  # warm: the kernel loaded from the cache (or compiled)
    ekf_s, verdict_s = float("inf"), float("inf")
    for _ in range(args.repeat):  # alternating, so both see the same load
        ekf_s = min(ekf_s, cpu_best(1, lambda: run_ekf(model, run, **stored)))
        verdict_s = min(verdict_s, cpu_best(1, lambda: observability_of(model, run, trace)))
    obs = observability_of(model, run, trace)
    steps = run.n_steps
    hour = 3600.0 / (steps * run.dt)
    print(f"quadcopter {args.seconds:g} s, {steps} steps, {len(obs.directions)} fault directions")
    for name, spent in (("EKF (as the pipeline ran it)", ekf_s), ("observability verdict", verdict_s)):
        print(f"{name:30s}{1e6 * spent / steps:7.2f} us/step  {spent * hour:6.2f} s per log-hour")
    print(f"verdict / EKF                 {verdict_s / ekf_s:7.2f}")
    if args.cold:
        print(f"verdict's cold compile        {cold_compile():7.2f} CPU s")
    print("uptime:", subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())


if __name__ == "__main__":
    main()
