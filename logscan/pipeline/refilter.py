"""The EKF's gain K and innovation covariance S without holding them for the whole log.

K (N, n, m) and S (N, m, m) in float64 are 395 MB each per hour of a 100 Hz quadcopter log, more
than everything else of an analysis together. A detector that reads them a block of steps at a
time (the encoded EKF's predicted spread of e_x: `logscan.detectors.normalised_check`) needs them
only one block at a time. So the pipeline filters the log once without them, and `run_ekf_parts`
hands the trace a `Refiltered` K and S: array-like (N, ...) series that filter the block of steps
asked for again, from the filter's state carried from the block before, and give the same numbers.

The kernel's state between two steps is x, P, the last finite input, and the seeding flags; a block
from step s > 0 is filtered as steps s-1 .. e-1, the first of them without samples (no update,
no seeding) and with the held input, from x = x_post(s-1) and P = P_post(s-1) of the block before:
its prediction at step s is then the one of the whole run. Exact only where the state is fully
carried: no divergence in the log (a restart returns to the model's prior, not to the block's
start), and the seeding of the directly observed states either done or not begun at each block
start; otherwise the whole run's K and S are filtered in one go on first read (as before).
Read in order (the detectors' row blocks), each step is filtered once more; a read that goes back,
or an index other than a slice of steps (a full array: ``np.asarray``), costs a pass from the start.
"""

from __future__ import annotations

import numpy as np

from logscan.errors import InternalError
from logscan.filters.ekf import KernelInputs, filter_into, pack_run, run_ekf
from logscan.filters.ekf_pack import trace_buffers
from logscan.needs import CodedVariance, Part
from logscan.traces import EkfTrace

BLOCK = 4096  # steps per kernel call: its full P, K and S buffers are ~2.4 KB per step (n = m = 12)


def run_ekf_parts(model, run, parts: frozenset[Part], x0=None, P0=None, steps_done=None, seed=None) -> EkfTrace:
    """`run_ekf` with the trace ``parts`` asked for ("K", "S", "P", "y", a `CodedVariance`); K and S,
    when asked, re-filtered block by block on read (`Refiltered`) instead of held for the whole log.
    ``steps_done``: `run_ekf`'s progress counter; ``seed``: its (`pack_run`)."""
    heavy = parts & {"K", "S"}
    codings = {part for part in parts if isinstance(part, CodedVariance)}
    if len(codings) > 1:  # one encoded check per profile: its coding is the one asked for
        raise InternalError(f"the EKF was asked for {len(codings)} different coding vectors; it computes one")
    trace = run_ekf(
        model,
        run,
        x0=x0,
        P0=P0,
        store_gain="K" in parts and "P" in parts,
        store_S="S" in parts and "P" in parts,
        full_P="P" in parts,
        store_innovations="y" in parts,
        steps_done=steps_done,
        coding=next(iter(codings), None),
        seed=seed,
    )
    if heavy and "P" not in parts:  # with the full P asked for, the trace holds them all anyway
        source = Refiltered(pack_run(model, run, x0=x0, P0=P0, seed=seed), trace, heavy)
        trace.K = source.part("K") if "K" in parts else None  # type: ignore[assignment]
        trace.S = source.part("S") if "S" in parts else None  # type: ignore[assignment]
    return trace


class Refiltered:
    """K and S of one EKF run, filtered again a block of steps at a time (see the module docstring)."""

    def __init__(self, k: KernelInputs, trace: EkfTrace, parts: frozenset[Part]) -> None:
        self.k = k
        self.store = {"store_gain": "K" in parts, "store_S": "S" in parts, "store_innovations": False}
        self.n_steps = trace.n_steps
        self.n, self.m = int(trace.x_prior.shape[1]), int(k.z.shape[1])
        seeded = trace.seeded[:, k.direct_groups()]
        # the first step each directly observed group was seeded at (n_steps: never)
        self.first_seed = np.where(seeded.any(axis=0), seeded.argmax(axis=0), self.n_steps)
        starts = range(BLOCK, self.n_steps, BLOCK)
        self.exact_blocks = not trace.diverged.any() and all(self._settled(s) for s in starts)
        self.whole: tuple[np.ndarray, np.ndarray] | None = None
        self.cached: tuple[int, np.ndarray, np.ndarray] | None = None  # (block, K, S)
        self.last: tuple[int, int, np.ndarray, np.ndarray] | None = None  # (start, stop, K, S) last read
        self.carry: tuple[int, np.ndarray, np.ndarray, np.ndarray] | None = None  # (next block, x, P, u_last)

    def part(self, name: str) -> RefilteredPart:
        shape = (self.n_steps, self.n, self.m) if name == "K" else (self.n_steps, self.m, self.m)
        return RefilteredPart(self, 0 if name == "K" else 1, shape)

    def _pending(self, start: int) -> bool:
        """Whether the kernel still seeds directly observed states at step ``start`` (no divergence)."""
        return bool(self.k.seed_at_start) and not bool(np.all(self.first_seed < start))

    def _settled(self, start: int) -> bool:
        """A block can start at ``start``: its seeding is done, or not begun (the kernel's flags all False)."""
        return not self._pending(start) or bool(np.all(self.first_seed >= start))

    def rows(self, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
        """(K, S) of steps start .. stop-1."""
        if stop <= start:
            return np.empty((0, self.n, self.m)), np.empty((0, self.m, self.m))
        if self.whole is not None or not self.exact_blocks:
            K, S = self.all()
            return K[start:stop], S[start:stop]
        if self.last is not None and self.last[:2] == (start, stop):  # K then S of the same rows
            return self.last[2], self.last[3]
        first = start // BLOCK
        blocks = [self.block(b) for b in range(first, (stop - 1) // BLOCK + 1)]
        cut = slice(start - first * BLOCK, stop - first * BLOCK)
        if len(blocks) == 1:
            K, S = blocks[0][0][cut], blocks[0][1][cut]
        else:
            K, S = np.concatenate([b[0] for b in blocks])[cut], np.concatenate([b[1] for b in blocks])[cut]
        self.last = (start, stop, K, S)
        return K, S

    def all(self) -> tuple[np.ndarray, np.ndarray]:
        """(K, S) of the whole run, filtered in one go and kept."""
        if self.whole is None:
            out = trace_buffers(
                self.n_steps, self.n, len(self.k.group_names), self.m,
                full_P=False, **self.store,
            )  # fmt: skip
            if self.n_steps:
                filter_into(*self.k.kernel_arguments(), out)
            self.whole = (out.K_out, out.S_out)
        return self.whole

    def block(self, b: int) -> tuple[np.ndarray, np.ndarray]:
        """(K, S) of block ``b``, filtered from the state the blocks before it left."""
        if self.cached is not None and self.cached[0] == b:
            return self.cached[1], self.cached[2]
        if self.carry is not None and self.carry[0] > b:
            self.carry = None  # a read that goes back: from the start again
        while True:
            following = 0 if self.carry is None else self.carry[0]
            K, S = self._filter(following)
            if following == b:
                self.cached = (b, K, S)
                return K, S

    def _filter(self, b: int) -> tuple[np.ndarray, np.ndarray]:
        """Filter block ``b`` from the carried state (none: b = 0, the run's prior) and carry its
        end state to block b + 1."""
        start = b * BLOCK
        stop = min(start + BLOCK, self.n_steps)
        carry = None if self.carry is None else (*self.carry[1:], self._pending(start))
        out, left = filter_rows(self.k, start, stop, carry, **self.store)
        self.carry = (b + 1, *left)
        offset = 0 if carry is None else 1  # the row before: the carried state
        return out.K_out[offset:], out.S_out[offset:]


def filter_rows(k: KernelInputs, start: int, stop: int, carry=None, *, predict_last: bool = False, **store):
    """The kernel's buffers, with the full P, of the packed run's steps start .. stop-1, and the state
    they leave to the steps after (x_post, P_post, the last finite input). From ``carry`` (x_post,
    P_post, last finite input and whether seeding is pending, of the step before ``start``: filtered
    as an extra first row without samples, with the held input), else from the run's prior at
    ``start``. ``predict_last``: the last step predicted, not updated. ``store``: `trace_buffers`'s
    store_gain, store_S, store_innovations."""
    model_id, model, sensors, data = k.kernel_arguments()
    first = start if carry is None else start - 1
    u, fresh = data.u[first:stop], data.fresh[first:stop]
    if carry is not None or predict_last:
        u, fresh = u.copy(), fresh.copy()
    if predict_last:
        fresh[-1] = False
    if carry is not None:
        x, P, u_last, pending = carry
        u[0], fresh[0] = u_last, False  # no update, no seeding: only the carried state
        model = model._replace(x0=x, P0=P, seed_at_start=pending)
    R_std = data.R_std[first:stop] if data.R_std.shape[0] == data.u.shape[0] else data.R_std
    data = data._replace(u=u, z=data.z[first:stop], fresh=fresh, R_std=R_std)
    out = trace_buffers(stop - first, model.x0.size, len(k.group_names), data.z.shape[1], full_P=True, **store)
    filter_into(model_id, model, sensors, data, out)
    finite = np.flatnonzero(np.all(np.isfinite(u), axis=1))
    u_last = u[finite[-1]].copy() if finite.size else k.u_default.copy()
    return out, (out.x_post[-1].copy(), out.P_post_full[-1].copy(), u_last)


class RefilteredPart:
    """K or S of a `Refiltered` run, read like the (N, ...) float64 array: a slice of steps is
    filtered on read; any other index, or ``np.asarray``, gives (and keeps) the whole run's."""

    ndim = 3
    dtype = np.dtype(np.float64)

    def __init__(self, source: Refiltered, which: int, shape: tuple[int, int, int]) -> None:
        self.source, self.which, self.shape = source, which, shape

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, index) -> np.ndarray:
        if isinstance(index, slice) and index.step in (None, 1):
            start, stop, _ = index.indices(self.shape[0])
            return self.source.rows(start, max(stop, start))[self.which]
        return self.source.all()[self.which][index]

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        whole = self.source.all()[self.which]
        return whole if dtype is None else whole.astype(dtype)
