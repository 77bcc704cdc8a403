"""The aligned run: a log on a profile's analysis grid (the dataclasses every later layer reads).

INTERFACE (fixed): downstream code (filters, detectors, simulator tests) relies only on these
dataclasses; fields may be added with defaults, never renamed or removed."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from logscan.results import GroundAround


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
    gate_closed: np.ndarray | None = None  # (N,) bool, where its gate was known closed (None: never)
    # a `from = "geodetic"` group: the (lat deg, lon deg, alt m) its north/east/down are relative to
    origin: tuple[float, ...] | None = None


class HeldTable:
    """Columns held onto the grid but stored at their own rate: the samples (M, c) and, per grid
    step, the row held there (-1: none within the staleness limit). Reads like the dense (N, c)
    array (``table[rows]``, ``np.asarray(table)``); a 50 Hz on-board estimate on a 100 Hz grid
    takes half the memory plus 4 bytes a step."""

    def __init__(self, samples: np.ndarray, row: np.ndarray, padded: np.ndarray | None = None):
        self.samples = samples
        self.row = row
        self.shape = (int(row.size), int(samples.shape[1]))
        self.ndim = 2
        self.dtype = samples.dtype
        # ``padded``: the samples followed by one row of NaN (``samples`` a view of its first M rows),
        # when the aligner made them so: row -1 then reads NaN in one gather, without a mask
        self.padded = padded

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, rows) -> np.ndarray:
        held = self.row[rows]
        if self.padded is not None:
            return self.padded[held]
        out = np.take(self.samples, np.maximum(held, 0), axis=0)  # a copy also for one step
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
    # a window's ground channel on the whole grid's steps just outside it: a take-off before it or a
    # landing after it holds back steps inside it (`AlarmPolicy.suspend`)
    ground_around: GroundAround | None = None
    onboard_state: np.ndarray | HeldTable | None = None
    onboard_variance: np.ndarray | HeldTable | None = None
    warnings: list[str] = field(default_factory=list)
    gaps: list[tuple[float, float, str]] = field(default_factory=list)  # (start s, end s, channel)
    gap_reports: list = field(default_factory=list)  # each channel's gaps, as reported (`logscan.align.notes`)
    # Optional additions (alignment fills them):
    input_names: list[str] = field(default_factory=list)  # model input name of each column of u
    mode_channel: str | None = None
    onboard_names: list[str] = field(default_factory=list)  # column names (model states)
    onboard_state_channels: list[str | None] = field(default_factory=list)
    onboard_variance_channels: list[str | None] = field(default_factory=list)
    redundant: dict[str, AlignedGroup] = field(default_factory=dict)  # sensors as channels
    channel_stats: dict[str, dict[str, int]] = field(default_factory=dict)  # samples, nonfinite, ...
    window: tuple[float | None, float | None] | None = None  # --start/--end (s since start_ns), if given
    first_step: int = 0  # the full grid's index of t[0] (0: the log's first step; a window: later)
    grid_origin_s: float = 0.0  # the full grid's step 0 as t: its step k is grid_origin_s + k * dt

    @property
    def n_steps(self) -> int:
        return int(self.t.size)
