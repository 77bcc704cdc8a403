"""Synthetic linear loops for the recovery tests: a position/velocity loop (`linear` model) with a
position group "gps" and a velocity group "odo", truth simulated with the model's own discrete
matrices, optional sensor biases (attacks) on a time window."""

from __future__ import annotations

import numpy as np

from logscan.align import AlignedGroup, AlignedRun
from logscan.filters import run_ekf
from logscan.models import get_model
from logscan.recovery import LoopRun

# x = (p, v); a damped double integrator driven by an acceleration input
PARAMS = {
    "A": [[0.0, 1.0], [0.0, -0.2]],
    "B": [[0.0], [1.0]],
    "C": {"gps": [[1.0, 0.0]], "odo": [[0.0, 1.0]]},
    "Q": [[1e-3, 0.0], [0.0, 2e-2]],
    "R": {"gps": [0.3], "odo": [0.05]},
    "states": ["p", "v"],
}


def model(params=None):
    return get_model("linear", params or PARAMS)


def inputs(N: int, dt: float) -> np.ndarray:
    t = np.arange(N) * dt
    return (0.5 * np.sin(0.7 * t) + 0.2)[:, None]


def simulate(mdl, N, dt, rng, u, x0=None, noise=1.0):
    """Truth x_k = f(x_{k-1}, u[k]) + w_k (the kernel's convention), vectorised over runs when
    ``rng`` draws (R, ...) arrays: here one run."""
    n = mdl.n_states
    Lq = np.linalg.cholesky(mdl.default_Q(dt))
    W = noise * rng.normal(size=(N, n)) @ Lq.T
    x = np.zeros((N, n))
    x[0] = np.zeros(n) if x0 is None else x0
    for k in range(1, N):
        x[k] = mdl.f(x[k - 1], u[k], dt) + W[k]
    return x


def measure(mdl, truth, u, rng, rates, attacks=(), noise=1.0, dt=0.1):
    """Groups sampled every rates[g] steps; attacks: (group, t_start, t_end, bias)."""
    N = truth.shape[0]
    t = np.arange(N) * dt
    groups = {}
    for g, period in rates.items():
        fresh = np.arange(N) % period == 0
        std = np.sqrt(np.diag(mdl.default_R(g)))
        z = np.full((N, mdl.groups[g].size), np.nan)
        for k in np.flatnonzero(fresh):
            z[k] = mdl.h(g, truth[k], u[k]) + noise * std * rng.normal(size=std.size)
        for target, t0, t1, bias in attacks:
            if target == g:
                z[(t >= t0) & (t < t1) & fresh] += bias
        groups[g] = AlignedGroup(g, list(mdl.groups[g].outputs), z, fresh)
    return groups


def make_run(groups, u, dt, start_ns=0):
    N = u.shape[0]
    return AlignedRun(
        t=np.arange(N) * dt,
        dt=dt,
        start_ns=start_ns,
        u=u,
        u_fresh=np.ones(N, bool),
        input_channels=["/u"],
        groups=groups,
    )


def make_loop(name="outer", N=300, dt=0.1, seed=0, rates=None, attacks=(), noise=1.0, params=None, x0=None, P0=None):
    """(LoopRun, truth): the loop's shared EKF started at the true initial state."""
    mdl = model(params)
    rng = np.random.default_rng(seed)
    u = inputs(N, dt)
    truth = simulate(mdl, N, dt, rng, u, noise=noise)
    groups = measure(mdl, truth, u, rng, rates or {"gps": 1, "odo": 1}, attacks, noise, dt)
    run = make_run(groups, u, dt)
    x0 = truth[0] if x0 is None else x0
    P0 = np.eye(mdl.n_states) * 1e-2 if P0 is None else P0
    trace = run_ekf(mdl, run, x0=x0, P0=P0, full_P=True)
    return LoopRun(name, mdl, run, trace), truth
