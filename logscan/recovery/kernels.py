"""Recovery's numba kernels: a model's h and H along a recovered trajectory, and the bound on its
Jacobians F. Each is compiled per model (`numba.literally(model_id)`, through
`logscan.models.dispatch`'s in-place functions, as the EKF kernel is), so a cold start compiles only
the models a run uses."""

from __future__ import annotations

import numpy as np
from numba import literally, njit

from logscan.models import dispatch
from logscan.numba_cache import follow_dependencies


@njit(cache=True)
def group_predictions(model_id, gid, p, x_prior, u, steps, hx, H):
    """h(x) and H = dh/dx of group gid at the given steps.

    x_prior (N, n), u (N, nu) finite, steps (s,) int64; fills hx (s, m) and H (s, m, n)."""
    literally(model_id)
    m, n = hx.shape[1], x_prior.shape[1]
    hk, Hk = np.empty(m), np.zeros((m, n))
    R3, D3 = np.empty((3, 3)), np.empty((3, 3, 3))  # the quadcopter's work arrays
    for a in range(steps.size):
        k = steps[a]
        Hk[:] = 0.0
        dispatch.model_meas_into(model_id, gid, p, x_prior[k], u[k], np.int64(0), hk, Hk, R3, D3)
        hx[a] = hk
        H[a] = Hk


@njit(cache=True)
def jacobian_bound(model_id, p, x, u, dt):
    """Abar = max_k |F_k| elementwise, F_k = df/dx at (x[k-1], u[k]) for k = 1..J-1.

    x (J, n) recovered trajectory, u (J, nu) finite inputs; returns (n, n)."""
    literally(model_id)
    n = x.shape[1]
    Abar = np.zeros((n, n))
    x_next, kv, xs = np.empty(n), np.empty(n), np.empty(n)
    F, A, J, Jn = np.empty((n, n)), np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    for k in range(1, x.shape[0]):
        dispatch.model_predict_into(model_id, p, x[k - 1], u[k], dt, x_next, F, kv, xs, A, J, Jn)
        for i in range(n):
            for j in range(n):
                Abar[i, j] = max(Abar[i, j], abs(F[i, j]))
    return Abar


follow_dependencies(__name__)
