"""Benchmark of the shared EKF core against filterpy's ExtendedKalmanFilter (one run, same data).

A 12-state quadcopter flies a hover-and-circle under a PD controller (truth: the model's RK4 step
plus w ~ N(0, Q)); accelerometer and gyro at 100 Hz and position at 10 Hz with noise ~ N(0, R).
Both filters use the same model (filterpy: logscan's model functions f, F, h, H, each a call into
compiled code, and again the same model in plain numpy, `ekf_baselines.NumpyQuadcopter`), the same
Q, R, x0, P0 and the same update up to rounding (filterpy's EKF.update: Joseph form with inv(S);
logscan: Cholesky solves and P - K S K^T), so their state estimates agree to rounding; the script
checks it. A hand-tuned filter for this model and sensor layout (`ekf_baselines.hand_tuned_ekf`)
runs beside logscan's, interleaved: the reference algebra the generic kernel is measured against,
the light trace against it as it is, the full trace (S and K stored at every step, 1.5 KB) against
it storing the same S and K (checked equal to logscan's): each ratio then compares the same work.

Also measured: the numba cold-compile time (fresh NUMBA_CACHE_DIR in a subprocess) and the
warm-cache start-up time.

    python bench/bench_ekf.py                 # 100,000 steps
    python bench/bench_ekf.py --steps 20000   # quick check
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time

import numpy as np
from numba import njit

from logscan.align import AlignedGroup, AlignedRun
from logscan.filters import linalg, run_ekf
from logscan.memory import reuse_freed_arrays
from logscan.models import dispatch, get_model
from logscan.models.quadcopter_kernels import QP_G, QP_MASS, QUADCOPTER_ID
from logscan.numba_cache import follow_dependencies

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from ekf_baselines import NumpyQuadcopter, run_hand_tuned  # noqa: E402

DT = 0.01


@njit(cache=True)
def _simulate(p, N, dt, Lq, noise):
    """Closed-loop truth: PD position/attitude controller around a 5 m circle (bench only)."""
    m, g = p[QP_MASS], p[QP_G]
    x = np.zeros(12)
    X = np.empty((N, 12))
    U = np.empty((N, 4))
    Acc = np.empty((N, 3))
    u = np.zeros(4)
    for k in range(N):
        t = k * dt
        ref = np.array([5.0 * np.cos(0.2 * t) - 5.0, 5.0 * np.sin(0.2 * t), 2.0])
        ax = 1.0 * (ref[0] - x[0]) - 1.5 * x[3]
        ay = 1.0 * (ref[1] - x[1]) - 1.5 * x[4]
        az = 2.0 * (ref[2] - x[2]) - 2.0 * x[5]
        # small-angle inversion of the translational dynamics (yaw held at 0)
        pitch_ref = max(-0.3, min(0.3, ax / g))
        roll_ref = max(-0.3, min(0.3, -ay / g))
        u[0] = m * (g + az) / (np.cos(x[6]) * np.cos(x[7]))
        u[1] = 0.0212 * (40.0 * (roll_ref - x[6]) - 10.0 * x[9])
        u[2] = 0.0212 * (40.0 * (pitch_ref - x[7]) - 10.0 * x[10])
        u[3] = 0.0392 * (10.0 * (0.0 - x[8]) - 5.0 * x[11])
        if k > 0:
            w = noise * (Lq @ np.random.randn(12))
            x = dispatch.f_disc(QUADCOPTER_ID, p, x, u, dt) + w
        X[k] = x
        U[k] = u
        Acc[k] = dispatch.h_meas(QUADCOPTER_ID, 0, p, x, u)  # specific force
    return X, U, Acc


def make_run(steps: int, seed: int = 0):
    model = get_model("quadcopter")
    rng = np.random.default_rng(seed)
    _seed_numba(seed)
    L_Q = np.linalg.cholesky(model.default_Q(DT))
    X, U, Acc = _simulate(model.param_vector(), steps, DT, L_Q, 1.0)
    groups = {}
    for name, period in (("accel", 1), ("gyro", 1), ("position", 10)):
        spec = model.groups[name]
        fresh = np.arange(steps) % period == 0
        z = np.full((steps, 3), np.nan)
        idx = np.flatnonzero(fresh)
        clean = {"accel": Acc[idx], "gyro": X[idx, 9:12], "position": X[idx, 0:3]}[name]
        z[idx] = clean + rng.normal(size=clean.shape) * np.asarray(spec.noise_std)
        groups[name] = AlignedGroup(name, list(spec.outputs), z, fresh)
    run = AlignedRun(
        t=np.arange(steps) * DT,
        dt=DT,
        start_ns=0,
        u=U,
        u_fresh=np.ones(steps, bool),
        input_channels=list(model.input_names),
        groups=groups,
    )
    return model, run, X


@njit(cache=True)
def _seed_numba(seed):
    np.random.seed(seed)


def run_filterpy(model, run, x0, P0, functions=None):
    """filterpy's ExtendedKalmanFilter on the same model: F before predict, stacked H/h/R.
    ``functions``: the f/F/h/H to drive it with (default: the logscan model's own, each a call
    into compiled code; `NumpyQuadcopter`: plain numpy)."""
    from filterpy.kalman import ExtendedKalmanFilter

    n = model.n_states
    fun = model if functions is None else functions
    names = list(run.groups)
    Q = model.default_Q(run.dt)
    R = {g: model.default_R(g) for g in names}

    class ModelEKF(ExtendedKalmanFilter):
        def predict_x(self, u=0):
            self.x = fun.f(self.x, u, run.dt)

    ekf = ModelEKF(dim_x=n, dim_z=9)
    ekf.x = x0.copy()
    ekf.P = P0.copy()
    ekf.Q = Q
    x_post = np.empty((run.n_steps, n))
    fresh = np.column_stack([run.groups[g].fresh for g in names])
    for k in range(run.n_steps):
        u = run.u[k]
        if k > 0:
            ekf.F = fun.F(ekf.x, u, run.dt)
            ekf.predict(u=u)
        used = [g for g, f in zip(names, fresh[k]) if f]
        z = np.concatenate([run.groups[g].z[k] for g in used])
        Rk = np.zeros((z.size, z.size))
        o = 0
        for g in used:
            s = R[g].shape[0]
            Rk[o : o + s, o : o + s] = R[g]
            o += s
        ekf.update(
            z,
            HJacobian=lambda x, used=used, u=u: np.vstack([fun.H(g, x, u) for g in used]),
            Hx=lambda x, used=used, u=u: np.concatenate([fun.h(g, x, u) for g in used]),
            R=Rk,
        )
        x_post[k] = ekf.x
    return x_post


@njit(cache=True)
def _phase_loop(which, reps, p, x, u, dt, P, Q, R):
    """Time one sub-step of the EKF step `reps` times on fixed inputs (accel + gyro update,
    m = 6), with the core's own helpers and work arrays."""
    n, m = 12, 6
    x_new, kv, xs = np.empty(n), np.empty(n), np.empty(n)
    F, A, J, Jn, W, FP, P_upd = (
        np.empty((n, n)),
        np.empty((n, n)),
        np.empty((n, n)),
        np.empty((n, n)),
        np.empty((n, n)),
        np.empty((n, n)),
        np.empty((n, n)),
    )
    fcols, fnnz = np.empty((n, n), np.int64), np.empty(n, np.int64)
    hcols, hnnz = np.empty((m, n), np.int64), np.empty(m, np.int64)
    rcols, rnnz = np.empty((m, m), np.int64), np.empty(m, np.int64)
    hx, Hs, R3, D3 = np.empty(m), np.empty((m, n)), np.empty((3, 3)), np.empty((3, 3, 3))
    HP, KT, S, L = np.empty((m, n)), np.empty((m, n)), np.empty((m, m)), np.empty((m, m))
    D, DT, V = np.empty((n, m)), np.empty((m, n)), np.empty((m, n))
    all_cols = np.empty((n, m), np.int64)
    for i in range(n):
        for a in range(m):
            all_cols[i, a] = a
    m_cnt = np.full(n, m, np.int64)
    qid = QUADCOPTER_ID
    dispatch.predict_into(qid, p, x, u, dt, x_new, F, kv, xs, A, J, Jn)
    linalg.sparse_rows(F, n, n, fcols, fnnz)
    linalg.sparse_rows(R, m, m, rcols, rnnz)
    acc = 0.0
    for it in range(reps + 1):
        if which == 0 or it == 0:  # RK4 step and its exact Jacobian
            dispatch.predict_into(qid, p, x, u, dt, x_new, F, kv, xs, A, J, Jn)
        if which == 1 or it == 0:  # P_prior = F P F^T + Q
            linalg.sparse_rows(F, n, n, fcols, fnnz)
            linalg.fpft_q(F, P, Q, n, fcols, fnnz, FP, W, P_upd)
        if which == 2 or it == 0:  # h, H of accel and gyro
            dispatch.meas_into(qid, 0, p, x, u, 0, hx, Hs, R3, D3)
            dispatch.meas_into(qid, 1, p, x, u, 3, hx, Hs, R3, D3)
            linalg.sparse_rows(Hs, m, n, hcols, hnnz)
        if which == 3 or it == 0:  # H P and S = H P H^T + R
            linalg.sparse_mm(Hs, hcols, hnnz, m, P, n, HP)
            for a in range(m):
                for b in range(m):
                    t = R[a, b]
                    for s in range(hnnz[b]):
                        t += HP[a, hcols[b, s]] * Hs[b, hcols[b, s]]
                    S[a, b] = t
        if which == 4 or it == 0:  # Cholesky of S, V = L^-1 H P and K^T = L^-T V
            linalg.cholesky(S, 0, m, L)
            linalg.gain_rows(L, m, HP, V, KT, n)
        if which == 5 or it == 0:  # short form P - V^T V
            linalg.short_update(P, V, m, n, 1e-6, P_upd)
        if which == 6 or it == 0:  # Joseph form (the fallback)
            linalg.joseph(P, Hs, hcols, hnnz, HP, KT, R, rcols, rnnz, m, n, all_cols, m_cnt, W, DT, D, P_upd)
        acc += P_upd[1, 2] + KT[0, 0] + x_new[0]
    return acc


PHASES = (
    "RK4 step + exact Jacobian F",
    "F P F^T + Q",
    "h, H (accel, gyro)",
    "H P, S = H P H^T + R",
    "Cholesky of S, K = P H^T S^-1",
    "short P update P - V^T V",
    "Joseph P update (fallback)",
)


def phase_times(model, trace, run, reps=100_000):
    """CPU microseconds per call of each sub-step, on a state and covariance from the run."""
    k = trace.n_steps // 2
    R = np.zeros((6, 6))
    R[:3, :3] = model.default_R("accel")
    R[3:, 3:] = model.default_R("gyro")
    args = (
        model.param_vector(run.dt),
        trace.x_post[k].copy(),
        run.u[k].copy(),
        run.dt,
        np.ascontiguousarray(trace.P_post[k]),
        model.default_Q(run.dt),
        R,
    )
    out = {}
    for which, name in enumerate(PHASES):
        _phase_loop(which, 10, *args)
        c0 = time.process_time()
        _phase_loop(which, reps, *args)
        out[name] = (time.process_time() - c0) / reps * 1e6
    return out


_COLD = """
import time
t0, c0 = time.perf_counter(), time.process_time()
import numpy as np
from logscan.align import AlignedGroup, AlignedRun
from logscan.filters import run_ekf
from logscan.models import get_model
m = get_model("quadcopter")
N = 50
run = AlignedRun(t=np.arange(N) * 0.01, dt=0.01, start_ns=0, u=np.tile(m.hover_input(), (N, 1)),
                 u_fresh=np.ones(N, bool), input_channels=list(m.input_names),
                 groups={"gyro": AlignedGroup("gyro", ["a", "b", "c"], np.zeros((N, 3)),
                                              np.ones(N, bool))})
run_ekf(m, run)
print(time.perf_counter() - t0, time.process_time() - c0)
"""


def compile_times() -> tuple[tuple[float, float], tuple[float, float]]:
    """((wall s, CPU s) cold: empty NUMBA_CACHE_DIR, (wall s, CPU s) warm: same cache again) to
    import + first run."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        out = []
        for _ in range(2):
            res = subprocess.run([sys.executable, "-c", _COLD], env=env, capture_output=True, text=True, check=True)
            wall, cpu = res.stdout.strip().splitlines()[-1].split()
            out.append((float(wall), float(cpu)))
    return out[0], out[1]


def best_of(funs, reps):
    """[(result, best wall s, best CPU s)] per function; repetitions interleaved (f1 f2 f1 f2 ...)
    so that a change in the machine's load hits every variant alike."""
    wall = [[] for _ in funs]
    cpu = [[] for _ in funs]
    results = [None] * len(funs)
    for _ in range(reps):
        for i, fun in enumerate(funs):
            t0, c0 = time.perf_counter(), time.process_time()
            results[i] = fun()
            wall[i].append(time.perf_counter() - t0)
            cpu[i].append(time.process_time() - c0)
    return [(r, min(w), min(c)) for r, w, c in zip(results, wall, cpu)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=100_000)
    ap.add_argument("--reps", type=int, default=5, help="logscan repetitions (best is reported)")
    ap.add_argument("--no-compile", action="store_true", help="skip the cold-compile measurement")
    ap.add_argument("--no-phases", action="store_true", help="skip the per-sub-step timings")
    ap.add_argument("--compile-only", action="store_true", help="only the cold-compile measurement")
    ap.add_argument("--no-filterpy", action="store_true", help="skip the (slow) filterpy runs")
    args = ap.parse_args(argv)
    # as the CLI does (logscan.cli): a run's freed trace arrays are reused by the next one, not
    # returned to the system and faulted in again (page faults were 0.2-0.5 us of a light step)
    reuse_freed_arrays()

    print(
        f"# {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"load average {os.getloadavg()[0]:.1f}"
    )
    if not args.no_compile:
        (cold, cold_cpu), (warm, warm_cpu) = compile_times()
        print(
            f"numba cold compile (empty cache, import + first run): {cold:.1f} s ({cold_cpu:.1f} s CPU); "
            f"warm cache: {warm:.2f} s ({warm_cpu:.2f} s CPU)"
        )
    if args.compile_only:
        return 0
    model, run, truth = make_run(args.steps)
    x0 = truth[0].copy()
    P0 = np.diag(np.square(model.state_scale())) * 0.01
    run_ekf(model, run, x0=x0, P0=P0)  # compile / load from cache outside the timing
    run_hand_tuned(model, run, x0, P0, store_gain=True)
    (full, wall, cpu), (light, wall_l, cpu_l), (hand, wall_h, cpu_h), (hand_full, wall_hf, cpu_hf) = best_of(
        [
            lambda: run_ekf(model, run, x0=x0, P0=P0),
            lambda: run_ekf(model, run, x0=x0, P0=P0, store_gain=False, store_S=False),
            lambda: run_hand_tuned(model, run, x0, P0),
            lambda: run_hand_tuned(model, run, x0, P0, store_gain=True),
        ],
        args.reps,
    )
    filterpy_runs = {}
    for label, functions in (
        ("logscan's compiled model", None),
        ("numpy model", NumpyQuadcopter(model.param_vector(DT))),
    ):
        if args.no_filterpy:  # placeholders: no filterpy figures printed (NaN)
            filterpy_runs[label] = (full.x_post, np.nan, np.nan)
            continue
        t0, c0 = time.perf_counter(), time.process_time()
        x_fp = run_filterpy(model, run, x0, P0, functions)
        filterpy_runs[label] = (x_fp, time.perf_counter() - t0, time.process_time() - c0)
    cpu_fp = filterpy_runs["numpy model"][2]
    cpu_fp_compiled = filterpy_runs["logscan's compiled model"][2]

    rmse = np.sqrt(np.mean((full.x_post[:, :3] - truth[:, :3]) ** 2))
    N = args.steps
    print(
        f"steps {N}: accel+gyro 100 Hz, position 10 Hz; position RMSE vs truth {rmse:.3f} m; "
        f"mean NIS/m {np.nanmean(full.nis / full.m_k):.3f}"
    )
    print("| filter | wall s | steps/s (wall) | CPU s | us/step (CPU) | speed-up vs filterpy, numpy model (CPU) |")
    print("|---|---:|---:|---:|---:|---:|")
    rows = [
        ("logscan, full trace (S, K stored)", wall, cpu),
        ("logscan, store_gain=False, store_S=False", wall_l, cpu_l),
        ("hand-tuned reference algebra (bench/ekf_baselines.py)", wall_h, cpu_h),
        ("hand-tuned reference algebra, S and K stored", wall_hf, cpu_hf),
    ]
    rows += [(f"filterpy ExtendedKalmanFilter, {label}", w, c) for label, (_, w, c) in filterpy_runs.items()]
    for label, w, c in rows:
        print(f"| {label} | {w:.2f} | {N / w:,.0f} | {c:.2f} | {c / N * 1e6:.2f} | {cpu_fp / c:.1f}x |")
    print(
        f"logscan / hand-tuned (CPU per step): light {cpu_l / cpu_h:.2f}x; full trace {cpu / cpu_hf:.2f}x "
        f"against the reference storing the same S and K ({cpu / cpu_h:.2f}x against the one storing neither); "
        f"filterpy with logscan's compiled model / with the numpy model: {cpu_fp_compiled / cpu_fp:.2f}"
    )
    ok = np.array_equal(full.x_post, light.x_post)
    for label, other in [("hand-tuned", hand)] + [(f"filterpy ({k})", v[0]) for k, v in filterpy_runs.items()]:
        diff = np.max(np.abs(full.x_post - other))
        print(
            f"agreement: max |x_logscan - x_{label}| = {diff:.2e} (relative {diff / np.max(np.abs(full.x_post)):.1e})"
        )
        ok = ok and diff < 1e-6
    _, S_hand, K_hand = hand_full
    for label, ours, theirs in (("S", full.S, S_hand), ("K", full.K, K_hand)):
        same_nan = np.array_equal(np.isnan(ours), np.isnan(theirs))
        diff = np.nanmax(np.abs(ours - theirs))
        print(f"agreement: max |{label}_logscan - {label}_hand-tuned| = {diff:.2e}, NaN alike: {same_nan}")
        ok = ok and same_nan and diff < 1e-6 * max(1.0, np.nanmax(np.abs(ours)))
    print("agreement check:", "PASS" if ok else "FAIL")
    if not args.no_phases:
        short = run_ekf(model, make_run(2000)[1], x0=x0, P0=P0, full_P=True)
        print(
            f"per-step CPU time of the whole kernel (light trace): {cpu_l / N * 1e6:.2f} us; "
            "its sub-steps (accel + gyro update, m = 6; CPU us per call):"
        )
        for name, us in phase_times(model, short, run).items():
            print(f"  {name}: {us:.2f}")
    print(f"load average after the run: {os.getloadavg()[0]:.1f}")
    return 0 if ok else 1


follow_dependencies(__name__)  # the bench kernels compile in the model kernels and linalg

if __name__ == "__main__":
    sys.exit(main())
