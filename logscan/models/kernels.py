"""Numba functions of every vehicle model and their dispatch on (model_id, group_id).

All models' discrete `f`, Jacobian `F`, measurement `h` and Jacobian `H` live here as
`@njit(cache=True)` functions that read a packed float64 parameter vector `p` (built by each
model's `param_vector`). The EKF kernel calls only the two in-place dispatchers at the bottom
(`predict_into`, `meas_into`: in-place, no allocation), so one cached kernel serves every model;
`predict`, `f_disc`, `h_meas`, `H_meas` are the allocating versions (simulator, numpy views).

Model ids: 0 quadcopter, 1 steer_by_wire, 2 dc_motor, 3 linear (2 and 3 share the linear code:
the dc_motor model packs its exactly discretised A, B, C like a linear model).

Continuous-time nonlinear models are discretised with one RK4 step per grid period; the discrete
Jacobian F is the exact derivative of that RK4 step, obtained by propagating the continuous
Jacobian A through the four stages (dk_i/dx = A(x_i) dx_i/dx).
"""

from __future__ import annotations

import numpy as np
from numba import njit

QUADCOPTER_ID = 0
STEER_BY_WIRE_ID = 1
DC_MOTOR_ID = 2
LINEAR_ID = 3

# ---- quadcopter parameter layout ------------------------------------------------------------
QP_MASS, QP_G, QP_KD, QP_IX, QP_IY, QP_IZ, QP_ARM, QP_KT, QP_BTAU, QP_INPUT_MODE = range(10)
QUAD_N_PARAMS = 10

# ---- steer-by-wire parameter layout ---------------------------------------------------------
(SP_JEQ, SP_BEQ, SP_FS, SP_CF, SP_CR, SP_LF, SP_LR, SP_LC, SP_LP, SP_M, SP_IZ, SP_V,
 SP_VS) = range(13)
SBW_N_PARAMS = 13


# =============================================================================================
# quadcopter
# =============================================================================================
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
def quad_rotation(phi, theta, psi):
    """Body-to-world rotation R = Rz(psi) Ry(theta) Rx(phi) (ZYX Euler angles)."""
    R = np.empty((3, 3))
    quad_rotation_into(phi, theta, psi, R)
    return R


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
def quad_rotation_derivatives(phi, theta, psi):
    """dR/dphi, dR/dtheta, dR/dpsi of R = Rz Ry Rx, stacked as (3, 3, 3)."""
    D = np.empty((3, 3, 3))
    quad_rotation_derivatives_into(phi, theta, psi, D)
    return D


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
    quad_meas_into(p, gid, x, u, 0, out, np.empty((0, 0)), np.empty((3, 3)),
                   np.empty((3, 3, 3)), False)
    return out


@njit(cache=True)
def quad_H(p, gid, x, u):
    H = np.zeros((3, 12))
    quad_meas_into(p, gid, x, u, 0, np.empty(3), H, np.empty((3, 3)), np.empty((3, 3, 3)),
                   True)
    return H


# =============================================================================================
# steer-by-wire (front-wheel subsystem + single-track vehicle)
# =============================================================================================
@njit(cache=True)
def sbw_fA(p, x, u, d, A, want_A):
    """Jeq d2_dd + Beq d_dot + Fs tanh(d_dot/vs) + tau_e = tau_eq, with the self-aligning torque
    tau_e = Cf (lc + lp) (delta_f - beta - lf gamma / V); bicycle model for beta and gamma.
    A: the paper's section V.B Jacobian, with d tanh(d_dot/vs)/d d_dot in place of the sign's."""
    Jeq, Beq, Fs = p[SP_JEQ], p[SP_BEQ], p[SP_FS]
    Cf, Cr, lf, lr = p[SP_CF], p[SP_CR], p[SP_LF], p[SP_LR]
    lt = p[SP_LC] + p[SP_LP]
    M, Iz, V, vs = p[SP_M], p[SP_IZ], p[SP_V], p[SP_VS]
    delta, dd, beta, gamma = x[0], x[1], x[2], x[3]
    th = np.tanh(dd / vs)
    a22 = -(Cf + Cr) / (M * V)
    a23 = -1.0 + (Cr * lr - Cf * lf) / (M * V * V)
    a32 = (Cr * lr - Cf * lf) / Iz
    a33 = -(Cr * lr * lr + Cf * lf * lf) / (Iz * V)
    d[0] = dd
    tau_e = Cf * lt * (delta - beta - lf * gamma / V)
    d[1] = (u[0] - Beq * dd - Fs * th - tau_e) / Jeq
    d[2] = a22 * beta + a23 * gamma + Cf / (M * V) * delta
    d[3] = a32 * beta + a33 * gamma + Cf * lf / Iz * delta
    if not want_A:
        return
    A[:, :] = 0.0
    A[0, 1] = 1.0
    A[1, 0] = -Cf * lt / Jeq
    A[1, 1] = -(Beq + Fs * (1.0 - th * th) / vs) / Jeq
    A[1, 2] = Cf * lt / Jeq
    A[1, 3] = Cf * lt * lf / (Jeq * V)
    A[2, 0] = Cf / (M * V)
    A[2, 2] = a22
    A[2, 3] = a23
    A[3, 0] = Cf * lf / Iz
    A[3, 2] = a32
    A[3, 3] = a33


@njit(cache=True)
def sbw_H_row_into(p, gid, Hs, r):
    """Groups: 0 steering_angle (delta_f), 1 yaw_rate (gamma),
    2 lateral_accel a_y = V (beta_dot + gamma) (linear in the state): H into row r of Hs."""
    for j in range(4):
        Hs[r, j] = 0.0
    if gid == 0:
        Hs[r, 0] = 1.0
    elif gid == 1:
        Hs[r, 3] = 1.0
    else:
        Cf, Cr, lf, lr = p[SP_CF], p[SP_CR], p[SP_LF], p[SP_LR]
        M, V = p[SP_M], p[SP_V]
        Hs[r, 0] = Cf / M
        Hs[r, 2] = -(Cf + Cr) / M
        Hs[r, 3] = (Cr * lr - Cf * lf) / (M * V)


@njit(cache=True)
def sbw_H(p, gid, x, u):
    H = np.zeros((1, 4))
    sbw_H_row_into(p, gid, H, 0)
    return H


@njit(cache=True)
def sbw_h(p, gid, x, u):
    H = sbw_H(p, gid, x, u)
    return H @ x


# =============================================================================================
# linear (also dc_motor): p = [n, nu, G, group_start[G], Ad (n*n), Bd (n*nu), groups...],
# each group block = [m, C (m*n), D (m*nu)]
# =============================================================================================
@njit(cache=True)
def lin_dims(p):
    return int(p[0]), int(p[1]), int(p[2])


@njit(cache=True)
def lin_AB(p):
    n, nu, G = lin_dims(p)
    a0 = 3 + G
    Ad = p[a0:a0 + n * n].reshape((n, n))
    Bd = p[a0 + n * n:a0 + n * n + n * nu].reshape((n, nu))
    return Ad, Bd


@njit(cache=True)
def lin_CD(p, gid):
    n, nu, G = lin_dims(p)
    s = int(p[3 + gid])
    m = int(p[s])
    C = p[s + 1:s + 1 + m * n].reshape((m, n))
    D = p[s + 1 + m * n:s + 1 + m * n + m * nu].reshape((m, nu))
    return C, D


@njit(cache=True)
def lin_f(p, x, u):
    Ad, Bd = lin_AB(p)
    # x_k = Ad x_{k-1} + Bd u_k
    return Ad @ x + Bd @ u


@njit(cache=True)
def lin_h(p, gid, x, u):
    C, D = lin_CD(p, gid)
    # z = C x + D u
    return C @ x + D @ u


@njit(cache=True)
def lin_H(p, gid, x, u):
    C, D = lin_CD(p, gid)
    return C.copy()


@njit(cache=True)
def lin_meas_into(p, gid, x, u, r, hx, Hs):
    """z = C x + D u of group gid into hx[r:r+m], C into Hs[r:r+m, :] (no allocation)."""
    n, nu, G = lin_dims(p)
    s = int(p[3 + gid])
    m = int(p[s])
    c0 = s + 1
    d0 = c0 + m * n
    for i in range(m):
        t = 0.0
        for j in range(n):
            C_ij = p[c0 + i * n + j]
            Hs[r + i, j] = C_ij
            t += C_ij * x[j]
        for j in range(nu):
            t += p[d0 + i * nu + j] * u[j]
        hx[r + i] = t


@njit(cache=True)
def lin_predict_into(p, x, u, x_next, F):
    """x_next = Ad x + Bd u and F = Ad (no allocation)."""
    n, nu, G = lin_dims(p)
    a0 = 3 + G
    b0 = a0 + n * n
    for i in range(n):
        t = 0.0
        for j in range(n):
            A_ij = p[a0 + i * n + j]
            F[i, j] = A_ij
            t += A_ij * x[j]
        for j in range(nu):
            t += p[b0 + i * nu + j] * u[j]
        x_next[i] = t


# =============================================================================================
# RK4 with its exact Jacobian, and the dispatchers
# =============================================================================================
@njit(cache=True)
def cont_fA(model_id, p, x, u, d, A, want_A):
    if model_id == QUADCOPTER_ID:
        quad_fA(p, x, u, d, A, want_A)
    else:
        sbw_fA(p, x, u, d, A, want_A)


@njit(cache=True)
def rk4_predict_into(model_id, p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """One RK4 step x_next and its exact Jacobian F = d x_next / d x, into x_next and F.

    Stages x1 = x, x2 = x + dt/2 k1, x3 = x + dt/2 k2, x4 = x + dt k3 with k_i = f_c(x_i); with
    dk_i/dx = J_i: J1 = A(x1), J2 = A(x2) (I + dt/2 J1), J3 = A(x3) (I + dt/2 J2),
    J4 = A(x4) (I + dt J3); x_next = x + dt/6 (k1 + 2 k2 + 2 k3 + k4),
    F = I + dt/6 (J1 + 2 J2 + 2 J3 + J4).
    kv, xs (n,) and A, J, Jn (n, n) are work arrays; the products skip the zeros of the sparse
    continuous Jacobian A.
    """
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


@njit(cache=True)
def _quad_blk(Jn, F, A, J, r0, c0, qd, qa, qb, h, cw, acc, first):
    """One 3x3 block (rows r0.., cols c0..) of a stage Jacobian Jn = A + h A J (= A (I + h J))
    and its RK4 weight into F: F_blk (= or +=) cw Jn_blk. With acc, the terms of h A J are those
    of the non-zero blocks of A in the block row: a diagonal block at column qd and full blocks
    at columns qa, qb (-1: none), summed in increasing column order as the generic loop does."""
    for i in range(3):
        r = r0 + i
        if acc and qd >= 0:
            ad = h * A[r, qd + i]
        if acc and qa >= 0:
            a0 = h * A[r, qa]
            a1 = h * A[r, qa + 1]
            a2 = h * A[r, qa + 2]
        if acc and qb >= 0:
            b0 = h * A[r, qb]
            b1 = h * A[r, qb + 1]
            b2 = h * A[r, qb + 2]
        for j in range(3):
            c = c0 + j
            s = A[r, c]
            if acc:
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
            if first:
                F[r, c] = cw * s
            else:
                F[r, c] += cw * s


@njit(cache=True)
def _quad_stage_jacobian(Jn, F, A, J, h, cw, acc, first):
    """All nine non-zero 3x3 blocks of Jn = A (I + h J) and their weight into F (quadcopter)."""
    # pos rows: A = [0, I, 0, 0];  vel rows: [0, Dv, Va, 0] (Dv diagonal)
    _quad_blk(Jn, F, A, J, 0, 3, 3, -1, -1, h, cw, acc, first)
    _quad_blk(Jn, F, A, J, 0, 6, 3, -1, -1, h, cw, acc, first)
    _quad_blk(Jn, F, A, J, 0, 9, 3, -1, -1, h, cw, acc, first)
    _quad_blk(Jn, F, A, J, 3, 3, 3, -1, -1, h, cw, acc, first)
    _quad_blk(Jn, F, A, J, 3, 6, 3, 6, -1, h, cw, acc, first)
    _quad_blk(Jn, F, A, J, 3, 9, 3, 6, -1, h, cw, acc, first)
    # att rows: [0, 0, Ea, Wr];  rate rows: [0, 0, 0, Or]
    _quad_blk(Jn, F, A, J, 6, 6, -1, 6, -1, h, cw, acc, first)
    _quad_blk(Jn, F, A, J, 6, 9, -1, 6, 9, h, cw, acc, first)
    _quad_blk(Jn, F, A, J, 9, 9, -1, 9, -1, h, cw, acc, first)


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
    for i in range(3, 12):  # the zero blocks of F: block column 0 and below the block diagonal
        for j in range(3 if i < 6 else (6 if i < 9 else 9)):
            F[i, j] = 0.0
    for i in range(3):
        F[i, 0] = F[i, 1] = F[i, 2] = 0.0
    for stage in range(4):
        quad_fA_nonzeros(p, xs, u, kv, A, True)
        cw = c * (1.0 if stage == 0 or stage == 3 else 2.0)
        h = 0.5 * dt if stage < 3 else dt
        step = 0.5 * dt if stage < 2 else dt
        # J_i = A_i + h A_i J_{i-1};  F += cw J_i (F = cw J_1 in stage 0)
        if stage == 0:
            _quad_stage_jacobian(Jn, F, A, J, h, cw, False, True)
        else:
            _quad_stage_jacobian(Jn, F, A, J, h, cw, True, False)
        for i in range(12):
            x_next[i] += cw * kv[i]
            xs[i] = x[i] + step * kv[i]
        J, Jn = Jn, J
    for i in range(12):
        F[i, i] += 1.0


@njit(cache=True)
def rk4_predict(model_id, p, x, u, dt):
    """One RK4 step x_next and its exact Jacobian F (allocating wrapper of rk4_predict_into)."""
    n = x.size
    x_next = np.empty(n)
    F = np.empty((n, n))
    rk4_predict_into(model_id, p, x, u, dt, x_next, F, np.empty(n), np.empty(n),
                     np.empty((n, n)), np.empty((n, n)), np.empty((n, n)))
    return x_next, F


@njit(cache=True)
def rk4_f(model_id, p, x, u, dt):
    """The RK4 step alone (no Jacobian): the simulator's truth propagation."""
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


@njit(cache=True)
def predict(model_id, p, x, u, dt):
    """(f(x, u), F(x, u)) of the discrete model `model_id`."""
    if model_id == DC_MOTOR_ID or model_id == LINEAR_ID:
        Ad, Bd = lin_AB(p)
        return lin_f(p, x, u), Ad.copy()
    return rk4_predict(model_id, p, x, u, dt)


@njit(cache=True)
def predict_into(model_id, p, x, u, dt, x_next, F, kv, xs, A, J, Jn):
    """predict() without allocation: f(x, u) into x_next, F(x, u) into F (kv, xs (n,) and
    A, J, Jn (n, n) are work arrays)."""
    if model_id == DC_MOTOR_ID or model_id == LINEAR_ID:
        lin_predict_into(p, x, u, x_next, F)
    elif model_id == QUADCOPTER_ID:
        quad_rk4_predict_into(p, x, u, dt, x_next, F, kv, xs, A, J, Jn)
    else:
        rk4_predict_into(model_id, p, x, u, dt, x_next, F, kv, xs, A, J, Jn)


@njit(cache=True)
def f_disc(model_id, p, x, u, dt):
    if model_id == DC_MOTOR_ID or model_id == LINEAR_ID:
        return lin_f(p, x, u)
    return rk4_f(model_id, p, x, u, dt)


@njit(cache=True)
def h_meas(model_id, gid, p, x, u):
    if model_id == QUADCOPTER_ID:
        return quad_h(p, gid, x, u)
    if model_id == STEER_BY_WIRE_ID:
        return sbw_h(p, gid, x, u)
    return lin_h(p, gid, x, u)


@njit(cache=True)
def H_meas(model_id, gid, p, x, u):
    if model_id == QUADCOPTER_ID:
        return quad_H(p, gid, x, u)
    if model_id == STEER_BY_WIRE_ID:
        return sbw_H(p, gid, x, u)
    return lin_H(p, gid, x, u)


@njit(cache=True)
def meas_into(model_id, gid, p, x, u, r, hx, Hs, R3, D3):
    """h_meas and H_meas without allocation: h of group gid into hx[r:r+m], H into
    Hs[r:r+m, :] (R3 (3, 3) and D3 (3, 3, 3) are the quadcopter's work arrays)."""
    if model_id == QUADCOPTER_ID:
        quad_meas_into(p, gid, x, u, r, hx, Hs, R3, D3, True)
    elif model_id == STEER_BY_WIRE_ID:
        sbw_H_row_into(p, gid, Hs, r)
        t = 0.0
        for j in range(4):
            t += Hs[r, j] * x[j]
        hx[r] = t
    else:
        lin_meas_into(p, gid, x, u, r, hx, Hs)
