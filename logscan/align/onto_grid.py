"""`align`: a log onto its profile's analysis grid, the inputs, measurement groups, mode, ground
flag, on-board estimates and redundant sensors each held by the aligner."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from logscan.align.aligned import AlignedGroup, AlignedRun, HeldTable
from logscan.align.aligner import _Aligner, _linear_transforms
from logscan.align.sample_hold import _NS
from logscan.results import GroundAround
from logscan.timebase.time_sanity import check_window, grid, grid_length, grid_points, outlier_warnings


def align(
    log,
    profile,
    *,
    start_s: float | None = None,
    end_s: float | None = None,
    release: Callable[[str], bool] | None = None,
) -> AlignedRun:
    """Put ``log`` onto ``profile``'s analysis grid (see the module docstring for the rules),
    from ``start_s`` to ``end_s`` seconds since the log's start when given. ``release`` (a test
    of the name; None: none): the channels the log drops the samples of once held for the last
    time (`Log.release_samples`): a long log's raw samples and aligned copies then overlap less.
    Raises ProfileError when the profile names channels the log lacks (with close names),
    InputError when none of its input/measurement channels holds a finite sample, the grid is
    over MAX_GRID_STEPS or the window misses the log, and UsageError for a window with end <= start."""
    check_window(start_s, end_s)
    profile.check_channels(log)
    aligner = _Aligner(log, profile)
    held = _LastHolds(aligner, profile, release)
    window = None if start_s is None and end_s is None else (start_s, end_s)
    grid_ns, t, start_ns, first_step = _grid(aligner, log, profile, window)
    n, dt = grid_ns.size, 1.0 / float(profile.vehicle.rate_hz)
    scratch = np.empty(n, dtype=bool)  # fresh masks nobody reads
    u, u_fresh = _inputs(aligner, profile, grid_ns, dt, scratch)
    held.done("inputs")
    groups = _measurement_groups(aligner, profile, grid_ns, scratch)
    held.done("measurements")
    mode, ground, around = _mode_and_ground(aligner, profile, grid_ns, scratch, None if window is None else first_step)
    held.done("mode")
    onboard = _onboard(aligner, profile, log, grid_ns)
    held.done("onboard")
    redundant = _redundant_groups(aligner, profile, grid_ns)  # before the gaps are taken: its gaps are the run's
    held.done("redundant")
    return AlignedRun(
        t=t,
        dt=dt,
        start_ns=start_ns,
        u=u,
        u_fresh=u_fresh,
        input_channels=list(profile.inputs.channels),
        groups=groups,
        mode=mode,
        ground=ground,
        ground_around=around,
        onboard_state=onboard.state,
        onboard_variance=onboard.variance,
        warnings=aligner.warnings + aligner.gap_lines(),
        gaps=sorted(aligner.gaps),
        gap_reports=aligner.gap_reports,
        input_names=list(profile.inputs.names),
        mode_channel=profile.mode.channel if profile.mode is not None else None,
        onboard_names=onboard.names,
        onboard_state_channels=onboard.state_channels,
        onboard_variance_channels=onboard.variance_channels,
        redundant=redundant,
        channel_stats=_channel_stats(aligner),
        window=window,
        first_step=first_step,
        grid_origin_s=(aligner.grid_span[0] - start_ns) / _NS,  # `_grid_times` of step 0
    )


def _mode_and_ground(aligner: _Aligner, profile, grid_ns: np.ndarray, scratch: np.ndarray, first_step: int | None):
    """(mode, ground, around): the profile's [mode] channel and [alarms] ground_channel held, each
    None without one, and a window's (``first_step``: its first step's index in the whole grid) ground
    channel around it (`_ground_around`)."""
    mode = ground = around = None
    if profile.mode is not None:
        mode, _ = aligner.hold(profile.mode.channel, grid_ns, profile.mode.stale_s, fresh=scratch)
    policy = getattr(profile, "alarm_policy", None)
    if policy is not None and policy.ground_channel:  # logged on change: held as long as it says
        ground, _ = aligner.hold(policy.ground_channel, grid_ns, float("inf"), fresh=scratch)
        if first_step is not None and grid_ns.size:
            around = _ground_around(aligner, policy, float(profile.vehicle.rate_hz), grid_ns, first_step)
    return mode, ground, around


def _ground_around(aligner: _Aligner, policy, rate: float, grid_ns: np.ndarray, first_step: int):
    """A window's ground channel held on the whole grid's steps just before and after it, as far as
    a take-off, a landing or a blip there holds back steps inside it (`AlarmPolicy.margins_s`, and
    two steps); None without such a step. The steps are the whole grid's (`grid`'s first +
    round(k dt)), the times its t."""
    first_ns, last_ns = aligner.grid_span
    whole_steps = grid_length(first_ns, last_ns, rate)
    before_s, after_s = policy.margins_s()
    last_step = first_step + grid_ns.size - 1
    before = np.arange(max(first_step - int(np.ceil(before_s * rate)) - 2, 0), first_step)
    after = np.arange(last_step + 1, min(last_step + int(np.ceil(after_s * rate)) + 3, whole_steps))
    if not before.size and not after.size:
        return None
    k = np.concatenate([before, after])
    held, _ = aligner.hold(policy.ground_channel, grid_points(first_ns, k, rate), float("inf"))
    t = _grid_times(first_ns, aligner.start_ns, k, rate)
    return GroundAround(t[: before.size], held[: before.size], t[before.size :], held[before.size :])


class _LastHolds:
    """The channels each step of `align` holds, to release each (when ``release`` allows) once the
    last step that holds it is done."""

    def __init__(self, aligner: _Aligner, profile, release: Callable[[str], bool] | None):
        self.aligner = aligner
        self.release = release
        self.steps: dict[str, set[str]] = {} if release is None else _channels_by_step(profile, aligner.log)

    def done(self, step: str) -> None:
        if self.release is None:
            return
        held = self.steps.pop(step)
        later = set().union(*self.steps.values())
        self.aligner.release(sorted(ch for ch in held - later if self.release(ch)))


def _channels_by_step(profile, log) -> dict[str, set[str]]:
    """The channels each step of `align` holds (or cleans), by step, in the order they run."""
    measured: set[str] = set()
    for spec in profile.measurements.values():
        measured.update(spec.channels)
        measured.update(spec.noise_channels or ())
        if getattr(spec, "gate_channel", None):
            measured.add(spec.gate_channel)
    mode = {profile.mode.channel} if profile.mode is not None else set()
    policy = getattr(profile, "alarm_policy", None)
    if policy is not None and policy.ground_channel:
        mode.add(policy.ground_channel)
    onboard: set[str] = set()
    if profile.onboard is not None:
        for which in ("state", "variance"):
            onboard.update(ch for ch in profile.onboard_channels(which, log.channels)[0] if ch is not None)
    redundant = {sensor.channel for red in profile.redundant.values() for sensor in red.sensors.values()}
    return {
        "inputs": {ch for ch in profile.inputs.channels if ch is not None},
        "measurements": measured,
        "mode": mode,
        "onboard": onboard,
        "redundant": redundant,
    }


def _grid(aligner: _Aligner, log, profile, window) -> tuple[np.ndarray, np.ndarray, int, int]:
    """(grid_ns, t in s since the log's time zero, that time zero in ns, the full grid's index of
    the first step): the grid spans where the input and measurement channels are dense, cut to
    ``window``."""
    rate = float(profile.vehicle.rate_hz)
    span_channels = list(profile.inputs.channels) + [ch for g in profile.measurements.values() for ch in g.channels]
    first, last = aligner.span(span_channels)
    # the log's own time zero, whatever was read (`Log.origin_ns`); start_ns, a pass over every
    # channel's times, only of a log without one
    origin = log.origin_ns if hasattr(log, "origin_ns") else log.start_ns
    start_ns = int(origin) if origin is not None else first
    early = [int(times[0]) for times in aligner.dropped.values() if times[0] < first]
    if early and start_ns <= max(early):  # the log's start is an outlier: count from the grid's
        start_ns = first
    aligner.start_ns = start_ns
    aligner.grid_span = (first, last)  # the whole grid's, a window's or not
    kept = {name: aligner.kept.get(name, aligner.cache[name].t.size) for name in aligner.dropped}
    aligner.warnings.extend(outlier_warnings(aligner.dropped, kept, start_ns))
    grid_ns, k0 = grid(first, last, rate, window, start_ns, aligner.ends, log.source.path)
    return grid_ns, _grid_times(first, start_ns, k0 + np.arange(grid_ns.size), rate), start_ns, k0


def _grid_times(first: int, start_ns: int, k: np.ndarray, rate: float) -> np.ndarray:
    """The grid's points ``k`` as t, seconds since the log's time zero ``start_ns``."""
    return (first - start_ns) / _NS + k * (1.0 / rate)


def _inputs(aligner: _Aligner, profile, grid_ns: np.ndarray, dt: float, scratch: np.ndarray):
    """(u (N, nu), u_fresh (N,)): the model inputs held onto the grid."""
    n = grid_ns.size
    input_channels = list(profile.inputs.channels)
    u = np.empty((n, len(input_channels)))
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

    return u, u_fresh


def _measurement_groups(
    aligner: _Aligner, profile, grid_ns: np.ndarray, scratch: np.ndarray
) -> dict[str, AlignedGroup]:
    """The measurement groups on the grid, their samples side by side in one array."""
    n = grid_ns.size
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

    return groups


@dataclass
class _Onboard:
    """The on-board estimator's states and variances on the grid, and their channels."""

    state: np.ndarray | HeldTable | None = None
    variance: np.ndarray | HeldTable | None = None
    names: list[str] = field(default_factory=list)
    state_channels: list = field(default_factory=list)
    variance_channels: list = field(default_factory=list)


def _onboard(aligner: _Aligner, profile, log, grid_ns: np.ndarray) -> _Onboard:
    """The profile's [onboard] estimate held onto the grid (empty without one)."""
    out = _Onboard()
    if profile.onboard is None:
        return out
    for which in ("state", "variance"):
        chans, names = profile.onboard_channels(which, log.channels)
        if not chans:
            continue
        out.names = out.names or names
        missing = [nm for nm, ch in zip(names, chans) if ch is None]
        if missing:
            aligner.warnings.append(f"[onboard] {which}: no channel for {', '.join(missing)}; those columns are NaN")
        # variances in float32, as the filter's own P diagonals they are compared with
        dtype = np.float64 if which == "state" else np.float32
        arr = aligner.table(chans, grid_ns, profile.onboard.stale_s, dtype)
        if which == "state":
            out.state, out.state_channels = arr, chans
        else:
            out.variance, out.variance_channels = arr, chans
    return out


def _redundant_groups(aligner: _Aligner, profile, grid_ns: np.ndarray) -> dict[str, AlignedGroup]:
    """The [redundant] groups on the grid, each sensor through its calibration polynomial."""
    from numpy.polynomial import polynomial as P

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

    return redundant


def _channel_stats(aligner: _Aligner) -> dict:
    """Per channel read: samples, non-finite, duplicate, unsorted and outlying counts."""
    return {
        name: {
            "samples": c.samples,
            "nonfinite": c.nonfinite,
            "duplicates": c.duplicates,
            "unsorted": c.unsorted,
            **({"outliers": c.outliers} if c.outliers else {}),
        }
        for name, c in aligner.cache.items()
    }
