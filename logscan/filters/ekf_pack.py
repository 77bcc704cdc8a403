"""The EKF kernel's arguments, and packing an aligned run into them.

`logscan.filters.ekf.ekf_run` takes its arrays grouped by meaning into NamedTuples, every field's
shape and dtype beside it: `EkfModel` (parameters, Q, prior), `EkfSensors` (the groups' layout, R,
ranges), `EkfData` (the run's inputs and samples) and `EkfBuffers` (the trace it writes).
`pack_run` checks a run against the model and builds the first three (`KernelInputs`),
`trace_buffers` the fourth; `EkfWork` holds the kernel's own work arrays.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from logscan.align import AlignedRun
from logscan.errors import ModelError
from logscan.filters.coding import coding_arguments
from logscan.filters.gates import outlier_gates
from logscan.filters.q_scale import calibrated_Q
from logscan.models import dispatch
from logscan.models.base import Model
from logscan.needs import CodedVariance


# =============================================================================================
# the kernel's arguments (N steps, n states, nu inputs, G groups, m_total outputs of all groups
# stacked group after group; a group's outputs are rows group_offsets[g] : + group_sizes[g])
# =============================================================================================
class EkfModel(NamedTuple):
    """The model and the prior: what the kernel holds fixed over a run."""

    p: np.ndarray  # (n_p,) float64: the model's packed parameters (Model.param_vector)
    dt: float  # the grid step, s
    Q: np.ndarray  # (n, n) float64: process noise covariance of one step
    x0: np.ndarray  # (n,) float64: the initial state, and the state a restart returns to
    P0: np.ndarray  # (n, n) float64: its covariance
    seed_at_start: bool  # no x0 given: seed the directly observed states from their first samples
    # the encoded check's coding vector (logscan.filters.coding): its floor sigma_floor * state scale,
    # (n,) float64, (0,) when its predicted variance is not asked for; and the sum bound r_max
    coding_floor: np.ndarray
    coding_r_max: float


class EkfSensors(NamedTuple):
    """The measurement groups: which model outputs, their noise, range and direct states."""

    group_ids: np.ndarray  # (G,) int64: each group's id in the model (its h, H)
    group_offsets: np.ndarray  # (G,) int64: each group's first output
    group_sizes: np.ndarray  # (G,) int64: each group's number of outputs
    R_all: np.ndarray  # (m_total, m_total) float64: measurement noise covariance (group blocks)
    range_lo: np.ndarray  # (m_total,) float64: physical range of each output (outside: rejected)
    range_hi: np.ndarray  # (m_total,) float64
    wrap: np.ndarray  # (m_total,) bool: an angle (its innovation wraps to [-pi, pi))
    direct_idx: np.ndarray  # (m_total,) int64: the state i an output observes as z = gain * x[i], else -1
    direct_gain: np.ndarray  # (m_total,) float64: that gain
    # (G,) float64: each group's outlier gate on its NIS against the prior (inf: none; `outlier_gates`)
    gate: np.ndarray


class EkfData(NamedTuple):
    """The run's samples on the grid."""

    u: np.ndarray  # (N, nu) float64: the input held at each step (a non-finite row: the last finite one)
    u_default: np.ndarray  # (nu,) float64: the input held before the first finite row
    z: np.ndarray  # (N, m_total) float64: the samples, group blocks side by side
    fresh: np.ndarray  # (N, G) bool: group g has a new sample at step k
    R_std: np.ndarray  # (N, m_total) float64: per-sample noise std (NaN: R_all's); (0, m_total): none


class EkfBuffers(NamedTuple):
    """What the kernel writes, preallocated by the caller (NaN / False / 0 filled, but S_out and
    K_out, which the kernel NaN-fills step by step). The optional ones (marked *) are stored when
    their first dimension is N; a zero-length first dimension skips them."""

    x_prior: np.ndarray  # (N, n) float64
    x_post: np.ndarray  # (N, n) float64
    P_prior_diag: np.ndarray  # (N, n) float32
    P_post_diag: np.ndarray  # (N, n) float32
    P_prior_full: np.ndarray  # (N, n, n) float64 *
    P_post_full: np.ndarray  # (N, n, n) float64 *
    y_out: np.ndarray  # (N, m_total) float32 * innovation, NaN where not updated
    S_out: np.ndarray  # (N, m_total, m_total) float64 * innovation covariance
    S_diag_out: np.ndarray  # (N, m_total) float32, stored with y_out
    K_out: np.ndarray  # (N, n, m_total) float64 * gain
    ex_var: np.ndarray  # (N,) float64 * CV K S K^T CV^T, 0 where not updated (EkfModel.coding_floor)
    nis: np.ndarray  # (N,) float64
    nis_group: np.ndarray  # (N, G) float64
    m_k: np.ndarray  # (N,) int64: outputs in the update (0: none)
    gain_norm: np.ndarray  # (N,) float64: Frobenius norm of K
    updated: np.ndarray  # (N, G) bool
    rejected: np.ndarray  # (N, G) bool: fresh but non-finite or out of range
    seeded: np.ndarray  # (N, G) bool
    diverged: np.ndarray  # (N,) bool
    input_held: np.ndarray  # (N,) bool
    # (1,) int64: the steps filtered so far, written at every step; the kernel runs without the GIL,
    # so a thread can read it while the kernel runs (a progress bar counting filter steps)
    steps_done: np.ndarray


class EkfWork(NamedTuple):
    """The step loop's state and work arrays, allocated once per run (`work_arrays`) and handed to
    the loop, which is compiled without numba's reference counting (NRT) and so cannot allocate:
    with the NRT on, every array argument of a call and every array swapped or viewed in the loop
    counted a reference up and down (an external call and an atomic add each, tens per step)."""

    x: np.ndarray  # (n,) float64: the state (x0 at the start)
    P: np.ndarray  # (n, n) float64: its covariance (P0 at the start)
    u_last: np.ndarray  # (nu,) float64: the last finite input
    is_direct: np.ndarray  # (G,) bool: every output of the group observes one state
    seed_done: np.ndarray  # (G,) bool: the group re-seeded its states since the last restart
    rows: np.ndarray  # (m,) int64: the step's stacked outputs
    sel_g: np.ndarray  # (G,) int64: the step's updating groups
    x_new: np.ndarray  # (n,) float64: f(x, u)
    kv: np.ndarray  # (n,) float64: RK4 work
    xs: np.ndarray  # (n,) float64: RK4 work
    x_upd: np.ndarray  # (n,) float64: x (+) K y
    dx: np.ndarray  # (n,) float64: K y
    F: np.ndarray  # (n, n) float64: the step's Jacobian
    F_bits: np.ndarray  # (n * n,) int64: F's entries as int64 (the same memory)
    W: np.ndarray  # (n, n) float64: work
    P_upd: np.ndarray  # (n, n) float64: the next covariance (swapped with P)
    Aw: np.ndarray  # (n, n) float64: RK4 Jacobian stages
    Jw: np.ndarray  # (n, n) float64
    Jnw: np.ndarray  # (n, n) float64
    R3: np.ndarray  # (3, 3) float64: a rotation (quadcopter)
    D3: np.ndarray  # (3, 3, 3) float64: its derivatives
    f_outside: np.ndarray  # (n * n,) int64: -1 where F has been zero (of either sign) at every step so far
    fcols: np.ndarray  # (n, n) int64: the other columns of F's row i (linalg.grow_pattern), first fnnz[i]
    fnnz: np.ndarray  # (n,) int64
    hcols: np.ndarray  # (m, n) int64: the non-zero columns of each row of H
    hnnz: np.ndarray  # (m,) int64
    hx: np.ndarray  # (m,) float64: h(x)
    y: np.ndarray  # (m,) float64: innovation
    v: np.ndarray  # (m,) float64: work
    Hs: np.ndarray  # (m, n) float64: the stacked H
    HP: np.ndarray  # (m, n) float64: H P
    KT: np.ndarray  # (m, n) float64: K^T
    S: np.ndarray  # (m, m) float64: H P H^T + R
    Rs: np.ndarray  # (m, m) float64: the step's R
    RsT: np.ndarray  # (m, m) float64: its transpose (Joseph form)
    rcols: np.ndarray  # (m, m) int64: R's non-zeros by column (Joseph form)
    rnnz: np.ndarray  # (m,) int64
    L: np.ndarray  # (m, m) float64: Cholesky factor of S
    Lg: np.ndarray  # (m, m) float64: of a group's block of S
    D: np.ndarray  # (n, m) float64: Joseph form work
    DT: np.ndarray  # (m, n) float64
    V: np.ndarray  # (m, n) float64: L^-1 H P
    all_cols: np.ndarray  # (n, m) int64: all_cols[i, a] = a
    m_cnt: np.ndarray  # (n,) int64
    pos: np.ndarray  # (m,) int64: where each output sits in the step's update (-1: not in it)
    cv: np.ndarray  # (n,) float64: the encoded check's coding vector


def _carved(specs: dict) -> dict[str, np.ndarray]:
    """Arrays carved from one buffer, each on its own 64-byte line: the step loop touches all of
    them at every step, and together they fit a few pages (separate allocations were scattered
    over the heap: the loop ran about 3 % slower). ``specs``: name -> the array's initial values,
    or (shape, dtype, fill)."""
    layout = {}
    for name, spec in specs.items():
        shape, dtype = (spec.shape, spec.dtype) if isinstance(spec, np.ndarray) else spec[:2]
        layout[name] = (shape, np.dtype(dtype), int(np.prod(shape)) * np.dtype(dtype).itemsize)
    raw = np.zeros(sum(-(-nbytes // 64) * 64 for _, _, nbytes in layout.values()) + 64, dtype=np.uint8)
    at = -raw.ctypes.data % 64
    out = {}
    for name, (shape, dtype, nbytes) in layout.items():
        out[name] = raw[at : at + nbytes].view(dtype).reshape(shape)
        spec = specs[name]
        out[name][...] = spec if isinstance(spec, np.ndarray) else spec[2]
        at += -(-nbytes // 64) * 64
    return out


def work_arrays(model: EkfModel, sensors: EkfSensors, data: EkfData) -> EkfWork:
    """The kernel's work arrays for a run (x = x0, P = P0, u_last = u_default), allocated here in
    numpy: a compiled allocator of these 46 arrays took a second to compile on the first run, for
    microseconds of work per run."""
    n, m, G = model.x0.size, sensors.direct_idx.size, sensors.group_sizes.size
    direct = sensors.direct_idx >= 0
    # a group is direct when every one of its outputs observes one state (an empty group is)
    ends = sensors.group_offsets + sensors.group_sizes
    is_direct = np.array([direct[o:e].all() for o, e in zip(sensors.group_offsets, ends)], dtype=np.bool_)
    f8, i8 = np.float64, np.int64
    vectors = {name: ((n,), f8, 0) for name in ("x_new", "kv", "xs", "x_upd", "dx", "cv")}
    squares = {name: ((n, n), f8, 0) for name in ("F", "W", "P_upd", "Aw", "Jw", "Jnw")}
    outputs = {name: ((m,), f8, 0) for name in ("hx", "y", "v")}
    rows_by_state = {name: ((m, n), f8, 0) for name in ("Hs", "HP", "KT", "DT", "V")}
    blocks = {name: ((m, m), f8, 0) for name in ("S", "Rs", "RsT", "L", "Lg")}
    arrays = _carved(
        {
            "x": model.x0, "P": model.P0, "u_last": data.u_default, "is_direct": is_direct,
            "seed_done": ((G,), np.bool_, 0), "rows": ((m,), i8, 0), "sel_g": ((G,), i8, 0),
            **vectors, **squares, **outputs, **rows_by_state, **blocks,
            "R3": ((3, 3), f8, 0), "D3": ((3, 3, 3), f8, 0), "f_outside": ((n * n,), i8, -1),
            "fcols": ((n, n), i8, 0), "fnnz": ((n,), i8, 0), "hcols": ((m, n), i8, 0), "hnnz": ((m,), i8, 0),
            "rcols": ((m, m), i8, 0), "rnnz": ((m,), i8, 0), "D": ((n, m), f8, 0),
            "all_cols": np.tile(np.arange(m, dtype=i8), (n, 1)), "m_cnt": ((n,), i8, 0), "pos": ((m,), i8, -1),
        }
    )  # fmt: skip
    return EkfWork(**arrays, F_bits=arrays["F"].reshape(n * n).view(np.int64))


def trace_buffers(
    N: int,
    n: int,
    G: int,
    m: int,
    *,
    full_P: bool,
    store_gain: bool,
    store_S: bool,
    store_innovations: bool,
    store_ex_var: bool = False,
) -> EkfBuffers:
    """The kernel's output arrays for N steps (n states, G groups, m outputs), NaN / False / 0
    filled where the kernel writes only some steps; the ones not stored have a zero-length first
    dimension."""
    nan = np.nan
    return EkfBuffers(
        # x and P, prior and posterior: written by ekf_run at every step, so not filled first
        x_prior=np.empty((N, n)),
        x_post=np.empty((N, n)),
        # float32: variances are scales (coding vectors, consistency bands), 7 digits are ample,
        # and a 1-hour log keeps 35 MB less
        P_prior_diag=np.empty((N, n), dtype=np.float32),
        P_post_diag=np.empty((N, n), dtype=np.float32),
        P_prior_full=np.empty((N if full_P else 0, n, n)),
        P_post_full=np.empty((N if full_P else 0, n, n)),
        # S_out, K_out: written step by step by ekf_run, NaN where not updated (one pass, not two)
        # float32: y and diag(S) are drawn (the report's measured-vs-predicted figures), never
        # filtered further; a 1-hour log keeps 35 MB less
        y_out=np.full((N if store_innovations else 0, m), nan, dtype=np.float32),
        S_out=np.empty((N if store_S else 0, m, m)),
        S_diag_out=np.full((N if store_innovations else 0, m), nan, dtype=np.float32),
        K_out=np.empty((N if store_gain else 0, n, m)),
        ex_var=np.zeros(N if store_ex_var else 0),  # 0 where not updated
        nis=np.full(N, nan),
        nis_group=np.full((N, G), nan),
        m_k=np.zeros(N, dtype=np.int64),
        gain_norm=np.full(N, nan),
        updated=np.zeros((N, G), dtype=np.bool_),
        rejected=np.zeros((N, G), dtype=np.bool_),
        seeded=np.zeros((N, G), dtype=np.bool_),
        diverged=np.zeros(N, dtype=np.bool_),
        input_held=np.zeros(N, dtype=np.bool_),
        steps_done=np.zeros(1, dtype=np.int64),
    )


# =============================================================================================
# packing a run for the kernel
# =============================================================================================
@dataclass
class KernelInputs:
    """The packed arrays `ekf_run` reads (built by `pack_run`; the reference filter reads them
    too)."""

    model_id: int
    p: np.ndarray
    x0: np.ndarray
    P0: np.ndarray
    Q: np.ndarray
    u: np.ndarray
    u_default: np.ndarray
    z: np.ndarray
    fresh: np.ndarray
    group_names: list[str]
    group_ids: np.ndarray
    group_offsets: np.ndarray
    group_sizes: np.ndarray
    R_all: np.ndarray
    R_std: np.ndarray  # (N, m_total) per-sample noise std, NaN where none; (0, m_total): none
    range_lo: np.ndarray
    range_hi: np.ndarray
    wrap: np.ndarray
    direct_idx: np.ndarray
    direct_gain: np.ndarray
    gate: np.ndarray  # (G,) the groups' outlier gates (inf: none)
    dt: float
    seed_at_start: bool
    coding_floor: np.ndarray  # EkfModel's: (0,) unless pack_run was given a CodedVariance
    coding_r_max: float

    def kernel_arguments(self) -> tuple[int, EkfModel, EkfSensors, EkfData]:
        """``ekf_run``'s arguments before its buffers: the model id and the pack's arrays grouped
        by meaning (the same arrays, not copies)."""
        model = EkfModel(
            self.p, self.dt, self.Q, self.x0, self.P0, self.seed_at_start, self.coding_floor, self.coding_r_max
        )
        sensors = EkfSensors(
            self.group_ids,
            self.group_offsets,
            self.group_sizes,
            self.R_all,
            self.range_lo,
            self.range_hi,
            self.wrap,
            self.direct_idx,
            self.direct_gain,
            self.gate,
        )
        return self.model_id, model, sensors, EkfData(self.u, self.u_default, self.z, self.fresh, self.R_std)

    def direct_groups(self) -> np.ndarray:
        """(G,) bool: the groups that observe states directly (the ones the kernel seeds)."""
        return np.array(
            [bool(np.all(self.direct_idx[o : o + s] >= 0)) for o, s in zip(self.group_offsets, self.group_sizes)]
        )


def _square(name: str, value, size: int) -> np.ndarray:
    M = np.asarray(value, dtype=np.float64)
    if M.ndim == 1 and M.size == size:
        M = np.diag(M)
    if M.shape != (size, size):
        raise ModelError(f"{name} must be {size} x {size} (or a diagonal of {size}), got shape {M.shape}")
    if not np.all(np.isfinite(M)):
        raise ModelError(f"{name} has non-finite entries")
    return M


def _group_ranges(run: AlignedRun, names: list[str], specs, which: str) -> np.ndarray:
    """``range_lo`` or ``range_hi`` of every output, group after group: the aligned group's
    (from the profile) when it has one, else the model's GroupSpec's."""
    parts = []
    for name, spec in zip(names, specs):
        own = getattr(run.groups[name], which, None)
        parts.append(np.broadcast_to(np.asarray(getattr(spec, which) if own is None else own, float), (spec.size,)))
    return np.concatenate(parts)


def samples_side_by_side(
    run: AlignedRun, names: list[str], offsets: np.ndarray, sizes: np.ndarray
) -> np.ndarray | None:
    """The (N, m_total) float64 array whose column blocks are the groups' samples in this order
    (what `logscan.align` builds), else None. The kernel only reads z, so it may share it."""
    first = run.groups[names[0]].z
    base = first.base if isinstance(first, np.ndarray) else None
    if not isinstance(base, np.ndarray) or base.dtype != np.float64 or not base.flags.c_contiguous:
        return None
    if base.shape != (run.n_steps, int(sizes.sum())):
        return None
    origin = base.__array_interface__["data"][0]
    for name, offset, size in zip(names, offsets.tolist(), sizes.tolist()):
        z = run.groups[name].z
        if not isinstance(z, np.ndarray) or z.base is not base or z.shape != (run.n_steps, size):
            return None
        if z.__array_interface__["data"][0] != origin + 8 * offset or z.strides != base.strides:
            return None
    return base


def pack_run(
    model: Model, run: AlignedRun, Q=None, R=None, x0=None, P0=None, coding: CodedVariance | None = None, seed=None
) -> KernelInputs:
    """Check the run against the model and pack it into the kernel's arrays.

    Q: None (the model's default_Q, scaled by its calibrated ``process_noise_scale`` when set),
    or an (n, n) matrix. R: None (each group's profile noise_std, else the model's default_R), or a dict
    group -> (m, m) matrix or (m,) standard deviations. The physical range (samples outside it are
    rejected) is each group's profile range_lo / range_hi where given, else the model's. ``coding``:
    the encoded check's predicted variance is computed too (`logscan.filters.coding`). ``seed``:
    whether the run starts by seeding its directly observed states (None: when no x0 is given).
    """
    dispatch.check_model_id(model.model_id, model.name)
    u = _inputs(model, run)
    if not run.groups:
        raise ModelError("the run has no measurement groups: the filter has nothing to update with")
    names = list(run.groups)
    specs = [model.group(g) for g in names]
    sizes = np.array([s.size for s in specs], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    m_total = int(sizes.sum())
    z, fresh, R_all, R_std = _samples_and_noise(model, run, names, specs, offsets, sizes, dict(R or {}))
    x0, P0, Q, seed = _prior(model, run, Q, x0, P0, seed)
    first = first_finite_row(u)
    u_default = u[first].copy() if first >= 0 else np.zeros(model.n_inputs)
    direct = [s.direct_map() for s in specs]
    coding_floor, coding_r_max = coding_arguments(coding, model)
    return KernelInputs(
        model_id=int(model.model_id),
        p=np.ascontiguousarray(model.param_vector(run.dt), dtype=np.float64),
        x0=np.ascontiguousarray(x0),
        P0=np.ascontiguousarray(P0),
        Q=np.ascontiguousarray(Q),
        u=u,
        u_default=u_default,
        z=z,
        fresh=fresh,
        group_names=names,
        group_ids=np.array([s.group_id for s in specs], dtype=np.int64),
        group_offsets=offsets,
        group_sizes=sizes,
        R_all=R_all,
        R_std=np.empty((0, m_total)) if R_std is None else np.ascontiguousarray(R_std),
        # the profile's physical range of a group where it gives one, else the model's
        range_lo=_group_ranges(run, names, specs, "range_lo"),
        range_hi=_group_ranges(run, names, specs, "range_hi"),
        wrap=np.concatenate([s.wrap_mask() for s in specs]),
        direct_idx=np.concatenate([d[0] for d in direct]),
        direct_gain=np.concatenate([d[1] for d in direct]),
        gate=outlier_gates(specs, [getattr(run.groups[g], "rate_hz", None) for g in names], fresh, run.dt),
        dt=float(run.dt),
        seed_at_start=seed,
        coding_floor=coding_floor,
        coding_r_max=coding_r_max,
    )


def first_finite_row(u: np.ndarray) -> int:
    """The first row of ``u`` (N, nu) with all values finite, -1 if none: looked for in blocks doubling
    from 64 rows (the first row almost always is; checking all N was 2 ms of a 100,000-step run)."""
    start, size = 0, 64
    while start < u.shape[0]:
        rows = np.flatnonzero(np.isfinite(u[start : start + size]).all(axis=1))
        if rows.size:
            return start + int(rows[0])
        start, size = start + size, 2 * size
    return -1


def _inputs(model: Model, run: AlignedRun) -> np.ndarray:
    """The run's (N, nu) inputs as contiguous float64, checked against the model's inputs."""
    N = run.n_steps
    u = np.ascontiguousarray(run.u, dtype=np.float64)
    if u.ndim != 2 or u.shape != (N, model.n_inputs):
        raise ModelError(
            f"model {model.name!r} takes {model.n_inputs} inputs ({', '.join(model.input_names)}) "
            f"but the run has inputs of shape {u.shape} for {N} steps",
            hint="map every model input to a log channel in the profile's [inputs]",
        )
    return u


def _samples_and_noise(
    model: Model, run: AlignedRun, names: list[str], specs, offsets: np.ndarray, sizes: np.ndarray, R: dict
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """z (N, m_total), fresh (N, G), R_all (m_total, m_total) and the per-sample noise std
    R_std (N, m_total; None when no group has one), group blocks in the order of ``names``."""
    N = run.n_steps
    m_total = int(sizes.sum())
    z = samples_side_by_side(run, names, offsets, sizes)  # alignment's own array, when it has that layout
    packed = z is not None
    z = np.empty((N, m_total)) if z is None else z
    fresh = np.zeros((N, len(names)), dtype=np.bool_)
    R_all = np.zeros((m_total, m_total))
    R_std = None  # per-sample noise of the groups that have it (AlignedGroup.noise_std_series)
    for g, (name, spec) in enumerate(zip(names, specs)):
        grp = run.groups[name]
        zg = np.asarray(grp.z, dtype=np.float64)
        if zg.ndim == 1:
            zg = zg[:, None]
        if zg.shape != (N, spec.size):
            raise ModelError(
                f"group {name!r}: {zg.shape[1] if zg.ndim == 2 else '?'} channels, the model's "
                f"group has {spec.size} ({', '.join(spec.outputs)})",
                hint="list one channel per model output in the profile",
            )
        o = offsets[g]
        if not packed:
            z[:, o : o + spec.size] = zg
        fresh[:, g] = np.asarray(grp.fresh, dtype=bool)
        R_all[o : o + spec.size, o : o + spec.size] = _group_R(model, name, spec, grp, R)
        noise = getattr(grp, "noise_std_series", None)
        if noise is not None:
            if R_std is None:
                R_std = np.full((N, m_total), np.nan)
            R_std[:, o : o + spec.size] = np.asarray(noise, dtype=np.float64).reshape(N, spec.size)
    unknown_R = sorted(set(R) - set(names))
    if unknown_R:
        raise ModelError(f"R given for group(s) not in the run: {', '.join(unknown_R)}")
    return z, fresh, R_all, R_std


def _group_R(model: Model, name: str, spec, grp, R: dict) -> np.ndarray:
    """A group's measurement noise covariance: given in ``R``, else its profile noise_std, else
    the model's default_R."""
    if name in R:
        given = np.square(R[name]) if np.ndim(R[name]) == 1 else R[name]  # std or matrix
        return _square(f"R[{name}]", given, spec.size)
    if grp.noise_std is not None:
        return np.diag(np.square(np.broadcast_to(np.asarray(grp.noise_std, float), (spec.size,))))
    return model.default_R(name)


def _prior(model: Model, run: AlignedRun, Q, x0, P0, seed) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """(x0, P0, Q, seed_at_start): the given ones checked, else the model's (Q scaled when
    trained tables calibrated it); seed_at_start as given, else when no x0 is given."""
    n = model.n_states
    seed = x0 is None if seed is None else bool(seed)
    x0 = model.default_x0() if x0 is None else np.asarray(x0, dtype=np.float64).reshape(-1)
    if x0.size != n or not np.all(np.isfinite(x0)):
        raise ModelError(f"x0 must hold {n} finite values")
    P0 = model.default_P0() if P0 is None else _square("P0", P0, n)
    if Q is None:  # the model's, scaled when trained tables calibrated it (`logscan.training.process_noise`)
        Q = calibrated_Q(model, run.dt)
    Q = model.default_Q(run.dt) if Q is None else _square("Q", Q, n)
    return x0, P0, Q, seed
