"""The sensor beside the statistic: each measurement group's samples against the filter's prediction.

For a group an alarm names, the report draws per channel the measured value z, the filter's prior
measurement h(x_prior) = z - y with the +-k sigma band of the innovation covariance
(sigma_i = sqrt(S_ii)), and the normalised innovation y_i / sigma_i.

They come from the EKF's innovations (`Needs` part "y") and the aligned samples, which are freed
before the detectors' memory peak, and which group will alarm is known only after it. So right after
the filter every group is packed into 8 bytes per sample, as much as its float64 sample took:
the prediction as float32 (less the channel's median, so a value far from zero keeps its digits)
and the innovation and sigma as float16 (3 significant digits: figures only), each channel scaled
by a power of two near its median sigma so float16's range fits any unit. When the samples are
freed anyway the pack is written into their buffer: through the detectors the figures cost the
samples' memory (35 MB on a 1-hour 100 Hz quadcopter log), which would otherwise be freed.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

K_SIGMA = 3.0  # half-width of the band drawn around the prediction, in sigma of S
PACKED = np.dtype([("predicted", "<f4"), ("innovation", "<f2"), ("sigma", "<f2")])  # = one float64
ROWS_PER_BLOCK = 8_192  # a few MB of float64 at a time beside the pack


@dataclass
class SensorView:
    """One measurement group on the analysis grid, (N, k) float32 arrays, one column per channel,
    NaN where the filter did not update with the group.

    measured:   the sample the filter used, z.
    predicted:  h(x_prior) = z - y.
    sigma:      sqrt(S_ii), the innovation's standard deviation.
    normalised: y_i / sigma_i (about N(0, 1) on a consistent filter).
    """

    group: str
    channels: list[str]
    measured: np.ndarray
    predicted: np.ndarray
    sigma: np.ndarray
    normalised: np.ndarray


@dataclass
class Innovations:
    """Every group's prediction, innovation and sigma per step, packed: (N, m_total) `PACKED`,
    the prediction of column j less ``offset[j]``, its innovation and sigma divided by ``scale[j]``."""

    group_names: list[str]
    group_offsets: np.ndarray
    group_sizes: np.ndarray
    channels: dict[str, list[str]]
    packed: np.ndarray
    scale: np.ndarray
    offset: np.ndarray

    def _columns(self, group: str) -> slice | None:
        if group not in self.group_names:
            return None
        g = self.group_names.index(group)
        return slice(int(self.group_offsets[g]), int(self.group_offsets[g] + self.group_sizes[g]))

    def view(self, group: str) -> SensorView | None:
        """The group's `SensorView` (float32 arrays, made now, each channel a contiguous column),
        None for a group it does not hold."""
        columns = self._columns(group)
        if columns is None:
            return None
        fields = self._fields(columns)
        n, k = self.packed.shape[0], columns.stop - columns.start
        measured, predicted, sigma, normalised = (np.empty((n, k), dtype=np.float32, order="F") for _ in range(4))
        for j, c in enumerate(range(columns.start, columns.stop)):
            column = fields[j]
            p = np.add(column["predicted"], self.offset[c], dtype=np.float64)  # float64 while the offset is added back
            innovation, sigma_scaled = _halves(column["innovation"]), _halves(column["sigma"])
            predicted[:, j] = p
            # z = h(x_prior) + y in float64, rounded once to float32 (as before the pack)
            np.add(p, _scaled(innovation, self.scale[c]), out=measured[:, j], dtype=np.float64, casting="unsafe")
            np.copyto(sigma[:, j], _scaled(sigma_scaled, self.scale[c]), casting="unsafe")
            normalised[:, j] = _quotient(innovation, sigma_scaled)
        return SensorView(group, self.channels[group], measured, predicted, sigma, normalised)

    def _fields(self, columns: slice) -> np.ndarray:
        """The group's columns of the pack, (k, N) `PACKED`, each a contiguous row: one pass over the
        pack's rows (a field read column by column is a pass over every group's bytes each time)."""
        as_words = self.packed.view(np.uint64)  # one 8-byte word per (step, channel)
        return np.ascontiguousarray(as_words[:, columns].T).view(PACKED)

    def predicted(self, group: str, channels: Sequence[int]) -> np.ndarray | None:
        """The group's predictions h(x_prior) of these of its channels (indices into the group),
        (N, len(channels)) float32 as its `view` has them; None for a group it does not hold."""
        columns = self._columns(group)
        if columns is None:
            return None
        chosen = [columns.start + int(j) for j in channels]
        return (self.packed["predicted"][:, chosen] + self.offset[chosen]).astype(np.float32)

    def times(self, group: str, t: np.ndarray) -> np.ndarray:
        """The times of the group's rows: the analysis grid ``t`` itself (every step is a row; block
        mode's `logscan.report.kept_views.KeptRows` has times of its own)."""
        return t

    def normalised(self, group: str) -> np.ndarray | None:
        """The group's normalised innovations alone, (N, k) float32 as its `view` has them (a
        quarter of the work: the overview of every group draws nothing else); None for a group
        it does not hold."""
        columns = self._columns(group)
        if columns is None:
            return None
        part = self.packed[:, columns]  # one pass over the pack's rows, no table: a few times faster here
        return _quotient(part["innovation"], part["sigma"])


class GroupRows(Protocol):
    """What the report reads of the filter's innovations: `Innovations` (every step of the grid)
    or block mode's kept rows (`logscan.report.kept_views.KeptRows`, times of their own)."""

    group_names: list[str]
    channels: dict[str, list[str]]

    def view(self, group: str) -> SensorView | None: ...
    def times(self, group: str, t: np.ndarray) -> np.ndarray: ...
    def normalised(self, group: str) -> np.ndarray | None: ...
    def predicted(self, group: str, channels: Sequence[int]) -> np.ndarray | None: ...


class PageViews:
    """The groups' `SensorView`s while one page is built, each made once: a view the headlines ask
    for (`view`) is kept until the group's sensor figures take it (`take`: a group is drawn once
    per page), so no more views are held at a time than the headlines held before."""

    def __init__(self, innovations: GroupRows):
        self.innovations = innovations
        self.group_names = innovations.group_names
        self._kept: dict[str, SensorView | None] = {}

    def view(self, group: str) -> SensorView | None:
        """The group's view, kept for the next caller."""
        if group not in self._kept:
            self._kept[group] = self.innovations.view(group)
        return self._kept[group]

    def times(self, group: str, t: np.ndarray) -> np.ndarray:
        """The times of the group's view's rows (``t``: the analysis grid)."""
        return self.innovations.times(group, t)

    def take(self, group: str) -> SensorView | None:
        """The group's view, no longer kept."""
        return self._kept.pop(group) if group in self._kept else self.innovations.view(group)


# every float16's value as float32, by its bits: numpy converts float16 element by element, a
# table lookup is a few times faster and gives the same values
_HALF_VALUES = np.arange(1 << 16, dtype=np.uint32).astype(np.uint16).view(np.float16).astype(np.float32)
# scales that keep every float16 value (2^-24 to 65504) a normal float32 (2^-126 to 2^128)
_SCALE_RANGE = (2.0**-100, 2.0**100)


def _halves(values: np.ndarray) -> np.ndarray:
    """float16 ``values`` (a packed field) as float32, exactly."""
    return np.take(_HALF_VALUES, values.view(np.uint16))


def _scaled(halves: np.ndarray, scale: float) -> np.ndarray:
    """``halves`` (float16 values as float32) times the column's power-of-two ``scale``: in float32,
    exact, as float64's product rounded to float32 is, where the scale keeps every float16 value a
    normal float32 (else in float64)."""
    if _SCALE_RANGE[0] <= scale <= _SCALE_RANGE[1]:
        return np.multiply(halves, np.float32(scale))
    return np.multiply(halves, scale, dtype=np.float64)


def _quotient(innovation: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """y_i / sigma_i from the packed (scaled) values, float16 or as float32, as float32: both carry
    the column's power-of-two scale, which cancels exactly (within float32's range), and the float32
    quotient of the float16 values is their float64 quotient rounded to float32."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.divide(innovation, sigma, dtype=np.float32)


def _divisor(scale: np.ndarray, y_dtype: np.dtype) -> np.ndarray:
    """The columns' power-of-two ``scale`` to divide float32 innovations by in float32: exact, so
    rounded once to float16 as float64's quotient is (a quotient float32 cannot hold normally is
    below float16's least or beyond its range either way: 0 or inf alike); float64 otherwise."""
    fits = y_dtype == np.float32 and bool(np.all((scale >= _SCALE_RANGE[0]) & (scale <= _SCALE_RANGE[1])))
    return scale.astype(np.float32) if fits else scale


def _channel_scales(S_diag: np.ndarray) -> np.ndarray:
    """A power of two near each column's median sigma (1 for a column never updated)."""
    sample = S_diag[:: max(S_diag.shape[0] // 10_000, 1)].astype(np.float64)
    with np.errstate(invalid="ignore"):
        sample[~(sample > 0) | ~np.isfinite(sample)] = np.nan
    scale = np.ones(S_diag.shape[1])
    for j in range(S_diag.shape[1]):  # a handful of columns
        column = sample[:, j]
        if np.isfinite(column).any():
            scale[j] = 2.0 ** np.round(np.log2(np.sqrt(np.nanmedian(column))))
    return scale


def _channel_offsets(samples, n_steps: int, m_total: int) -> np.ndarray:
    """Each column's median over up to 10,000 evenly spaced steps (0 for a column all NaN)."""
    rows = np.arange(0, n_steps, max(n_steps // 10_000, 1))
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns
        offset = np.nanmedian(samples(rows), axis=0) if rows.size else np.zeros(m_total)
    return np.where(np.isfinite(offset), offset, 0.0)


def pack_innovations(run, trace, samples: np.ndarray | None = None) -> Innovations:
    """Pack the trace's innovations (``trace.y``, ``trace.S_diag``) with the groups' samples.

    ``samples``: the (N, m_total) float64 array of every group's samples side by side in the
    trace's group order (`logscan.filters.ekf.pack_run`'s layout); given, the pack is written into
    its buffer, block by block, and it no longer holds samples (the caller drops it)."""
    n_steps, m_total = trace.y.shape
    blocks = [run.groups[name] for name in trace.group_names]

    def z_of(rows) -> np.ndarray:
        if samples is not None:
            return samples[rows].copy()  # a copy: read before the block is overwritten
        return np.concatenate([np.asarray(group.z[rows], dtype=np.float64).reshape(-1, int(size))
                               for group, size in zip(blocks, trace.group_sizes)], axis=1)  # fmt: skip

    scale = _channel_scales(trace.S_diag)
    offset = _channel_offsets(z_of, n_steps, m_total)
    packed = np.empty((n_steps, m_total), dtype=PACKED) if samples is None else samples.view(PACKED)
    over_scale = _divisor(scale, trace.y.dtype)
    for start in range(0, n_steps, ROWS_PER_BLOCK):
        rows = slice(start, min(start + ROWS_PER_BLOCK, n_steps))
        z = z_of(rows)  # a block of its own: the arithmetic below is in place
        y = trace.y[rows]  # float32: widened exactly where float64 meets it
        with np.errstate(invalid="ignore", over="ignore"):
            sigma = np.sqrt(trace.S_diag[rows], dtype=np.float64)
            sigma /= scale
            # h(x_prior) = z - y; y and sigma in float16 (beyond its range: inf, a gap in the figure)
            block = packed[rows]
            z -= y
            z -= offset
            block["predicted"] = z
            block["innovation"] = np.divide(y, over_scale)
            block["sigma"] = sigma
    channels = {name: list(run.groups[name].channels) for name in trace.group_names}
    return Innovations(
        list(trace.group_names),
        np.asarray(trace.group_offsets),
        np.asarray(trace.group_sizes),
        channels,
        packed,
        scale,
        offset,
    )
