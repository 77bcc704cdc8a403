"""Numba functions of the quadcopter model: dynamics, Jacobian, measurements, block RK4 step.

Shapes: p (QUAD_N_PARAMS,) packed by `Quadcopter.param_vector` (layout QP_* below), x (12,),
u (4,) (wrench or motor speeds, QP_INPUT_MODE), continuous d (12,) and A (12, 12); measurements
write rows r:r+3 of hx (m,) and Hs (m, 12); R (3, 3) and D (3, 3, 3) are rotation work arrays.
The block RK4 step is the generic one of `logscan.models.rk4` restricted to the non-zero 3x3
blocks of the quadcopter's continuous Jacobian (equal to the last bit).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from logscan.models.model_kernels import ModelKernels, additive_boxplus_into, register
from logscan.models.rk4 import rk4_f, rk4_predict
from logscan.numba_cache import follow_dependencies

QUADCOPTER_ID = 0  # its registered id (logscan.models.model_kernels)

# ---- parameter layout -------------------------------------------------------------------------
QP_MASS, QP_G, QP_KD, QP_IX, QP_IY, QP_IZ, QP_ARM, QP_KT, QP_BTAU, QP_INPUT_MODE = range(10)
QUAD_N_PARAMS = 10


@njit(cache=True)
def quad_wrench(p, u):
    """Collective thrust and body torques from the input (wrench, or motor speeds via the mixer).

    Mixer (plus configuration, motor i on the body arm at angle (i-1)*90 deg from +x):
    T_i = kT w_i^2; T = sum T_i; tau_x = L (T2 - T4); tau_y = L (T3 - T1);
    tau_z = b (T1 - T2 + T3 - T4) (motors 1 and 3 give +z reaction torque).
    """
    if p[QP_INPUT_MODE] == 0.0:
        return u[0], u[1], u[2], u[3]
    kT = p[QP_KT]
    L = p[QP_ARM]
    b = p[QP_BTAU]
    T1 = kT * u[0] * u[0]
    T2 = kT * u[1] * u[1]
    T3 = kT * u[2] * u[2]
    T4 = kT * u[3] * u[3]
    return T1 + T2 + T3 + T4, L * (T2 - T4), L * (T3 - T1), b * (T1 - T2 + T3 - T4)


@njit(cache=True)
def quad_rotation_into(phi, theta, psi, R):
    """Body-to-world rotation R = Rz(psi) Ry(theta) Rx(phi) (ZYX Euler angles), into R (3, 3)."""
    cf, sf = np.cos(phi), np.sin(phi)
    ct, st = np.cos(theta), np.sin(theta)
    cp, sp = np.cos(psi), np.sin(psi)
    R[0, 0] = cp * ct
    R[0, 1] = cp * st * sf - sp * cf
    R[0, 2] = cp * st * cf + sp * sf
    R[1, 0] = sp * ct
    R[1, 1] = sp * st * sf + cp * cf
    R[1, 2] = sp * st * cf - cp * sf
    R[2, 0] = -st
    R[2, 1] = ct * sf
    R[2, 2] = ct * cf


@njit(cache=True)
def quad_rotation_derivatives_into(phi, theta, psi, D):
    """dR/dphi, dR/dtheta, dR/dpsi of R = Rz Ry Rx, stacked into D (3, 3, 3)."""
    cf, sf = np.cos(phi), np.sin(phi)
    ct, st = np.cos(theta), np.sin(theta)
    cp, sp = np.cos(psi), np.sin(psi)
    # d/dphi
    D[0, 0, 0] = 0.0
    D[0, 0, 1] = cp * st * cf + sp * sf
    D[0, 0, 2] = -cp * st * sf + sp * cf
    D[0, 1, 0] = 0.0
    D[0, 1, 1] = sp * st * cf - cp * sf
    D[0, 1, 2] = -sp * st * sf - cp * cf
    D[0, 2, 0] = 0.0
    D[0, 2, 1] = ct * cf
    D[0, 2, 2] = -ct * sf
    # d/dtheta
    D[1, 0, 0] = -cp * st
    D[1, 0, 1] = cp * ct * sf
    D[1, 0, 2] = cp * ct * cf
    D[1, 1, 0] = -sp * st
    D[1, 1, 1] = sp * ct * sf
    D[1, 1, 2] = sp * ct * cf
    D[1, 2, 0] = -ct
    D[1, 2, 1] = -st * sf
    D[1, 2, 2] = -st * cf
    # d/dpsi
    D[2, 0, 0] = -sp * ct
    D[2, 0, 1] = -sp * st * sf - cp * cf
    D[2, 0, 2] = -sp * st * cf + cp * sf
    D[2, 1, 0] = cp * ct
    D[2, 1, 1] = cp * st * sf - sp * cf
    D[2, 1, 2] = cp * st * cf + sp * sf
    D[2, 2, 0] = 0.0
    D[2, 2, 1] = 0.0
    D[2, 2, 2] = 0.0


@njit(cache=True)
def quad_fA(p, x, u, d, A, want_A):
    """quad_fA_nonzeros with A zeroed first (the whole continuous Jacobian A = df_c/dx)."""
    if want_A:
        A[:, :] = 0.0
    quad_fA_nonzeros(p, x, u, d, A, want_A)


@njit(cache=True)
def quad_fA_nonzeros(p, x, u, d, A, want_A):
    """Continuous dynamics d = f_c(x, u) (paper eq. 5 with Euler-angle kinematics) and, when
    want_A, its Jacobian A = df_c/dx (the paper's F_k entries plus the kinematics terms),
    written only at its non-zero entries (the same ones on every call; the caller zeroes A):
    p_dot = v;  v_dot = R e3 T/m - g e3 - kD v/m;  eta_dot = W(phi, theta) omega;
    omega_dot = I^-1 (tau - omega x I omega)."""
    T, tx, ty, tz = quad_wrench(p, u)
    m, g, kD = p[QP_MASS], p[QP_G], p[QP_KD]
    Ix, Iy, Iz = p[QP_IX], p[QP_IY], p[QP_IZ]
    phi, theta, psi = x[6], x[7], x[8]
    wp, wq, wr = x[9], x[10], x[11]
    cf, sf = np.cos(phi), np.sin(phi)
    ct, st = np.cos(theta), np.sin(theta)
    cp, sp = np.cos(psi), np.sin(psi)
    tt = st / ct
    a = sf * wq + cf * wr
    b = cf * wq - sf * wr
    Tm = T / m
    d[0] = x[3]
    d[1] = x[4]
    d[2] = x[5]
    d[3] = Tm * (cp * st * cf + sp * sf) - kD * x[3] / m
    d[4] = Tm * (sp * st * cf - cp * sf) - kD * x[4] / m
    d[5] = Tm * (ct * cf) - g - kD * x[5] / m
    d[6] = wp + a * tt
    d[7] = b
    d[8] = a / ct
    d[9] = (tx - (Iz - Iy) * wq * wr) / Ix
    d[10] = (ty - (Ix - Iz) * wp * wr) / Iy
    d[11] = (tz - (Iy - Ix) * wp * wq) / Iz
    if not want_A:
        return
    A[0, 3] = 1.0
    A[1, 4] = 1.0
    A[2, 5] = 1.0
    A[3, 6] = Tm * (-cp * st * sf + sp * cf)
    A[3, 7] = Tm * (cp * ct * cf)
    A[3, 8] = Tm * (-sp * st * cf + cp * sf)
    A[4, 6] = Tm * (-sp * st * sf - cp * cf)
    A[4, 7] = Tm * (sp * ct * cf)
    A[4, 8] = Tm * (cp * st * cf + sp * sf)
    A[5, 6] = Tm * (-ct * sf)
    A[5, 7] = Tm * (-st * cf)
    A[3, 3] = -kD / m
    A[4, 4] = -kD / m
    A[5, 5] = -kD / m
    # phi_dot = p + a tan(theta)
    A[6, 6] = b * tt
    A[6, 7] = a / (ct * ct)
    A[6, 9] = 1.0
    A[6, 10] = sf * tt
    A[6, 11] = cf * tt
    # theta_dot = b
    A[7, 6] = -a
    A[7, 10] = cf
    A[7, 11] = -sf
    # psi_dot = a / cos(theta)
    A[8, 6] = b / ct
    A[8, 7] = a * st / (ct * ct)
    A[8, 10] = sf / ct
    A[8, 11] = cf / ct
    # Euler's equations
    A[9, 10] = -(Iz - Iy) * wr / Ix
    A[9, 11] = -(Iz - Iy) * wq / Ix
    A[10, 9] = -(Ix - Iz) * wr / Iy
    A[10, 11] = -(Ix - Iz) * wp / Iy
    A[11, 9] = -(Iy - Ix) * wq / Iz
    A[11, 10] = -(Iy - Ix) * wp / Iz


@njit(cache=True)
def quad_meas_into(p, gid, x, u, r, hx, Hs, R, D, want_H):
    """Groups: 0 accel a_b = R^T (v_dot + g e3) = [0, 0, T/m] - (kD/m) R^T v; 1 gyro (p, q, r);
    2 position (x, y, z); 3 attitude (roll, pitch, yaw). h into hx[r:r+3] and, when want_H,
    H = dh/dx into Hs[r:r+3, :]; R (3, 3) and D (3, 3, 3) are work arrays."""
    if want_H:
        for i in range(3):
            for j in range(12):
                Hs[r + i, j] = 0.0
    if gid == 0:
        T, tx, ty, tz = quad_wrench(p, u)
        c = p[QP_KD] / p[QP_MASS]
        quad_rotation_into(x[6], x[7], x[8], R)
        for i in range(3):
            hx[r + i] = -c * (R[0, i] * x[3] + R[1, i] * x[4] + R[2, i] * x[5])
        hx[r + 2] += T / p[QP_MASS]
        if not want_H:
            return
        quad_rotation_derivatives_into(x[6], x[7], x[8], D)
        for i in range(3):
            for j in range(3):
                Hs[r + i, 3 + j] = -c * R[j, i]  # d(R^T v)_i / dv_j = R[j, i]
            for a in range(3):
                s = 0.0
                for j in range(3):
                    s += D[a, j, i] * x[3 + j]
                Hs[r + i, 6 + a] = -c * s
    else:
        base = 9 if gid == 1 else (0 if gid == 2 else 6)
        for i in range(3):
            hx[r + i] = x[base + i]
            if want_H:
                Hs[r + i, base + i] = 1.0


@njit(cache=True)
def quad_h(p, gid, x, u):
    out = np.empty(3)
    quad_meas_into(p, gid, x, u, 0, out, np.empty((0, 0)), np.empty((3, 3)), np.empty((3, 3, 3)), False)
    return out


@njit(cache=True)
def quad_H(p, gid, x, u):
    H = np.zeros((3, 12))
    quad_meas_into(p, gid, x, u, 0, np.empty(3), H, np.empty((3, 3)), np.empty((3, 3, 3)), True)
    return H


# =============================================================================================
# RK4 step with its exact Jacobian on the 3x3 blocks
# =============================================================================================
@njit(cache=True, no_cpython_wrapper=True)
def _quad_blk(Jn, F, A, J, r0, c0, qd, qa, qb, h, cw):
    """One 3x3 block (rows r0.., cols c0..) of a stage Jacobian Jn = A + h A J (= A (I + h J))
    and its RK4 weight into F: F_blk += cw Jn_blk. The terms of h A J are those of the non-zero
    blocks of A in the block row: a diagonal block at column qd and full blocks at columns qa, qb
    (-1: none), summed in increasing column order as the generic loop does. (Stage 1 passes J = 0:
    Jn = A exactly, up to the sign of a zero.)"""
    for i in range(3):
        r = r0 + i
        ad = h * A[r, qd + i] if qd >= 0 else 0.0
        a0 = a1 = a2 = b0 = b1 = b2 = 0.0
        if qa >= 0:
            a0 = h * A[r, qa]
            a1 = h * A[r, qa + 1]
            a2 = h * A[r, qa + 2]
        if qb >= 0:
            b0 = h * A[r, qb]
            b1 = h * A[r, qb + 1]
            b2 = h * A[r, qb + 2]
        for j in range(3):
            c = c0 + j
            s = A[r, c]
            if qd >= 0:
                s += ad * J[qd + i, c]
            if qa >= 0:
                s += a0 * J[qa, c]
                s += a1 * J[qa + 1, c]
                s += a2 * J[qa + 2, c]
            if qb >= 0:
                s += b0 * J[qb, c]
                s += b1 * J[qb + 1, c]
                s += b2 * J[qb + 2, c]
            Jn[r, c] = s
            F[r, c] += cw * s


# the nine non-zero 3x3 blocks of a stage Jacobian, as (r0, c0, qd, qa, qb) of `_quad_blk`:
# pos rows: A = [0, I, 0, 0];  vel rows: [0, Dv, Va, 0] (Dv diagonal);
# att rows: [0, 0, Ea, Wr];  rate rows: [0, 0, 0, Or]
QUAD_BLOCKS = np.array(
    [
        [0, 3, 3, -1, -1],
        [0, 6, 3, -1, -1],
        [0, 9, 3, -1, -1],
        [3, 3, 3, -1, -1],
        [3, 6, 3, 6, -1],
        [3, 9, 3, 6, -1],
        [6, 6, -1, 6, -1],
        [6, 9, -1, 6, 9],
        [9, 9, -1, 9, -1],
    ],
    dtype=np.int64,
)


@njit(cache=True, no_cpython_wrapper=True)
def _quad_stage_jacobian(Jn, F, A, J, h, cw):
    """All nine non-zero 3x3 blocks of Jn = A (I + h J) and their weight into F (quadcopter)."""
    # block indices from an array, not literals, and no stage flags: literal arguments would
    # compile _quad_blk once per block and stage kind (18 specialisations, a third of the
    # quadcopter's cold compile) for a few per cent per step
    for b in range(QUAD_BLOCKS.shape[0]):
        blk = QUAD_BLOCKS[b]
        _quad_blk(Jn, F, A, J, blk[0], blk[1], blk[2], blk[3], blk[4], h, cw)


@njit(cache=True)
def quad_rk4_predict_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """rk4_predict_into for the quadcopter, on the 3x3 blocks of its continuous Jacobian.

    Blocks of the states (pos | vel | att | rates): A = [[0, I, 0, 0], [0, Dv, Va, 0],
    [0, 0, Ea, Wr], [0, 0, 0, Or]] (quad_fA; Dv = -kD/m I diagonal): block upper triangular with
    a zero first block column, so every stage Jacobian J_i = A_i (I + h J_{i-1}) has the same nine
    non-zero blocks (0,1) (0,2) (0,3) (1,1) (1,2) (1,3) (2,2) (2,3) (3,3); only those are
    computed, with the generic path's sums in its order (F and x_next equal to the last bit).
    """
    c = dt / 6.0
    for i in range(12):
        x_next[i] = x[i]
        xs[i] = x[i]
        for j in range(12):
            A[i, j] = 0.0
    for i in range(12):  # F accumulates the stages' weighted Jacobians; J_0 = 0 (Jn = A in stage 1)
        for j in range(12):
            F[i, j] = 0.0
            J[i, j] = 0.0
    for stage in range(4):
        quad_fA_nonzeros(p, xs, u, kv, A, True)
        cw = c * (1.0 if stage == 0 or stage == 3 else 2.0)
        h = 0.5 * dt if stage < 3 else dt
        step = 0.5 * dt if stage < 2 else dt
        # J_i = A_i + h A_i J_{i-1};  F += cw J_i
        _quad_stage_jacobian(Jn, F, A, J, h, cw)
        for i in range(12):
            x_next[i] += cw * kv[i]
            xs[i] = x[i] + step * kv[i]
        J, Jn = Jn, J
    for i in range(12):
        F[i, i] += 1.0


@njit(cache=True)
def quad_predict(p, x, u, dt):
    """(f(x, u), F(x, u)) by the generic RK4 step (allocating)."""
    return rk4_predict(QUADCOPTER_ID, p, x, u, dt)


@njit(cache=True)
def quad_f(p, x, u, dt):
    """f(x, u): the RK4 step alone (the simulator's truth)."""
    return rk4_f(QUADCOPTER_ID, p, x, u, dt)


@njit(cache=True, inline="always")
def quad_step_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """predict_into of the quadcopter (RK4 on the 3x3 blocks of its Jacobian)."""
    quad_rk4_predict_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn)


@njit(cache=True, inline="always")
def quad_meas_rows_into(gid, p, x, u, r, hx, Hs, R3, D3):
    """meas_into of the quadcopter."""
    quad_meas_into(p, gid, x, u, r, hx, Hs, R3, D3, True)


register(
    ModelKernels(
        QUADCOPTER_ID,
        "quadcopter",
        predict=quad_predict,
        f_disc=quad_f,
        h_meas=quad_h,
        H_meas=quad_H,
        predict_into=quad_step_into,
        meas_into=quad_meas_rows_into,
        boxplus_into=additive_boxplus_into,
        fA=quad_fA,
    )
)
follow_dependencies(__name__)
