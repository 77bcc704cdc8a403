"""The closed-loop simulation kernel (numba): truth, actuators, sensors, faults, on-board EKF.

One step k (period dt, x_k = f(x_{k-1}, u_k) + w_k as the models define it):
  1. controller: u_k from the on-board posterior estimate of step k-1 (never the true state);
     control faults act on u_k (the vehicle logs and flies the faulty output);
     actuators: a = M^-1 u clipped to the actuators' limits, u_cmd = M a (logged command);
  2. actuator faults act on a (on the actuator's total a_trim + a when the inputs are deviations
     from an operating point a_trim, the hover_uav's rotor thrusts; zero otherwise); the truth is
     driven by u_act = M a_faulty:
     x_k = f(x_{k-1}, u_act) + w_k, w_k ~ N(0, Q) (the model's own Q, so an analysis filter with
     the model's defaults is consistent with the simulator);
  3. each measurement group samples every `ratio` steps: z = h(x_k, u_act) + v, v ~ N(0, s^2) with
     s = base + slope |h| per channel (slope 0: the model's noise_std; the dc_motor's speed sensors
     grow noisier with the speed);
     sensor faults act on the sampled value (what the log records);
  4. on-board EKF (what a real autopilot runs, its state and variance logged): predict with the
     commanded u, one stacked update with the fresh groups, skipping a group with a non-finite or
     out-of-range sample (counted);
     state-corruption faults then corrupt its posterior.
The kernel uses the model's numba functions (`logscan.models.dispatch`), so truth and filters share
one model. All random draws (w, v, fault draws) are made before the loop from one seeded
generator, which makes a run a pure function of its seed.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from logscan.models.dispatch import H_meas, f_disc, h_meas, predict
from logscan.numba_cache import follow_dependencies
from logscan.simulate.controllers import control
from logscan.simulate.faults import (
    ACT_OFFSET,
    BIAS,
    BITFLIP,
    CTRL_GAIN,
    CTRL_STUCK,
    DRIFT,
    LOST_ACT,
    RANDOM,
    STATE_CORRUPT,
    STUCK,
)


@njit(cache=True)
def _bitflip(value, bit):
    """Flip bit ``bit`` of the float32 representation of ``value``."""
    buf = np.empty(1, dtype=np.float32)
    buf[0] = value
    bits = buf.view(np.uint32)
    bits[0] = bits[0] ^ np.uint32(1 << bit)
    return np.float64(buf[0])


@njit(cache=True)
def _sensor_faults(k, c, z, dt, f_kind, f_target, f_start, f_end, f_mag, f_unif, f_bit, stuck):
    """Value of channel ``c`` at step ``k`` after every sensor fault active on it."""
    for i in range(f_kind.size):
        if f_target[i] != c or k < f_start[i] or k >= f_end[i]:
            continue
        kind = f_kind[i]
        if kind == BIAS:
            z = z + f_mag[i]
        elif kind == DRIFT:
            z = z + f_mag[i] * (k - f_start[i]) * dt
        elif kind == RANDOM:
            z = z + f_mag[i] * (2.0 * f_unif[i, k] - 1.0)
        elif kind == BITFLIP:
            if f_unif[i, k] < f_mag[i]:
                z = _bitflip(z, f_bit[i, k])
        elif kind == STUCK:
            z = stuck[i]
    return z


@njit(cache=True)
def _control_faults(k, u, u_last, f_kind, f_target, f_start, f_end, f_mag, held):
    """Apply the control faults active at step ``k`` to the controller's output ``u`` (in place),
    then remember it in ``u_last``: a control-stuck fault holds the output of the step before its
    start."""
    for i in range(f_kind.size):
        if f_kind[i] == CTRL_STUCK and k == f_start[i]:
            held[i] = u_last[f_target[i]]
        if k < f_start[i] or k >= f_end[i]:
            continue
        if f_kind[i] == CTRL_GAIN:
            u[f_target[i]] *= 1.0 + f_mag[i]
        elif f_kind[i] == CTRL_STUCK:
            u[f_target[i]] = held[i]
    u_last[:] = u


@njit(cache=True)
def closed_loop(
    model_id,
    p,
    p_true,
    dt,
    x0,
    P0,
    Q,
    W,
    E,
    noise_base,
    noise_slope,
    g_id,
    g_m,
    g_off,
    g_ratio,
    ch_lo,
    ch_hi,
    ch_wrap,
    R_diag,
    ctrl_id,
    cp,
    cs,
    ref,
    M,
    M_inv,
    a_lo,
    a_hi,
    a_trim,
    f_kind,
    f_target,
    f_start,
    f_end,
    f_mag,
    f_unif,
    f_bit,
    control_on_truth,
):
    """Run the whole log; returns (x_true, u_cmd, u_act, z, x_hat, P_diag, rejected).

    p_true: the truth's packed parameters (the plant the vehicle is, its sensors' too); p: the
    nominal ones the on-board EKF uses (the same array unless the plant is off-nominal).

    z is (N, total measurements) with NaN where a group did not sample; rejected counts samples
    the on-board EKF skipped (non-finite or outside the sensor's physical range). E holds unit
    normal draws (N, total measurements); R_diag is the on-board EKF's (nominal) noise variance;
    a_trim (nu_actuators,) the actuators' operating point (zeros unless the model's inputs are
    deviations from one)."""
    N, n = W.shape
    nu = M.shape[0]
    n_meas = E.shape[1]
    x_true = np.empty((N, n))
    x_hat = np.empty((N, n))
    P_diag = np.empty((N, n))
    u_cmd = np.empty((N, nu))
    u_act = np.empty((N, nu))
    z_all = np.full((N, n_meas), np.nan)
    last_z = np.zeros(n_meas)
    stuck = np.zeros(f_kind.size)
    held = np.zeros(f_kind.size)  # control-stuck: the output held
    u_last = np.zeros(M.shape[0])  # the controller's output of the previous step (after its faults)
    rejected = 0
    y_s = np.empty(n_meas)
    R_s = np.empty(n_meas)
    H_s = np.empty((n_meas, n))
    x = x0.copy()
    xh = x0.copy()
    P = P0.copy()
    u = np.zeros(nu)
    for k in range(N):
        # 1. controller on the estimate (or on the true state: Scenario.control_on_truth), actuator limits
        control(ctrl_id, cp, cs, ref[k], x if control_on_truth else xh, dt, u)
        _control_faults(k, u, u_last, f_kind, f_target, f_start, f_end, f_mag, held)
        a = M_inv @ u
        for j in range(a.size):
            a[j] = min(max(a[j], a_lo[j]), a_hi[j])
        u_cmd[k] = M @ a
        # 2. actuator faults, truth
        for i in range(f_kind.size):
            if k >= f_start[i] and k < f_end[i]:
                j = f_target[i]
                if f_kind[i] == ACT_OFFSET:  # the total a_trim + a scaled by 1 + m
                    a[j] = (a_trim[j] + a[j]) * (1.0 + f_mag[i]) - a_trim[j]
                elif f_kind[i] == LOST_ACT:  # total 0
                    a[j] = -a_trim[j]
        ua = M @ a
        u_act[k] = ua
        if k > 0:
            # x_k = f(x_{k-1}, u_k) + w_k
            x = f_disc(model_id, p_true, x, ua, dt) + W[k]
            # on-board EKF predict: x_prior = f(x_post, u_cmd), P_prior = F P F^T + Q
            xh, F = predict(model_id, p, xh, u_cmd[k], dt)
            P = F @ P @ F.T + Q
        x_true[k] = x
        # 3. sensors; the valid fresh groups are stacked into one on-board update
        mk = 0
        for g in range(g_id.size):
            if k % g_ratio[g] != 0:
                continue
            m = g_m[g]
            o = g_off[g]
            zg = h_meas(model_id, g_id[g], p_true, x, ua)
            ok = True
            for j in range(m):
                c = o + j
                for i in range(f_kind.size):
                    if f_kind[i] == STUCK and f_target[i] == c and k == f_start[i]:
                        stuck[i] = last_z[c]
                sd = noise_base[c]
                if noise_slope[c] != 0.0:
                    sd = sd + noise_slope[c] * abs(zg[j])
                v = zg[j] + E[k, c] * sd
                if ch_wrap[c]:
                    v = (v + np.pi) % (2.0 * np.pi) - np.pi
                v = _sensor_faults(k, c, v, dt, f_kind, f_target, f_start, f_end, f_mag, f_unif, f_bit, stuck)
                z_all[k, c] = v
                last_z[c] = v
                if not (v >= ch_lo[c] and v <= ch_hi[c]):
                    ok = False
            if not ok:
                rejected += 1
                continue
            Hg = H_meas(model_id, g_id[g], p, xh, u_cmd[k])
            hg = h_meas(model_id, g_id[g], p, xh, u_cmd[k])
            for j in range(m):
                # y = z - h(x_prior), angles wrapped
                yj = z_all[k, o + j] - hg[j]
                if ch_wrap[o + j]:
                    yj = (yj + np.pi) % (2.0 * np.pi) - np.pi
                y_s[mk] = yj
                R_s[mk] = R_diag[o + j]
                H_s[mk] = Hg[j]
                mk += 1
        if mk > 0:
            H = H_s[:mk]
            HP = H @ P
            # S = H P H^T + R;  K = P H^T S^-1 (solve, S symmetric)
            S = HP @ H.T
            for j in range(mk):
                S[j, j] += R_s[j]
            K = np.linalg.solve(S, HP).T
            xh = xh + K @ y_s[:mk]
            # P_post = P_prior - K H P_prior, symmetrised
            P = P - K @ HP
            P = 0.5 * (P + P.T)
        for i in range(f_kind.size):
            if f_kind[i] == STATE_CORRUPT and k == f_start[i]:
                if f_target[i] < 0:
                    xh = xh + f_mag[i]
                else:
                    xh[f_target[i]] += f_mag[i]
        x_hat[k] = xh
        for j in range(n):
            P_diag[k, j] = P[j, j]
    return x_true, u_cmd, u_act, z_all, x_hat, P_diag, rejected


follow_dependencies(__name__)
