"""The aligner: every channel a profile names, cleaned once and held onto one grid (groups,
tables, conversions, transforms, warnings about gaps and misaligned groups)."""

from __future__ import annotations

import os
import re
from dataclasses import replace

import numpy as np

from logscan import conversions
from logscan.align.aligned import AlignedGroup, HeldTable
from logscan.align.notes import GapReport, gap_lines, gate_line
from logscan.align.sample_hold import (
    _NS,
    _Clean,
    _gaps,
    _TimeOrder,
    changed_steps,
    clean_samples,
    hold,
    stale_ns,
    time_order,
)
from logscan.errors import InternalError
from logscan.log import WholeTimes
from logscan.timebase.time_runs import dense_runs, dropped_times, runs_of
from logscan.timebase.time_sanity import dense_span


class _Aligner:
    """Holds every channel the profile names onto one grid, cleaning each channel once."""

    def __init__(self, log, profile):
        self.log = log
        self.profile = profile
        self.cache: dict[str, _Clean] = {}
        self.released: set[str] = set()  # channels whose samples are gone (`release`)
        # a topic's channels share one time array: its order and its gaps are found once
        # (keyed by the array's id; the array is kept with them, so the id is not reused)
        self.orders: dict[int, _TimeOrder] = {}
        self.gaps_found: dict[tuple[int, int, int, int], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self.warnings: list[str] = []
        self.gaps: list[tuple[float, float, str]] = []
        self.gap_reported: set[tuple[str, int]] = set()
        self.gap_reports: list[GapReport] = []  # the channels with gaps, as reported (`gap_lines`)
        self.start_ns = 0
        self.grid_span = (0, 0)  # the whole grid's first and last sample times, ns (set by `align`)
        self.dropped: dict[str, np.ndarray] = {}  # channel -> outlying times dropped (ns)
        self.kept: dict[str, int] = {}  # channel -> its samples left, of a window's whole file (`span`)
        self.ends = ("", "")  # the channels that start first and end last (after `span`)

    def clean(self, name: str) -> _Clean:
        if name in self.released:  # its samples are gone: holding it again would hold nothing
            raise InternalError(f"alignment read the channel {name!r} after releasing its samples")
        if name not in self.cache:
            ch = self.log.channels[name]
            order = self.orders.get(id(ch.t))
            if order is None or order.t is not ch.t:
                order = self.orders[id(ch.t)] = time_order(ch.t)
            c = clean_samples(ch.t, ch.values, order)
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

    def release(self, names) -> None:
        """Drop the samples of the channels ``names`` from the log (`Log.release_samples`) and
        from the cleaned channels (their counts stay): held for the last time, they are not read
        again, and a long log's raw samples then need not wait for every aligned copy."""
        names = [name for name in names if name in self.log.channels and name not in self.released]
        if not names:
            return
        self.released.update(names)
        self.log.release_samples(names)
        no_t, no_values = np.empty(0, dtype=np.int64), np.empty(0, dtype=np.float64)
        for name in names:
            if name in self.cache:
                self.cache[name] = replace(self.cache[name], t=no_t, values=no_values)
        # the orders and gaps found for time arrays no channel holds any more go with them
        raw = {id(channel.t) for channel in self.log.channels.values()}
        self.orders = {key: order for key, order in self.orders.items() if id(order.t) in raw}
        cleaned = {id(c.t) for c in self.cache.values()}
        self.gaps_found = {key: found for key, found in self.gaps_found.items() if id(found[0]) in cleaned}

    def span(self, names: list[str]) -> tuple[int, int]:
        """(first, last) ns of the ``names`` where they are dense (`time_sanity.dense_span`); the
        outlying samples are dropped from the cleaned channels and kept in ``dropped``. A log read
        as a window of its file (`Log.read_as_window`) is judged on the whole file's times."""
        whole = getattr(self.log, "whole_times", None)
        if whole:
            return self._whole_span(names, whole)
        times = {name: self.clean(name).t for name in dict.fromkeys(names) if self.clean(name).t.size}
        first, last, drops, self.ends = dense_span(times, self.log.source.path)
        for name, drop in drops.items():
            c = self.cache[name]
            self.dropped[name] = c.t[drop]
            keep = ~drop
            self.cache[name] = replace(c, t=c.t[keep], values=c.values[keep], outliers=int(drop.sum()))
        return first, last

    def _whole_span(self, names: list[str], whole: dict[str, WholeTimes]) -> tuple[int, int]:
        """`span` from the whole file's times of a window's channels, as runs (`time_runs.runs_of`:
        sorted, a time logged twice counted once, as cleaning keeps one): the samples read at an
        outlying time are dropped."""
        key = tuple(dict.fromkeys(names))
        for name in key:
            self.clean(name)  # cleaned first, as the whole read's span does: its warnings come first
        found = self.log.whole_spans.get(key)  # a window's lead-in aligns the same channels
        if found is None:
            runs = {}
            for name in key:
                found_runs = runs_of(whole[name]) if name in whole and whole[name].size else None
                if found_runs is not None:
                    runs[name] = found_runs
            first, last, drops, ends = dense_runs(runs, self.log.source.path)
            dropped = {name: dropped_times(runs[name], drop) for name, drop in drops.items()}
            found = self.log.whole_spans[key] = (runs, first, last, dropped, ends)
        runs, first, last, dropped, self.ends = found
        for name, times in dropped.items():
            c = self.clean(name)
            self.dropped[name] = times
            self.kept[name] = runs[name].size - times.size
            keep = ~np.isin(c.t, times)
            self.cache[name] = replace(c, t=c.t[keep], values=c.values[keep], outliers=int(times.size))
        return first, last

    def hold(self, name: str | None, grid_ns: np.ndarray, limit_s: float, transform=None, z=None, fresh=None):
        n = grid_ns.size
        if name is None:
            return np.full(n, np.nan), np.zeros(n, dtype=bool)
        c = self.clean(name)
        values = c.values if transform is None else transform(c.values)
        z, fresh = hold(c.t, values, grid_ns, stale_ns(limit_s), z, fresh)
        self.report_gaps(name, grid_ns, limit_s)
        return z, fresh

    def report_gaps(self, name: str, grid_ns: np.ndarray, limit_s: float) -> None:
        """Note the stretches of the grid's span without a sample of ``name`` for longer than
        ``limit_s`` (``gaps`` and `gap_lines`), once per channel and limit."""
        limit = stale_ns(limit_s)
        key = (name, limit)
        if key in self.gap_reported:
            return
        self.gap_reported.add(key)
        t = self.clean(name).t
        # `_gaps` reads the grid's first and last times only
        found_key = (id(t), limit, int(grid_ns[0]), int(grid_ns[-1]))
        found = self.gaps_found.get(found_key)
        if found is None or found[0] is not t:
            found = self.gaps_found[found_key] = (t, *_gaps(t, limit, grid_ns))
        _, g_start, g_end = found
        if g_start.size:
            s = (g_start - self.start_ns) / _NS
            e = (g_end - self.start_ns) / _NS
            self.gaps.extend((float(a), float(b), name) for a, b in zip(s, e))
            # the last stretch ran to the span's end without a sample (a block's next sees its end)
            last = int(np.searchsorted(t, grid_ns[-1], side="right"))  # the samples up to the span's end
            open_end = int(g_end[-1]) == int(grid_ns[-1]) and not (last and int(t[last - 1]) == int(grid_ns[-1]))
            before = np.searchsorted(grid_ns, g_end, side="left")  # the grid's points before each end
            self.gap_reports.append(GapReport(name, f"{limit_s:g}", s, e, before, open_end))

    def gap_lines(self) -> list[str]:
        """One warning per topic's channels with the same gaps (`logscan.align.notes.gap_lines`)."""
        return gap_lines(self.gap_reports)

    def table(
        self, channels: list[str | None], grid_ns: np.ndarray, limit_s: float, dtype=np.float64
    ) -> np.ndarray | HeldTable:
        """The ``channels`` held onto the grid (None: a NaN column): a `HeldTable` of ``dtype``
        samples when they share their sample times (one topic), else a dense (N, c) float64 array."""
        n = grid_ns.size
        named = [ch for ch in channels if ch is not None]
        column = np.empty(n)
        scratch = np.empty(n, dtype=bool)
        first_t = self.clean(named[0]).t if named else np.empty(0, dtype=np.int64)
        shared = bool(named) and all(
            self.clean(ch).t is first_t or np.array_equal(self.clean(ch).t, first_t) for ch in named
        )
        if not shared:
            arr = np.full((n, len(channels)), np.nan)
            for j, ch in enumerate(channels):
                if ch is not None:
                    self.hold(ch, grid_ns, limit_s, z=arr[:, j], fresh=scratch)
            return arr
        for ch in named:  # the gaps and warnings of each channel, as a dense hold reports them
            self.report_gaps(ch, grid_ns, limit_s)
        t = self.clean(named[0]).t
        padded = np.empty((t.size + 1, len(channels)), dtype=dtype)
        padded[-1] = np.nan  # the row -1 reads: "none held"
        samples = padded[:-1]
        for j, ch in enumerate(channels):
            samples[:, j] = np.nan if ch is None else self.clean(ch).values
        held, _ = hold(t, np.arange(t.size, dtype=np.float64), grid_ns, stale_ns(limit_s), column, scratch)
        row = np.where(np.isnan(held), -1, held).astype(np.int32 if t.size < 2**31 else np.int64)
        return HeldTable(samples, row, padded)

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
            # no sample used where the gate is below its minimum or unknown (none held: before its
            # first sample, or its topic silent); closed, with none expected, only where it is known
            unusable = ~(np.nan_to_num(gate, nan=-np.inf) >= spec.gate_min)
            closed = unusable & ~np.isnan(gate)
            if unusable.any():
                group.z[unusable] = np.nan
                group.fresh = group.fresh & ~unusable
                if group.channel_fresh is not None:
                    group.channel_fresh = group.channel_fresh & ~unusable[:, None]
            if closed.any():
                dt = float(np.median(np.diff(grid_ns))) / _NS if grid_ns.size > 1 else 0.0
                group.gated_s = float(closed.sum()) * dt
                group.gate_closed = closed
                self.warnings.append(
                    gate_line(spec.name, spec.gate_channel, spec.gate_min, group.gated_s, grid_ns.size * dt)
                )
        return group

    def _measurement_group(self, spec, grid_ns: np.ndarray, z: np.ndarray) -> AlignedGroup:
        transforms = _linear_transforms(spec.scale, spec.offset, len(spec.channels))
        if not spec.converted:
            return self.group(spec.name, spec.channels, grid_ns, spec.stale_s, transforms, z=z)
        raw = self.group(spec.name, spec.channels, grid_ns, spec.stale_s, transforms)
        assert raw.channel_fresh is not None  # `group` sets it
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

    def first_fix(self, spec, grid_ns: np.ndarray, raw: AlignedGroup) -> tuple[float, ...] | None:
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
