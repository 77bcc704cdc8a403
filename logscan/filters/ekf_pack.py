"""The EKF kernel's arguments, and packing an aligned run into them.

`logscan.filters.ekf.ekf_run` takes its arrays grouped by meaning into NamedTuples, every field's
shape and dtype beside it: `EkfModel` (parameters, Q, prior), `EkfSensors` (the groups' layout, R,
ranges), `EkfData` (the run's inputs and samples) and `EkfBuffers` (the trace it writes).
`pack_run` checks a run against the model and builds the first three (`KernelInputs`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from logscan.align import AlignedRun
from logscan.errors import ModelError
from logscan.filters.coding import coding_arguments
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
        )
        return self.model_id, model, sensors, EkfData(self.u, self.u_default, self.z, self.fresh, self.R_std)


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
    model: Model, run: AlignedRun, Q=None, R=None, x0=None, P0=None, coding: CodedVariance | None = None
) -> KernelInputs:
    """Check the run against the model and pack it into the kernel's arrays.

    Q: None (the model's default_Q, scaled by its calibrated ``process_noise_scale`` when set),
    or an (n, n) matrix. R: None (each group's profile noise_std, else the model's default_R), or a dict
    group -> (m, m) matrix or (m,) standard deviations. The physical range (samples outside it are
    rejected) is each group's profile range_lo / range_hi where given, else the model's. ``coding``:
    the encoded check's predicted variance is computed too (`logscan.filters.coding`).
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
    x0, P0, Q, seed = _prior(model, run, Q, x0, P0)
    finite_rows = np.flatnonzero(np.all(np.isfinite(u), axis=1))
    u_default = u[finite_rows[0]].copy() if finite_rows.size else np.zeros(model.n_inputs)
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
        dt=float(run.dt),
        seed_at_start=seed,
        coding_floor=coding_floor,
        coding_r_max=coding_r_max,
    )


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


def _prior(model: Model, run: AlignedRun, Q, x0, P0) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """(x0, P0, Q, seed_at_start): the given ones checked, else the model's (Q scaled when
    trained tables calibrated it); seed_at_start when no x0 is given."""
    n = model.n_states
    seed = x0 is None
    x0 = model.default_x0() if x0 is None else np.asarray(x0, dtype=np.float64).reshape(-1)
    if x0.size != n or not np.all(np.isfinite(x0)):
        raise ModelError(f"x0 must hold {n} finite values")
    P0 = model.default_P0() if P0 is None else _square("P0", P0, n)
    if Q is None:  # the model's, scaled when trained tables calibrated it (`logscan.training.process_noise`)
        Q = calibrated_Q(model, run.dt)
    Q = model.default_Q(run.dt) if Q is None else _square("Q", Q, n)
    return x0, P0, Q, seed
