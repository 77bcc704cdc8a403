"""The two baselines `bench_ekf.py` measures logscan's EKF kernel against (bench only).

- `NumpyQuadcopter`: the quadcopter model (RK4 step with its exact Jacobian, accel / gyro /
  position outputs) written in plain numpy, as a filterpy user would write it. filterpy's
  ExtendedKalmanFilter driven with it is the "pure-Python model" baseline: no compiled code
  anywhere in the loop, so the ratio to logscan measures a whole Python EKF against the compiled
  kernel. (Driven with logscan's own `Model.f/F/h/H`, each call enters a compiled function through
  Python, and that baseline mixes the two.)
- `hand_tuned_ekf`: the same filter as one numba loop written by hand for this model and this
  sensor layout only (accel + gyro every step, position every tenth): the model's own compiled RK4
  step and measurement functions, F P F^T + Q on F's non-zeros found once, the short covariance
  update P - V^T V with V = L^-1 H P (S = L L^T), and nothing else: no finite checks, no
  multi-rate bookkeeping, no trace but the posterior state. It is the reference algebra the
  generic kernel is measured against (issue 29 item 3: within 1.15x).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from logscan.models.quadcopter_kernels import (
    QP_ARM,
    QP_BTAU,
    QP_G,
    QP_INPUT_MODE,
    QP_IX,
    QP_IY,
    QP_IZ,
    QP_KD,
    QP_KT,
    QP_MASS,
    quad_meas_into,
    quad_rk4_predict_into,
)
from logscan.numba_cache import follow_dependencies


class NumpyQuadcopter:
    """The quadcopter's discrete model in plain numpy (the same equations as
    logscan.models.quadcopter_kernels; agrees with them to rounding)."""

    def __init__(self, p: np.ndarray):
        self.p = np.asarray(p, dtype=float)

    def _wrench(self, u):
        p = self.p
        if p[QP_INPUT_MODE] == 0.0:
            return u[0], u[1], u[2], u[3]
        T = p[QP_KT] * np.square(u)
        return T.sum(), p[QP_ARM] * (T[1] - T[3]), p[QP_ARM] * (T[2] - T[0]), p[QP_BTAU] * (T[0] - T[1] + T[2] - T[3])

    def fA(self, x, u):
        """Continuous dynamics and their Jacobian A = df_c/dx."""
        p = self.p
        T, tx, ty, tz = self._wrench(u)
        m, g, kD = p[QP_MASS], p[QP_G], p[QP_KD]
        Ix, Iy, Iz = p[QP_IX], p[QP_IY], p[QP_IZ]
        cf, sf, ct, st, cp, sp = np.cos(x[6]), np.sin(x[6]), np.cos(x[7]), np.sin(x[7]), np.cos(x[8]), np.sin(x[8])
        wp, wq, wr = x[9], x[10], x[11]
        tt, a, b, Tm = st / ct, sf * wq + cf * wr, cf * wq - sf * wr, T / m
        d = np.array(
            [
                x[3],
                x[4],
                x[5],
                Tm * (cp * st * cf + sp * sf) - kD * x[3] / m,
                Tm * (sp * st * cf - cp * sf) - kD * x[4] / m,
                Tm * (ct * cf) - g - kD * x[5] / m,
                wp + a * tt,
                b,
                a / ct,
                (tx - (Iz - Iy) * wq * wr) / Ix,
                (ty - (Ix - Iz) * wp * wr) / Iy,
                (tz - (Iy - Ix) * wp * wq) / Iz,
            ]
        )
        A = np.zeros((12, 12))
        A[0:3, 3:6] = np.eye(3)
        A[3:6, 3:6] = -kD / m * np.eye(3)
        A[3, 6:9] = Tm * np.array([-cp * st * sf + sp * cf, cp * ct * cf, -sp * st * cf + cp * sf])
        A[4, 6:9] = Tm * np.array([-sp * st * sf - cp * cf, sp * ct * cf, cp * st * cf + sp * sf])
        A[5, 6:8] = Tm * np.array([-ct * sf, -st * cf])
        A[6, [6, 7, 9, 10, 11]] = [b * tt, a / (ct * ct), 1.0, sf * tt, cf * tt]
        A[7, [6, 10, 11]] = [-a, cf, -sf]
        A[8, [6, 7, 10, 11]] = [b / ct, a * st / (ct * ct), sf / ct, cf / ct]
        A[9, 10:12] = [-(Iz - Iy) * wr / Ix, -(Iz - Iy) * wq / Ix]
        A[10, [9, 11]] = [-(Ix - Iz) * wr / Iy, -(Ix - Iz) * wp / Iy]
        A[11, 9:11] = [-(Iy - Ix) * wq / Iz, -(Iy - Ix) * wp / Iz]
        return d, A

    def predict(self, x, u, dt):
        """(x_next, F): one RK4 step and its exact Jacobian."""
        eye = np.eye(12)
        xs, x_next, F, J = x, x.copy(), eye.copy(), np.zeros((12, 12))
        for stage, (w, h) in enumerate(((1.0, 0.0), (2.0, 0.5), (2.0, 0.5), (1.0, 1.0))):
            k, A = self.fA(xs, u)
            J = A @ (eye + h * dt * J) if stage else A
            x_next = x_next + dt / 6.0 * w * k
            F = F + dt / 6.0 * w * J
            xs = x + (0.5 if stage < 2 else 1.0) * dt * k
        return x_next, F

    def f(self, x, u, dt):
        return self.predict(x, u, dt)[0]

    def F(self, x, u, dt):
        return self.predict(x, u, dt)[1]

    @staticmethod
    def _rotations(phi, theta, psi):
        """R = Rz(psi) Ry(theta) Rx(phi) and its derivatives by phi, theta, psi."""
        cf, sf, ct, st, cp, sp = np.cos(phi), np.sin(phi), np.cos(theta), np.sin(theta), np.cos(psi), np.sin(psi)
        Rz = np.array([[cp, -sp, 0.0], [sp, cp, 0.0], [0.0, 0.0, 1.0]])
        Ry = np.array([[ct, 0.0, st], [0.0, 1.0, 0.0], [-st, 0.0, ct]])
        Rx = np.array([[1.0, 0.0, 0.0], [0.0, cf, -sf], [0.0, sf, cf]])
        dRz = np.array([[-sp, -cp, 0.0], [cp, -sp, 0.0], [0.0, 0.0, 0.0]])
        dRy = np.array([[-st, 0.0, ct], [0.0, 0.0, 0.0], [-ct, 0.0, -st]])
        dRx = np.array([[0.0, 0.0, 0.0], [0.0, -sf, -cf], [0.0, cf, -sf]])
        return Rz @ Ry @ Rx, (Rz @ Ry @ dRx, Rz @ dRy @ Rx, dRz @ Ry @ Rx)

    def h(self, group, x, u):
        if group == "accel":
            c = self.p[QP_KD] / self.p[QP_MASS]
            out = -c * self._rotations(*x[6:9])[0].T @ x[3:6]
            out[2] += self._wrench(u)[0] / self.p[QP_MASS]
            return out
        return x[{"gyro": 9, "position": 0, "attitude": 6}[group] :][:3].copy()

    def H(self, group, x, u):
        H = np.zeros((3, 12))
        if group == "accel":
            c = self.p[QP_KD] / self.p[QP_MASS]
            R, dR = self._rotations(*x[6:9])
            H[:, 3:6] = -c * R.T
            for a in range(3):
                H[:, 6 + a] = -c * dR[a].T @ x[3:6]
            return H
        base = {"gyro": 9, "position": 0, "attitude": 6}[group]
        H[:, base : base + 3] = np.eye(3)
        return H


@njit(cache=True, error_model="numpy")
def hand_tuned_ekf(p, dt, Q, x0, P0, u, z, fresh, S_out, K_out):
    """x_post (N, 12) of the quadcopter EKF on accel (z columns 0:3, every step), gyro (3:6, every
    step) and position (6:9, where fresh[k, 2]); z has N + 1 rows, the last one the diagonal of R
    (`run_hand_tuned` packs them). With S_out (N, 9, 9) and K_out (N, 12, 9) of N rows (else 0) it
    also stores each step's S and K as logscan's full trace does, NaN where a sensor was not in the
    update: the same outputs, so that the full trace is measured against the same work."""
    N = u.shape[0]
    n = 12
    store = S_out.shape[0] == N
    R_diag = z[N]
    x, P = x0.copy(), P0.copy()
    x_new, kv, xs = np.empty(n), np.empty(n), np.empty(n)
    F, A, J, Jn = np.empty((n, n)), np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    FP, Pn = np.empty((n, n)), np.empty((n, n))
    R3, D3 = np.empty((3, 3)), np.empty((3, 3, 3))
    hx, y, Hs, HP = np.empty(9), np.empty(9), np.zeros((9, n)), np.empty((9, n))
    L, V = np.empty((9, 9)), np.empty((9, n))
    fcols, fnnz = np.empty((n, n), np.int64), np.zeros(n, np.int64)
    hcols, hnnz = np.empty((9, n), np.int64), np.zeros(9, np.int64)
    xs_out = np.empty((N, n))
    for k in range(N):
        uk = u[k]
        if k > 0:
            quad_rk4_predict_into(p, x, uk, dt, x_new, F, kv, xs, A, J, Jn)
            if k == 1:  # F's pattern is the same at every step (the model's block structure)
                for i in range(n):
                    for j in range(n):
                        if F[i, j] != 0.0:
                            fcols[i, fnnz[i]] = j
                            fnnz[i] += 1
            for i in range(n):  # FP = F P
                for j in range(n):
                    FP[i, j] = 0.0
                for s in range(fnnz[i]):
                    c = fcols[i, s]
                    f = F[i, c]
                    for j in range(n):
                        FP[i, j] += f * P[c, j]
            for i in range(n):  # P = FP F^T + Q, lower triangle mirrored
                for j in range(i + 1):
                    t = Q[i, j]
                    for s in range(fnnz[j]):
                        c = fcols[j, s]
                        t += FP[i, c] * F[j, c]
                    Pn[i, j] = t
                    Pn[j, i] = t
            P, Pn = Pn, P
            for i in range(n):
                x[i] = x_new[i]
        m = 6 if not fresh[k, 2] else 9
        quad_meas_into(p, 0, x, uk, 0, hx, Hs, R3, D3, True)
        quad_meas_into(p, 1, x, uk, 3, hx, Hs, R3, D3, True)
        if m == 9:
            quad_meas_into(p, 2, x, uk, 6, hx, Hs, R3, D3, True)
        if k == 0:  # H's pattern: accel's rows, then the selections of gyro and position
            for a in range(9):
                for j in range(n):
                    if a < 3 and 3 <= j < 9 or a >= 3 and j == (9 + a - 3 if a < 6 else a - 6):
                        hcols[a, hnnz[a]] = j
                        hnnz[a] += 1
        for a in range(m):
            y[a] = z[k, a] - hx[a]
            for j in range(n):
                t = 0.0
                for s in range(hnnz[a]):
                    c = hcols[a, s]
                    t += Hs[a, c] * P[c, j]
                HP[a, j] = t
        for a in range(m):  # S = H P H^T + R and its Cholesky factor L, row by row
            for b in range(a + 1):
                t = R_diag[a] if a == b else 0.0
                for s in range(hnnz[b]):
                    c = hcols[b, s]
                    t += HP[a, c] * Hs[b, c]
                if store:
                    S_out[k, a, b] = t
                    S_out[k, b, a] = t
                for c in range(b):
                    t -= L[a, c] * L[b, c]
                L[a, b] = np.sqrt(t) if a == b else t / L[b, b]
        for a in range(m):  # V = L^-1 H P
            for j in range(n):
                t = HP[a, j]
                for c in range(a):
                    t -= L[a, c] * V[c, j]
                V[a, j] = t / L[a, a]
        if store:  # K^T = L^-T V, straight into K; rows and columns of a sensor not updated: NaN
            for a in range(m - 1, -1, -1):
                for j in range(n):
                    t = V[a, j]
                    for c in range(a + 1, m):
                        t -= L[c, a] * K_out[k, j, c]
                    K_out[k, j, a] = t / L[a, a]
            for a in range(m, 9):
                for j in range(n):
                    K_out[k, j, a] = np.nan
                for b in range(9):
                    S_out[k, a, b] = np.nan
                    S_out[k, b, a] = np.nan
        for a in range(m):  # w = L^-1 y
            t = y[a]
            for c in range(a):
                t -= L[a, c] * y[c]
            y[a] = t / L[a, a]
        for a in range(m - 1, -1, -1):  # S^-1 y = L^-T w; then x += K y = (H P)^T S^-1 y
            t = y[a]
            for c in range(a + 1, m):
                t -= L[c, a] * y[c]
            y[a] = t / L[a, a]
        for a in range(m):
            for j in range(n):
                x[j] += HP[a, j] * y[a]
        for i in range(n):  # P -= V^T V, lower triangle mirrored
            for j in range(i + 1):
                t = P[i, j]
                for a in range(m):
                    t -= V[a, i] * V[a, j]
                P[i, j] = t
                P[j, i] = t
        for i in range(n):
            xs_out[k, i] = x[i]
    return xs_out


def run_hand_tuned(model, run, x0, P0, store_gain=False):
    """The hand-tuned filter on the bench's run (accel, gyro at every step, position every tenth):
    x_post, or with ``store_gain`` (x_post, S, K) as logscan's full trace stores S and K."""
    names = ["accel", "gyro", "position"]
    N = run.n_steps
    z = np.empty((N + 1, 9))
    for g, name in enumerate(names):
        z[:N, 3 * g : 3 * g + 3] = run.groups[name].z
        z[N, 3 * g : 3 * g + 3] = np.diag(model.default_R(name))
    fresh = np.column_stack([run.groups[g].fresh for g in names])
    if not (fresh[:, 0].all() and fresh[:, 1].all()):
        raise ValueError("the hand-tuned filter expects accel and gyro at every step")
    for name in names:
        R = model.default_R(name)
        if np.count_nonzero(R - np.diag(np.diag(R))):
            raise ValueError("the hand-tuned filter expects a diagonal R")
    p = model.param_vector(run.dt)
    rows = N if store_gain else 0
    S_out, K_out = np.empty((rows, 9, 9)), np.empty((rows, 12, 9))
    u = np.ascontiguousarray(run.u)
    xs = hand_tuned_ekf(p, run.dt, model.default_Q(run.dt), x0, P0, u, z, fresh, S_out, K_out)
    return (xs, S_out, K_out) if store_gain else xs


follow_dependencies(__name__)
