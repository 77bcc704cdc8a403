"""The UBIKF: a Kalman filter on an interval linear model with a covariance upper bound and a
sound envelope of the state estimates (docs/algorithms.md section 2).

Model `logscan.models.interval_model.IntervalModel`: x_{k+1} = [A] x_k + [B] u_k + w, y_k = [C] x_k + v,
[M] = M_m +- M_r; Q+ and R+ are Loewner upper bounds of [Q] and [R] (`loewner_upper`).

Covariance bound (weighted): (sum_t a_t)(sum_t a_t)^T <= sum_t a_t a_t^T / lambda_t with lambda_t
proportional to the size of each term. With sigma = sqrt(diag P) and rho = M_r sigma:

    P+_prior = (s/s0) A_m P+_post A_m^T + s diag(rho_A) + Q+            s0 = sqrt(tr A_m P A_m^T), s = s0 + sum rho_A
    S+       = (c/c0) C_m P+_prior C_m^T + c diag(rho_C) + R+           c0, c likewise with C (rows updated)
    K        = (c/c0) P+_prior C_m^T (S+)^-1
    P+_post  = (d/d0) M P+_prior M^T + d sum_a (rho_C,a / |k_a|) k_a k_a^T + K R+ K^T,   M = I - K C_m,
               d0 = sqrt(tr M P M^T), d = d0 + sum_a rho_C,a |k_a|  (k_a: column a of K)

so every point filter (A, C, Q, R) in the intervals that uses this gain sequence has its Joseph
covariance below P+.

State set: the mid-model point estimate x_c and the zonotope x_c + G [-1, 1]^p of the deviations
of every admissible point filter's estimate (same gains, inputs and measurements) from it:

    x_c,prior = A_m x_c + B_m u              G <- A_m G,  alpha = A_r (|x_c| + h) + B_r |u|
    r = y - C_m x_c,prior                     r_rad = rowsum |C_m G| + |C_m| alpha + gamma,
                                              gamma = C_r (|x_c,prior| + h_prior)
    x_c,post = x_c,prior + K r                G <- [(I - K C_m) G, diag(|I - K C_m| alpha + |K| gamma)]

with h = rowsum |G| the hull radius (h_prior adds alpha). The step's new deviations (the alpha box
through I - K C_m, and K [-gamma, gamma]) are boxed once, when they enter: one column per state
and step instead of n + m, then mapped exactly until the order reduction: every L_box steps
(default 10) the generators those steps added are boxed together (`box_columns`), and every L steps
(default 60, a multiple of L_box) the generators older than L steps are boxed
(`logscan.filters.intervals.reduce_order`); each is boxed once at each level, so no wrapping
compounds below L. The states fall into independent blocks where the model allows
(`logscan.filters.ubikf_blocks`), each filtered alone. The innovation box [r] = r +- r_rad encloses
y - C x_prior for every admissible point filter (it is the image of the zonotope through [C]).

Conventions (as the EKF core, logscan.filters.ekf): k = 0: prior = x0, P0, no prediction; k > 0:
predict with u_k (a non-finite input row is replaced by the last finite one). A group updates at k
when it is fresh and its whole sample is finite. Divergence: a non-positive-definite S+, or P+, G
or x_c non-finite or above `cap` in absolute value: the step is flagged `diverged` and the block
restarts from x0/P0 with an empty zonotope (no statistic of that step is stored, in any block).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from logscan.align import AlignedRun
from logscan.errors import ModelError
from logscan.filters.detectability import check_detectable
from logscan.filters.ubikf_blocks import Block, block_groups, state_blocks, usable_groups
from logscan.filters.ubikf_kernel import BlockPlace, UbikfBuffers, UbikfData, UbikfModel, UbikfSettings, ubikf_run
from logscan.models.interval_model import IntervalModel, loewner_upper


@dataclass
class UbikfTrace:
    """Per-step output of `run_ubikf` (N steps, n states, G groups, m = sum of the group sizes).

    Group g's measurement rows are `group_offsets[g] : group_offsets[g] + group_sizes[g]`; r_mid,
    r_rad and S hold the rows updated at a step, NaN elsewhere (S is NaN-padded to (m, m)).
    """

    t: np.ndarray  # (N,)
    x_mid: np.ndarray  # (N, n) mid-model point estimate x_c (posterior)
    x_lo: np.ndarray  # (N, n) hull of the posterior zonotope
    x_hi: np.ndarray
    P_trace: np.ndarray  # (N,) trace(P+_post)
    P_diag: np.ndarray  # (N, n) float32 diag(P+_post)
    r_mid: np.ndarray  # (N, m) innovation box midpoint y - C_m x_c,prior, NaN where not updated
    r_rad: np.ndarray  # (N, m) innovation box radius
    S: np.ndarray  # (N, m, m) S+, NaN-padded
    nis: np.ndarray  # (N,) point NIS r_mid^T (S+)^-1 r_mid, NaN without update
    updated: np.ndarray  # (N, G) bool
    m_k: np.ndarray  # (N,) int, measurements in the update
    diverged: np.ndarray  # (N,) bool, restarted from x0/P0 at this step
    n_generators: np.ndarray  # (N,) int, zonotope order p after the step
    group_names: tuple[str, ...]
    group_offsets: np.ndarray
    group_sizes: np.ndarray
    state_names: tuple[str, ...]
    K: np.ndarray | None = None  # (N, n, m) gain, NaN-padded (store_gain)
    P: np.ndarray | None = None  # (N, n, n) P+_post (store_P)


# ================================================================================================
# the Python entry point
# ================================================================================================
def _measurements(model: IntervalModel, run: AlignedRun) -> tuple[np.ndarray, np.ndarray]:
    """z (N, m) and fresh (N, G) in the model's group order."""
    N = run.n_steps
    z = np.full((N, model.m), np.nan)
    fresh = np.zeros((N, len(model.group_names)), dtype=np.bool_)
    for g, name in enumerate(model.group_names):
        if name not in run.groups:
            raise ModelError(f"the run has no measurement group {name!r}", hint="groups: " + ", ".join(run.groups))
        o, size = int(model.group_offsets[g]), int(model.group_sizes[g])
        zg = np.asarray(run.groups[name].z, dtype=np.float64).reshape(N, -1)
        if zg.shape[1] != size:
            raise ModelError(f"group {name!r} has {zg.shape[1]} channels, the interval model {size}")
        z[:, o : o + size] = zg
        fresh[:, g] = np.asarray(run.groups[name].fresh, dtype=bool)
    return z, fresh


def run_ubikf(
    model: IntervalModel,
    run: AlignedRun,
    *,
    L: int = 60,
    L_box: int = 10,
    cap: float = 1e12,
    store_gain: bool = False,
    store_P: bool = False,
) -> UbikfTrace:
    """Filter the aligned run with the interval model (see the module docstring).

    L: order-reduction period in steps; cap: divergence threshold on |P+|, |x_c| and the hull
    radius; store_gain / store_P add K (N, n, m) and P+_post (N, n, n). x0 defaults to zeros and
    P0 to the identity when the model gives none. Raises ModelError for an ill-formed or
    undetectable model, or a run that does not match it.
    """
    if int(L) < 1 or int(L_box) < 1 or int(L) % int(L_box):
        raise ValueError(
            f"the order-reduction periods must be L >= 1 steps, a multiple of L_box >= 1; got {L}, {L_box}"
        )
    model.check()
    check_detectable(model)
    n, m, N, G = model.n, model.m, run.n_steps, len(model.group_names)
    u = np.ascontiguousarray(run.u, dtype=np.float64).reshape(N, -1)
    if u.shape[1] != model.B_m.shape[1]:
        raise ModelError(f"the interval model takes {model.B_m.shape[1]} inputs, the run has {u.shape[1]}")
    z, fresh = _measurements(model, run)
    x0 = np.zeros(n) if model.x0.size == 0 else np.asarray(model.x0, dtype=np.float64)
    P0 = np.eye(n) if model.P0.size == 0 else np.asarray(model.P0, dtype=np.float64)
    finite = np.flatnonzero(np.all(np.isfinite(u), axis=1))
    u_default = u[finite[0]].copy() if finite.size else np.zeros(u.shape[1])
    out = _buffers(N, n, m, G, store_P=store_P, store_gain=store_gain)
    kernel_model = _kernel_model(model, x0, P0)
    usable = usable_groups(z, fresh, kernel_model.group_offsets, kernel_model.group_sizes)
    settings = UbikfSettings(int(L), int(L_box), float(cap))
    blocks = state_blocks(*(kernel_model[i] for i in (0, 1, 4, 5, 6, 7, 9)))
    if N:
        for block in blocks:
            _run_block(kernel_model, block, UbikfData(u, u_default, z, usable), settings, out)
        _finish(out, usable, kernel_model.group_sizes)
    buffers = out._asdict()
    buffers["P"] = out.P if store_P else None
    buffers["K"] = out.K if store_gain else None
    return UbikfTrace(
        t=np.asarray(run.t, dtype=np.float64),
        **buffers,
        group_names=tuple(model.group_names),
        group_offsets=np.asarray(model.group_offsets),
        group_sizes=np.asarray(model.group_sizes),
        state_names=tuple(model.state_names),
    )


def _run_block(model: UbikfModel, block: Block, data: UbikfData, settings: UbikfSettings, out: UbikfBuffers) -> None:
    """Filter one block (`logscan.filters.ubikf_blocks`): the kernel writes its part of ``out``."""
    s, r = block.states, block.rows
    c = np.ascontiguousarray
    offsets, sizes = block_groups(r, model.group_offsets, model.group_sizes)
    sub = UbikfModel(
        A_m=c(model.A_m[np.ix_(s, s)]), A_r=c(model.A_r[np.ix_(s, s)]),
        B_m=c(model.B_m[s]), B_r=c(model.B_r[s]),
        C_m=c(model.C_m[np.ix_(r, s)]), C_r=c(model.C_r[np.ix_(r, s)]),
        Q=c(model.Q[np.ix_(s, s)]), R=c(model.R[np.ix_(r, r)]),
        x0=c(model.x0[s]), P0=c(model.P0[np.ix_(s, s)]),
        group_offsets=offsets, group_sizes=sizes,
    )  # fmt: skip
    block_data = UbikfData(data.u, data.u_default, c(data.z[:, r]), data.fresh)
    ubikf_run(sub, block_data, settings, out, BlockPlace(c(s, dtype=np.int64), c(r, dtype=np.int64)))


def _finish(out: UbikfBuffers, usable: np.ndarray, sizes: np.ndarray) -> None:
    """The whole model's update flags after every block ran: a group updated where it was usable
    and no block diverged (a diverged step stores no update); S+ is zero between the rows of
    different blocks, NaN outside the rows updated; a gain entry between blocks is zero."""
    bad = out.diverged
    if out.P.shape[0]:
        out.P[np.isnan(out.P)] = 0.0  # between blocks
    out.updated[:] = usable & ~bad[:, None]
    out.m_k[:] = out.updated @ sizes
    for series in (out.r_mid, out.r_rad, out.nis):
        series[bad] = np.nan
    rows = np.isfinite(out.r_mid)
    both = rows[:, :, None] & rows[:, None, :]
    out.S[both & np.isnan(out.S)] = 0.0
    out.S[~both] = np.nan
    if out.K.shape[0]:
        K = out.K
        K[np.isnan(K) & rows[:, None, :]] = 0.0
        K[~np.broadcast_to(rows[:, None, :], K.shape)] = np.nan


def _buffers(N: int, n: int, m: int, G: int, *, store_P: bool, store_gain: bool) -> UbikfBuffers:
    """The kernel's output arrays, NaN / False / 0 filled (P and K empty unless stored)."""
    nan = np.nan
    return UbikfBuffers(
        x_mid=np.full((N, n), nan),
        x_lo=np.full((N, n), nan),
        x_hi=np.full((N, n), nan),
        P_trace=np.zeros(N),  # each block adds its part
        P_diag=np.full((N, n), nan, dtype=np.float32),
        n_generators=np.zeros(N, dtype=np.int64),
        P=np.full((N if store_P else 0, n, n), nan),
        r_mid=np.full((N, m), nan),
        r_rad=np.full((N, m), nan),
        S=np.full((N, m, m), nan),
        nis=np.full(N, nan),
        K=np.full((N if store_gain else 0, n, m), nan),
        updated=np.zeros((N, G), dtype=np.bool_),
        m_k=np.zeros(N, dtype=np.int64),
        diverged=np.zeros(N, dtype=np.bool_),
    )


def _kernel_model(model: IntervalModel, x0: np.ndarray, P0: np.ndarray) -> UbikfModel:
    """The model's matrices as the kernel reads them (contiguous float64, Q+ and R+ bounds)."""
    c = np.ascontiguousarray
    names = ("A_m", "A_r", "B_m", "B_r", "C_m", "C_r")
    matrices = {name: c(getattr(model, name), dtype=np.float64) for name in names}
    return UbikfModel(
        **matrices,
        Q=c(loewner_upper(model.Q_m, model.Q_r)),
        R=c(loewner_upper(model.R_m, model.R_r)),
        x0=c(x0),
        P0=c(P0),
        group_offsets=c(model.group_offsets, dtype=np.int64),
        group_sizes=c(model.group_sizes, dtype=np.int64),
    )
