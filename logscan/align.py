"""Alignment of a Log onto a profile's analysis grid: zero-order hold, staleness, fresh-sample masks.

INTERFACE (fixed): downstream code (filters, detectors, simulator tests) relies only on the
dataclasses below; fields may be added with defaults, never renamed or removed.

Time stays integer nanoseconds until the grid is built. Each channel is cleaned once (stable sort,
duplicate timestamps dropped keeping the last, non-finite samples removed and counted), then held
onto the grid with one compiled merge pass (numba): z[k] is the latest sample at or before t_k when it is no
older than the staleness limit, else NaN.

Time sanity (`logscan.timebase.time_sanity`, docs/algorithms.md section 8.1): the grid spans where the
input and measurement channels are dense (outlying runs dropped with a warning), its size is
checked before anything is allocated, and ``start_s``/``end_s`` cut it to a window of the log.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit

from logscan import conversions
from logscan.numba_cache import follow_dependencies
from logscan.timebase.time_sanity import MAX_GRID_STEPS, check_window, dense_span, grid, outlier_warnings, outlying_runs


@dataclass
class AlignedGroup:
    """One measurement group on the grid.

    z:      (N, m) float64, zero-order held value of each channel within the staleness limit,
            NaN where no sample is recent enough (never zero-filled). A profile group with
            ``scale`` / ``offset`` holds raw * scale + offset; with ``from`` (`logscan.conversions`),
            m is the converted width (3) and ``channels`` names each converted output (e.g.
            ``/vehicle_attitude_0/q[0..3] roll``), as with a converting ``frame`` ("flu": forward,
            right, down; "enu": north, east, down); ``nonfinite_count`` counts the raw channels.
    fresh:  (N,) bool, True at grid steps where every channel of the group has a sample newer than
            the previous grid step and not older than the staleness limit (the filter updates then).
            A profile group with ``fresh = "on_change"``: True where at least one channel's held
            value differs from the previous grid step's (a forward-filled CSV column's repeats are
            not new measurements); ``channel_fresh`` still marks the samples' arrivals.
    """

    name: str
    channels: list[str]
    z: np.ndarray
    fresh: np.ndarray
    noise_std: np.ndarray | None = None  # (m,) from the profile, None: the model's default
    nonfinite_count: int = 0  # non-finite samples masked out before holding
    # Optional additions (alignment fills them; defaults keep hand-built groups valid):
    range_lo: np.ndarray | None = None  # (m,) profile override of the physical range, None: model's
    range_hi: np.ndarray | None = None
    rate_hz: float | None = None  # nominal rate from the profile
    stale_s: float | None = None  # staleness limit used for holding
    channel_fresh: np.ndarray | None = None  # (N, m) bool, per channel: a new sample in (t_{k-1}, t_k]
    labels: list[str] | None = None  # the profile's name of each channel ([redundant] sensors), if named
    # (N, m) per-sample noise std held from the profile's noise_channels (NaN: the group's noise_std)
    noise_std_series: np.ndarray | None = None
    gated_s: float = 0.0  # time its gate was closed (no 3D fix): no sample there, and none expected
    # a `from = "geodetic"` group: the (lat deg, lon deg, alt m) its north/east/down are relative to
    origin: tuple[float, float, float] | None = None


class HeldTable:
    """Columns held onto the grid but stored at their own rate: the samples (M, c) and, per grid
    step, the row held there (-1: none within the staleness limit). Reads like the dense (N, c)
    array (``table[rows]``, ``np.asarray(table)``); a 50 Hz on-board estimate on a 100 Hz grid
    takes half the memory plus 4 bytes a step."""

    def __init__(self, samples: np.ndarray, row: np.ndarray):
        self.samples = samples
        self.row = row
        self.shape = (int(row.size), int(samples.shape[1]))
        self.ndim = 2
        self.dtype = samples.dtype

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, rows) -> np.ndarray:
        held = self.row[rows]
        out = self.samples[np.maximum(held, 0)]
        out[held < 0] = np.nan
        return out

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        dense = self[:]
        return dense if dtype is None else dense.astype(dtype)


@dataclass
class AlignedRun:
    """Everything a filter needs, on one uniform grid of N steps of period dt (seconds).

    t:        (N,) float64 seconds since the log's start_ns (grid point k is t0 + k*dt).
    u:        (N, nu) float64 model inputs held within their staleness limit (NaN where stale).
    u_fresh:  (N,) bool, every input channel valid at the step.
    groups:   measurement groups by name, in the profile's order.
    mode:     (N,) float64 mode / set-point channel, or None.
    onboard_state / onboard_variance: (N, n) held on-board estimator channels (a `HeldTable` when
              the columns share their sample times, else an array), or None.
    """

    t: np.ndarray
    dt: float
    start_ns: int
    u: np.ndarray
    u_fresh: np.ndarray
    input_channels: list[str]
    groups: dict[str, AlignedGroup]
    mode: np.ndarray | None = None
    ground: np.ndarray | None = None  # (N,) the [alarms] ground_channel held (non-zero: on the ground)
    onboard_state: np.ndarray | HeldTable | None = None
    onboard_variance: np.ndarray | HeldTable | None = None
    warnings: list[str] = field(default_factory=list)
    gaps: list[tuple[float, float, str]] = field(default_factory=list)  # (start s, end s, channel)
    # Optional additions (alignment fills them):
    input_names: list[str] = field(default_factory=list)  # model input name of each column of u
    mode_channel: str | None = None
    onboard_names: list[str] = field(default_factory=list)  # column names (model states)
    onboard_state_channels: list[str | None] = field(default_factory=list)
    onboard_variance_channels: list[str | None] = field(default_factory=list)
    redundant: dict[str, AlignedGroup] = field(default_factory=dict)  # sensors as channels
    channel_stats: dict[str, dict[str, int]] = field(default_factory=dict)  # samples, nonfinite, ...
    window: tuple[float | None, float | None] | None = None  # --start/--end (s since start_ns), if given

    @property
    def n_steps(self) -> int:
        return int(self.t.size)


# ------------------------------------------------------------------------------------------------
# Implementation
# ------------------------------------------------------------------------------------------------

_NS = 1_000_000_000
_NEVER_STALE_NS = np.iinfo(np.int64).max // 4  # stale_s = inf
_MAX_GAP_WARNINGS = 20


@dataclass
class _Clean:
    """One channel after cleaning: sorted unique int64 ns times with finite float64 values."""

    t: np.ndarray
    values: np.ndarray
    samples: int
    nonfinite: int
    unsorted: int
    duplicates: int
    outliers: int = 0  # outlying samples dropped (see `outlying_runs`)


def stale_ns(stale_s: float) -> int:
    """A staleness limit in integer nanoseconds (inf: never stale)."""
    if not np.isfinite(stale_s):
        return int(_NEVER_STALE_NS)
    return int(round(stale_s * _NS))


def clean_samples(t_ns: np.ndarray, values: np.ndarray) -> _Clean:
    """Stable-sort by time, drop duplicate timestamps (keep the last), then drop non-finite values."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    values = np.asarray(values, dtype=np.float64)
    samples = int(t_ns.size)
    unsorted = int(np.count_nonzero(t_ns[1:] < t_ns[:-1]))
    if unsorted:
        order = np.argsort(t_ns, kind="stable")
        t_ns, values = t_ns[order], values[order]
    last_of_run = np.ones(t_ns.size, dtype=bool)
    last_of_run[:-1] = t_ns[1:] != t_ns[:-1]
    duplicates = int(t_ns.size - np.count_nonzero(last_of_run))
    if duplicates:
        t_ns, values = t_ns[last_of_run], values[last_of_run]
    finite = np.isfinite(values)
    nonfinite = int(finite.size - np.count_nonzero(finite))
    if nonfinite:
        t_ns, values = t_ns[finite], values[finite]
    return _Clean(t_ns, values, samples, nonfinite, unsorted, duplicates)


@njit(cache=True)
def _hold_kernel(t_ns, values, grid_ns, limit_ns, z, fresh):  # pragma: no cover - compiled
    # One merge pass over two sorted arrays: i = max{i : t_i <= g_k} (-1: none yet).
    i = -1
    n_t = t_ns.size
    for k in range(grid_ns.size):
        g = grid_ns[k]
        while i + 1 < n_t and t_ns[i + 1] <= g:
            i += 1
        if i >= 0 and g - t_ns[i] <= limit_ns:
            z[k] = values[i]
            fresh[k] = k == 0 or t_ns[i] > grid_ns[k - 1]
        else:
            z[k] = np.nan
            fresh[k] = False


def hold(t_ns: np.ndarray, values: np.ndarray, grid_ns: np.ndarray, limit_ns: int, z=None, fresh=None):
    """Zero-order hold of sorted unique samples onto ``grid_ns`` within ``limit_ns``.

    Returns (z, fresh): z[k] = the latest sample at or before grid_ns[k] if it is at most
    ``limit_ns`` old, else NaN; fresh[k] = that sample is newer than grid_ns[k-1] (for k = 0:
    any sample within the limit). A compiled merge of the two sorted arrays, O(N + M);
    ``z`` / ``fresh`` may be given (e.g. a column of a 2-D array) to be written in place.
    """
    n = grid_ns.size
    z = np.empty(n) if z is None else z
    fresh = np.empty(n, dtype=np.bool_) if fresh is None else fresh
    _hold_kernel(
        np.ascontiguousarray(t_ns, dtype=np.int64),
        np.ascontiguousarray(values, dtype=np.float64),
        np.ascontiguousarray(grid_ns, dtype=np.int64),
        np.int64(limit_ns),
        z,
        fresh,
    )
    return z, fresh


@njit(cache=True)
def _gap_kernel(t_ns, g0, g1, limit_ns, starts, ends):  # pragma: no cover - compiled
    # Stretches without a sample inside [g0, g1] longer than the limit; edges: the last sample
    # before g0 (else g0), every sample in [g0, g1], then g1. Writes up to starts.size of them
    # (pass empty arrays to only count) and returns how many there are.
    i0 = np.searchsorted(t_ns, g0)  # first sample >= g0
    i1 = np.searchsorted(t_ns, g1, side="right")  # one past the last sample <= g1
    prev = t_ns[i0 - 1] if i0 > 0 else g0
    count = 0
    for i in range(i0, i1 + 1):
        cur = t_ns[i] if i < i1 else g1
        if cur - prev > limit_ns:
            if count < starts.size:
                starts[count] = prev
                ends[count] = cur
            count += 1
        prev = cur
    return count


def _gaps(t_ns: np.ndarray, limit_ns: int, grid_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(start_ns, end_ns) of every stretch of the grid span without a sample for > limit_ns.

    A stretch starts at the last sample before the span when there is one, else at the span
    start, and the one after the last sample ends at the span end; each counts only when it
    exceeds the limit.
    """
    args = (t_ns, np.int64(grid_ns[0]), np.int64(grid_ns[-1]), np.int64(limit_ns))
    count = _gap_kernel(*args, np.empty(0, np.int64), np.empty(0, np.int64))
    starts, ends = np.empty(count, np.int64), np.empty(count, np.int64)
    _gap_kernel(*args, starts, ends)
    return starts, ends


class _Aligner:
    """Holds every channel the profile names onto one grid, cleaning each channel once."""

    def __init__(self, log, profile):
        self.log = log
        self.profile = profile
        self.cache: dict[str, _Clean] = {}
        self.warnings: list[str] = []
        self.gaps: list[tuple[float, float, str]] = []
        self.gap_reported: set[tuple[str, int]] = set()
        # (topic, count, stale_s, longest, its start) -> the channels with those gaps (`gap_lines`)
        self.gap_channels: dict[tuple, list[str]] = {}
        self.start_ns = 0
        self.dropped: dict[str, np.ndarray] = {}  # channel -> outlying times dropped (ns)
        self.ends = ("", "")  # the channels that start first and end last (after `span`)

    def clean(self, name: str) -> _Clean:
        if name not in self.cache:
            ch = self.log.channels[name]
            c = clean_samples(ch.t, ch.values)
            if c.unsorted:
                self.warnings.append(
                    f"channel {name!r}: timestamps out of order ({c.unsorted} backward steps): sorted (stable)"
                )
            if c.duplicates:
                self.warnings.append(
                    f"channel {name!r}: {c.duplicates} duplicate timestamps dropped (kept the last sample)"
                )
            if c.nonfinite:
                self.warnings.append(
                    f"channel {name!r}: {c.nonfinite} non-finite samples (NaN/inf) masked out, not held"
                )
            self.cache[name] = c
        return self.cache[name]

    def span(self, names: list[str]) -> tuple[int, int]:
        """(first, last) ns of the ``names`` where they are dense (`time_sanity.dense_span`); the
        outlying samples are dropped from the cleaned channels and kept in ``dropped``."""
        times = {name: self.clean(name).t for name in dict.fromkeys(names) if self.clean(name).t.size}
        first, last, drops, self.ends = dense_span(times, self.log.source.path)
        for name, drop in drops.items():
            c = self.cache[name]
            self.dropped[name] = c.t[drop]
            keep = ~drop
            self.cache[name] = replace(c, t=c.t[keep], values=c.values[keep], outliers=int(drop.sum()))
        return first, last

    def hold(self, name: str | None, grid_ns: np.ndarray, limit_s: float, transform=None, z=None, fresh=None):
        n = grid_ns.size
        if name is None:
            return np.full(n, np.nan), np.zeros(n, dtype=bool)
        c = self.clean(name)
        values = c.values if transform is None else transform(c.values)
        limit = stale_ns(limit_s)
        z, fresh = hold(c.t, values, grid_ns, limit, z, fresh)
        key = (name, limit)
        if key not in self.gap_reported:
            self.gap_reported.add(key)
            g_start, g_end = _gaps(c.t, limit, grid_ns)
            if g_start.size:
                s = (g_start - self.start_ns) / _NS
                e = (g_end - self.start_ns) / _NS
                self.gaps.extend((float(a), float(b), name) for a, b in zip(s, e))
                longest = int(np.argmax(e - s))
                gap = (g_start.size, f"{limit_s:g}", f"{e[longest] - s[longest]:.3f}", f"{s[longest]:.3f}")
                self.gap_channels.setdefault((name.rsplit("/", 1)[0], *gap), []).append(name)
        return z, fresh

    def gap_lines(self) -> list[str]:
        """One warning per topic's channels with the same gaps (a GNSS receiver's ten fields lost
        together are one line), at most _MAX_GAP_WARNINGS."""
        lines = []
        for (topic, count, limit, longest, at), names in self.gap_channels.items():
            if len(names) == 1:
                what = f"channel {names[0]!r}: {count} gap{'s' if count > 1 else ''}"
            else:
                fields = ", ".join(name[len(topic) + 1 :] for name in names)
                what = f"channels {topic}/{{{fields}}}: {count} gap{'s' if count > 1 else ''} each"
            lines.append(
                f"{what} longer than stale_s={limit} s (longest {longest} s from t={at} s); held values are NaN there"
            )
        return lines[:_MAX_GAP_WARNINGS]

    def table(
        self, channels: list[str | None], grid_ns: np.ndarray, limit_s: float, dtype=np.float64
    ) -> np.ndarray | HeldTable:
        """The ``channels`` held onto the grid (None: a NaN column): a `HeldTable` of ``dtype``
        samples when they share their sample times (one topic), else a dense (N, c) float64 array."""
        n = grid_ns.size
        named = [ch for ch in channels if ch is not None]
        column = np.empty(n)
        scratch = np.empty(n, dtype=bool)
        shared = bool(named) and all(np.array_equal(self.clean(ch).t, self.clean(named[0]).t) for ch in named)
        if not shared:
            arr = np.full((n, len(channels)), np.nan)
            for j, ch in enumerate(channels):
                if ch is not None:
                    self.hold(ch, grid_ns, limit_s, z=arr[:, j], fresh=scratch)
            return arr
        for ch in named:  # the gaps and warnings of each channel, as a dense hold reports them
            self.hold(ch, grid_ns, limit_s, z=column, fresh=scratch)
        t = self.clean(named[0]).t
        samples = np.full((t.size, len(channels)), np.nan, dtype=dtype)
        for j, ch in enumerate(channels):
            if ch is not None:
                samples[:, j] = self.clean(ch).values
        held, _ = hold(t, np.arange(t.size, dtype=np.float64), grid_ns, stale_ns(limit_s), column, scratch)
        row = np.where(np.isnan(held), -1, held).astype(np.int32 if t.size < 2**31 else np.int64)
        return HeldTable(samples, row)

    def measurement_group(self, spec, grid_ns: np.ndarray, z: np.ndarray) -> AlignedGroup:
        """A profile's measurement group held into ``z`` (N, spec.width): each channel times its
        ``scale`` plus its ``offset``, then, with ``from`` or a converting ``frame``, the held
        channels converted (`logscan.conversions`); with a ``gate``, the steps where the gate
        channel is below its minimum (a GNSS fix type under 3) hold no sample (NaN, not fresh)."""
        group = self._measurement_group(spec, grid_ns, z)
        if getattr(spec, "fresh", "on_sample") == "on_change":
            group.fresh = changed_steps(group.z)
        if getattr(spec, "gate_channel", None):
            gate, _ = self.hold(spec.gate_channel, grid_ns, spec.stale_s, fresh=np.empty(grid_ns.size, dtype=bool))
            closed = ~(np.nan_to_num(gate, nan=-np.inf) >= spec.gate_min)
            if closed.any():
                group.z[closed] = np.nan
                group.fresh = group.fresh & ~closed
                if group.channel_fresh is not None:
                    group.channel_fresh = group.channel_fresh & ~closed[:, None]
                dt = float(np.median(np.diff(grid_ns))) / _NS if grid_ns.size > 1 else 0.0
                group.gated_s = float(closed.sum()) * dt
                self.warnings.append(
                    f"group {spec.name!r}: {spec.gate_channel} below {spec.gate_min:g} for {group.gated_s:.1f} s "
                    f"of {grid_ns.size * dt:.1f} s; no sample used there"
                )
        return group

    def _measurement_group(self, spec, grid_ns: np.ndarray, z: np.ndarray) -> AlignedGroup:
        transforms = _linear_transforms(spec.scale, spec.offset, len(spec.channels))
        if not spec.converted:
            return self.group(spec.name, spec.channels, grid_ns, spec.stale_s, transforms, z=z)
        raw = self.group(spec.name, spec.channels, grid_ns, spec.stale_s, transforms)
        origin = None
        channel_fresh = np.repeat(raw.fresh[:, None], spec.width, axis=1)
        if spec.source is None:  # a 3-vector's frame: FLU -> FRD or ENU -> NED
            z[:] = conversions.vector_to_frd_ned(raw.z, spec.frame)
            channel_fresh = raw.channel_fresh[:, [1, 0, 2]] if spec.frame == "enu" else raw.channel_fresh
        elif spec.source == "quaternion":
            invalid = int(np.count_nonzero(conversions.invalid_quaternions(raw.z)))
            z[:] = conversions.convert("quaternion", raw.z, frame=spec.frame)
            if invalid:
                lo, hi = conversions.QUATERNION_NORM_LIMITS
                self.warnings.append(
                    f"group {spec.name!r}: {invalid} grid step{'s hold' if invalid > 1 else ' holds'} a quaternion "
                    f"whose norm is outside [{lo:g}, {hi:g}]; roll, pitch and yaw are NaN there (not used)"
                )
        else:
            origin = tuple(spec.origin) if spec.origin is not None else self.first_fix(spec, grid_ns, raw)
            if origin is None:
                z[:] = np.nan
                self.warnings.append(
                    f"group {spec.name!r}: no sample with a valid latitude, longitude and altitude in the "
                    "window to take as the origin; its values are NaN (give [measurements."
                    f"{spec.name}] origin = [lat_deg, lon_deg, alt_m])"
                )
            else:
                z[:] = conversions.geodetic_to_local(raw.z, origin, spec.frame)
        label = _group_label(spec.channels)
        return AlignedGroup(
            name=spec.name,
            channels=[f"{label} {out}" for out in spec.output_names()],
            z=z,
            fresh=raw.fresh,
            nonfinite_count=raw.nonfinite_count,
            stale_s=raw.stale_s,
            channel_fresh=channel_fresh,
            origin=None if origin is None else tuple(float(v) for v in origin),
        )

    def first_fix(self, spec, grid_ns: np.ndarray, raw: AlignedGroup) -> tuple[float, float, float] | None:
        """The default origin of a geodetic group: its first sample inside the grid's span with a
        finite altitude and a latitude / longitude in range (the cleaned samples, scaled, at times
        all three channels share), else the first fresh grid step with such values."""
        cleaned = [self.clean(ch) for ch in spec.channels]
        scale = spec.scale or [1.0] * len(cleaned)
        offset = spec.offset or [0.0] * len(cleaned)
        times = cleaned[0].t
        for c in cleaned[1:]:
            times = np.intersect1d(times, c.t, assume_unique=True)
        times = times[(times >= grid_ns[0]) & (times <= grid_ns[-1])]
        if times.size:
            lla = np.stack(
                [c.values[np.searchsorted(c.t, times)] * f + o for c, f, o in zip(cleaned, scale, offset)],
                axis=1,
            )
            usable = conversions.valid_geodetic(lla)
            if getattr(spec, "gate_channel", None):  # the origin is a fix the gate lets through
                gate = self.clean(spec.gate_channel)
                i = np.searchsorted(gate.t, times, side="right") - 1
                usable &= (i >= 0) & (gate.values[np.maximum(i, 0)] >= spec.gate_min)
            ok = np.flatnonzero(usable)
            if ok.size:
                return tuple(float(v) for v in lla[ok[0]])
        ok = np.flatnonzero(raw.fresh & conversions.valid_geodetic(raw.z))
        return tuple(float(v) for v in raw.z[ok[0]]) if ok.size else None

    def group(self, name: str, channels, grid_ns, limit_s: float, transforms=None, z=None) -> AlignedGroup:
        m = len(channels)
        n = grid_ns.size
        z = np.empty((n, m)) if z is None else z
        ch_fresh = np.empty((n, m), dtype=bool)
        for j, ch in enumerate(channels):
            self.hold(ch, grid_ns, limit_s, transforms[j] if transforms else None, z[:, j], ch_fresh[:, j])
        fresh = ch_fresh[:, 0].copy() if m else np.zeros(n, dtype=bool)
        for j in range(1, m):
            fresh &= ch_fresh[:, j]
        if m > 1:
            fewest = min(int(np.count_nonzero(ch_fresh[:, j])) for j in range(m))
            n_fresh = int(np.count_nonzero(fresh))
            if fewest and n_fresh < 0.5 * fewest:
                self.warnings.append(
                    f"group {name!r}: its channels arrive at different times; only {n_fresh} "
                    f"grid steps have a new sample on every channel (a channel alone has {fewest}); "
                    f"a group should map channels logged together (one topic)"
                )
        return AlignedGroup(
            name=name,
            channels=list(channels),
            z=z,
            fresh=fresh,
            nonfinite_count=sum(self.clean(ch).nonfinite for ch in channels if ch is not None),
            stale_s=float(limit_s),
            channel_fresh=ch_fresh,
        )


def changed_steps(z: np.ndarray) -> np.ndarray:
    """(N,) bool: the grid steps where at least one column of ``z`` (N, m) holds a finite value
    that differs from the step before (step 0: any finite value). A held value changes only when
    a new sample arrives, so these are the new samples that are not repeats (``fresh =
    "on_change"``); a value back after a stale gap (NaN before it) counts as changed."""
    finite = np.isfinite(z)
    out = np.zeros(z.shape[0], dtype=bool)
    if z.shape[0]:
        out[0] = finite[0].any()
        out[1:] = ((z[1:] != z[:-1]) & finite[1:]).any(axis=1)
    return out


def _linear(factor: float, offset: float):
    """values * factor + offset (the identity skipped, a plain multiply without an offset)."""
    if offset == 0.0:
        return None if factor == 1.0 else (lambda values: values * factor)
    return lambda values: values * factor + offset


def _linear_transforms(scale, offset, n: int) -> list | None:
    """Per channel ``raw * scale + offset`` (None lists: 1 and 0), None when every one is the identity."""
    if scale is None and offset is None:
        return None
    scale = scale if scale is not None else [1.0] * n
    offset = offset if offset is not None else [0.0] * n
    transforms = [_linear(f, o) for f, o in zip(scale, offset)]
    return transforms if any(t is not None for t in transforms) else None


def _group_label(channels: list[str]) -> str:
    """One short name for the channels of a converted group: ``/a/q[0..3]`` for indexed channels
    of one field, ``/gps/{lat,lon,alt}`` for fields under one topic, else the names joined by commas."""
    prefix = os.path.commonprefix(channels)
    rests = [ch[len(prefix) :] for ch in channels]
    if prefix.endswith("[") and all(re.fullmatch(r"\d+\]", r) for r in rests):
        idx = [int(r[:-1]) for r in rests]
        consecutive = idx == list(range(idx[0], idx[0] + len(idx)))
        return f"{prefix}{idx[0]}..{idx[-1]}]" if consecutive else f"{prefix}{','.join(map(str, idx))}]"
    cut = max(prefix.rfind(sep) for sep in "/._")
    if cut >= 0 and all(ch[cut + 1 :] for ch in channels):
        return f"{prefix[: cut + 1]}{{{','.join(ch[cut + 1 :] for ch in channels)}}}"
    return ",".join(channels)


def align(log, profile, *, start_s: float | None = None, end_s: float | None = None) -> AlignedRun:
    """Put ``log`` onto ``profile``'s analysis grid (see the module docstring for the rules),
    from ``start_s`` to ``end_s`` seconds since the log's start when given.

    Raises ProfileError when the profile names channels the log lacks (with close names),
    InputError when none of its input/measurement channels holds a finite sample, the grid is
    over MAX_GRID_STEPS or the window misses the log, and UsageError for a window with end <= start.
    """
    from numpy.polynomial import polynomial as P

    check_window(start_s, end_s)
    profile.check_channels(log)
    aligner = _Aligner(log, profile)
    rate = float(profile.vehicle.rate_hz)
    input_channels = list(profile.inputs.channels)
    span_channels = input_channels + [ch for g in profile.measurements.values() for ch in g.channels]
    first, last = aligner.span(span_channels)
    origin = getattr(log, "origin_ns", log.start_ns)  # the log's own time zero, whatever was read
    start_ns = int(origin) if origin is not None else first
    early = [int(times[0]) for times in aligner.dropped.values() if times[0] < first]
    if early and start_ns <= max(early):  # the log's start is an outlier: count from the grid's
        start_ns = first
    aligner.start_ns = start_ns
    kept = {name: aligner.cache[name].t.size for name in aligner.dropped}
    aligner.warnings.extend(outlier_warnings(aligner.dropped, kept, start_ns))
    window = None if start_s is None and end_s is None else (start_s, end_s)
    grid_ns, k0 = grid(first, last, rate, window, start_ns, aligner.ends, log.source.path)
    n = grid_ns.size
    dt = 1.0 / rate
    t = (first - start_ns) / _NS + (k0 + np.arange(n)) * dt

    u = np.empty((n, len(input_channels)))
    scratch = np.empty(n, dtype=bool)  # fresh masks nobody reads
    # an input table's scale, offset and frame ("flu": the 2nd and 3rd negated), per bound channel
    input_transforms = _linear_transforms(
        profile.inputs.factors or None, profile.inputs.offsets or None, len(input_channels)
    )
    # an input stamped when it starts to act holds from the next step: step k (x_{k-1} -> x_k)
    # takes the input logged at or before t_{k-1}
    input_grid_ns = grid_ns
    if profile.inputs.stamp == "start" and n:  # the previous grid time itself (not t_k - dt, rounded)
        input_grid_ns = np.concatenate(([grid_ns[0] - int(round(dt * _NS))], grid_ns[:-1]))
    for j, ch in enumerate(input_channels):
        transform = input_transforms[j] if input_transforms else None
        aligner.hold(ch, input_grid_ns, profile.inputs.stale_s, transform, z=u[:, j], fresh=scratch)
    u_fresh = np.ones(n, dtype=bool)
    for j in range(u.shape[1]):
        u_fresh &= np.isfinite(u[:, j])

    groups: dict[str, AlignedGroup] = {}
    # the groups' samples side by side in one (N, m_total) array, in the profile's order: the
    # filter reads it in place (`filters.ekf.pack_run`) instead of a copy; a group with `from`
    # takes its converted width
    z_all = np.empty((n, sum(spec.width for spec in profile.measurements.values())))
    columns = 0
    for spec in profile.measurements.values():
        z = z_all[:, columns : columns + spec.width]
        columns += spec.width
        # a delayed sensor: the sample stamped t + delay_s is the vehicle at grid time t
        at = grid_ns + int(round(spec.delay_s * _NS)) if spec.delay_s else grid_ns
        g = aligner.measurement_group(spec, at, z)
        g.rate_hz = float(spec.rate_hz)
        if spec.noise_channels:  # held like the samples, so each sample gets the std logged with it
            g.noise_std = None if spec.noise_std is None else np.asarray(spec.noise_std, dtype=np.float64)
            series = np.empty((n, len(spec.noise_channels)))
            for j, ch in enumerate(spec.noise_channels):
                aligner.hold(ch, at, spec.stale_s, z=series[:, j], fresh=scratch)
            if spec.noise_channels_scale != 1.0:
                series *= spec.noise_channels_scale
            g.noise_std_series = series
        for attr in ("noise_std", "range_lo", "range_hi"):
            value = getattr(spec, attr)
            setattr(g, attr, None if value is None else np.asarray(value, dtype=np.float64))
        groups[spec.name] = g

    mode = None
    mode_channel = None
    if profile.mode is not None:
        mode_channel = profile.mode.channel
        mode, _ = aligner.hold(mode_channel, grid_ns, profile.mode.stale_s, fresh=scratch)

    ground = None
    policy = getattr(profile, "alarm_policy", None)
    if policy is not None and policy.ground_channel:  # logged on change: held as long as it says
        ground, _ = aligner.hold(policy.ground_channel, grid_ns, float("inf"), fresh=scratch)

    onboard_state = onboard_variance = None
    state_chans: list = []
    var_chans: list = []
    onboard_names: list[str] = []
    if profile.onboard is not None:
        for which in ("state", "variance"):
            chans, names = profile.onboard_channels(which, log.channels)
            if not chans:
                continue
            onboard_names = onboard_names or names
            missing = [nm for nm, ch in zip(names, chans) if ch is None]
            if missing:
                aligner.warnings.append(
                    f"[onboard] {which}: no channel for {', '.join(missing)}; those columns are NaN"
                )
            # variances in float32, as the filter's own P diagonals they are compared with
            dtype = np.float64 if which == "state" else np.float32
            arr = aligner.table(chans, grid_ns, profile.onboard.stale_s, dtype)
            if which == "state":
                onboard_state, state_chans = arr, chans
            else:
                onboard_variance, var_chans = arr, chans

    redundant: dict[str, AlignedGroup] = {}
    for red in profile.redundant.values():
        sensors = list(red.sensors.values())
        transforms = [
            # the default argument binds each sensor's own coefficients
            (lambda v, c=np.asarray(s.poly): P.polyval(v, c)) if s.poly is not None else None  # noqa: B008
            for s in sensors
        ]
        g = aligner.group(red.name, [s.channel for s in sensors], grid_ns, red.stale_limit_s(), transforms)
        g.rate_hz = red.rate_hz
        g.labels = [s.name for s in sensors]
        redundant[red.name] = g

    stats = {
        name: {
            "samples": c.samples,
            "nonfinite": c.nonfinite,
            "duplicates": c.duplicates,
            "unsorted": c.unsorted,
            **({"outliers": c.outliers} if c.outliers else {}),
        }
        for name, c in aligner.cache.items()
    }
    return AlignedRun(
        t=t,
        dt=dt,
        start_ns=start_ns,
        u=u,
        u_fresh=u_fresh,
        input_channels=input_channels,
        groups=groups,
        mode=mode,
        ground=ground,
        onboard_state=onboard_state,
        onboard_variance=onboard_variance,
        warnings=aligner.warnings + aligner.gap_lines(),
        gaps=sorted(aligner.gaps),
        input_names=list(profile.inputs.names),
        mode_channel=mode_channel,
        onboard_names=onboard_names,
        onboard_state_channels=state_chans,
        onboard_variance_channels=var_chans,
        redundant=redundant,
        channel_stats=stats,
        window=window,
    )


__all__ = ["MAX_GRID_STEPS", "AlignedGroup", "AlignedRun", "align", "check_window", "hold", "outlying_runs"]

follow_dependencies(__name__)  # the cached hold kernels are stamped with time_sanity's source too
