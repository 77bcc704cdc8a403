"""One RK4 step per grid period with its exact Jacobian, for the continuous-time models.

The discrete Jacobian F is the exact derivative of the RK4 step, obtained by propagating the
continuous Jacobian A through the four stages (dk_i/dx = A(x_i) dx_i/dx). Shapes: x, x_next,
kv, xs (n,); F, A, J, Jn (n, n); p is the model's packed parameter vector.

The model's continuous dynamics are its registered `fA` (`logscan.models.model_kernels`), found
while numba compiles a step for the literal model id: a model's kernels module calls these with its
own id constant, and its cached functions carry the step (these are not cached on their own: they
would carry a model's dynamics without following its module).
"""

from __future__ import annotations

import numpy as np
from numba import literally, njit
from numba.extending import overload

from logscan.models.model_kernels import literal_kernel


def cont_fA(model_id, p, x, u, d, A, want_A):
    """Continuous dynamics d = f_c(x, u) and, when want_A, A = df_c/dx of the model ``model_id``
    (a compile-time constant; numba code only)."""
    raise NotImplementedError("cont_fA is resolved by numba at compile time")


@overload(cont_fA, inline="always")
def _cont_fA(model_id, p, x, u, d, A, want_A):
    fA = literal_kernel(model_id, "fA")
    if fA is not None:

        def impl(model_id, p, x, u, d, A, want_A):
            fA(p, x, u, d, A, want_A)

        return impl


@njit
def rk4_predict_into(model_id, p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """One RK4 step x_next and its exact Jacobian F = d x_next / d x, into x_next and F.

    Stages x1 = x, x2 = x + dt/2 k1, x3 = x + dt/2 k2, x4 = x + dt k3 with k_i = f_c(x_i); with
    dk_i/dx = J_i: J1 = A(x1), J2 = A(x2) (I + dt/2 J1), J3 = A(x3) (I + dt/2 J2),
    J4 = A(x4) (I + dt J3); x_next = x + dt/6 (k1 + 2 k2 + 2 k3 + k4),
    F = I + dt/6 (J1 + 2 J2 + 2 J3 + J4).
    kv, xs (n,) and A, J, Jn (n, n) are work arrays; the products skip the zeros of the sparse
    continuous Jacobian A.
    """
    literally(model_id)  # one step per model: its fA compiled in
    n = x.size
    c = dt / 6.0
    for i in range(n):
        x_next[i] = x[i]
        xs[i] = x[i]
        for j in range(n):
            F[i, j] = 0.0
    for stage in range(4):
        cont_fA(model_id, p, xs, u, kv, A, True)
        cw = c * (1.0 if stage == 0 or stage == 3 else 2.0)
        h = 0.5 * dt if stage < 3 else dt
        step = 0.5 * dt if stage < 2 else dt
        for i in range(n):
            # Jn = A + h A J  (= A (I + h J))
            for j in range(n):
                Jn[i, j] = A[i, j]
            if stage > 0:
                for q in range(n):
                    a = A[i, q]
                    if a != 0.0:
                        a *= h
                        for j in range(n):
                            Jn[i, j] += a * J[q, j]
            for j in range(n):
                F[i, j] += cw * Jn[i, j]
            x_next[i] += cw * kv[i]
            xs[i] = x[i] + step * kv[i]
        J, Jn = Jn, J
    for i in range(n):
        F[i, i] += 1.0


@njit
def rk4_predict(model_id, p, x, u, dt):
    """One RK4 step x_next and its exact Jacobian F (allocating wrapper of rk4_predict_into)."""
    literally(model_id)
    n = x.size
    x_next = np.empty(n)
    F = np.empty((n, n))
    rk4_predict_into(
        model_id, p, x, u, dt, x_next, F, np.empty(n), np.empty(n), np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    )
    return x_next, F


@njit
def rk4_f(model_id, p, x, u, dt):
    """The RK4 step alone (no Jacobian): the simulator's truth propagation."""
    literally(model_id)
    n = x.size
    k = np.empty(n)
    xs = x.copy()
    x_next = x.copy()
    A = np.empty((0, 0))
    c = dt / 6.0
    for stage in range(4):
        cont_fA(model_id, p, xs, u, k, A, False)
        w = 1.0 if stage == 0 or stage == 3 else 2.0
        step = 0.5 * dt if stage < 2 else dt
        for i in range(n):
            x_next[i] += c * w * k[i]
            xs[i] = x[i] + step * k[i]
    return x_next
