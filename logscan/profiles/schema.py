"""Profile schema: the dataclasses a validated profile is made of, its keys and staleness defaults.

The schema is documented in docs/profiles.md; keep the two in step.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from typing import Any

from logscan.conversions import CONVERSIONS, VECTOR_FRAME_OUTPUTS
from logscan.profiles.loops import PRIMARY_LOOP, RecoverySpec
from logscan.profiles.problems import profile_error, suggest, suggest_channel
from logscan.profiles.toml_tables import alarms_table, group_table, redundant_table
from logscan.profiles.toml_writer import dumps_toml
from logscan.results import AlarmPolicy

TOP_KEYS = (
    "name",
    "description",
    "notes",
    "vehicle",
    "inputs",
    "measurements",
    "mode",
    "redundant",
    "onboard",
    "detectors",
    "alarms",
    "tables",
    "loops",
    "recovery",
)
VEHICLE_KEYS = ("model", "rate_hz", "params", "loop", "id")
GROUP_KEYS = (
    "channels",
    "rate_hz",
    "stale_s",
    "noise_std",
    "range_lo",
    "range_hi",
    "scale",
    "offset",
    "from",
    "frame",
    "origin",
    "noise_channels",
    "noise_channels_scale",
    "gate",
    "delay_s",
    "fresh",
)
#: ``fresh`` of a measurement group: when a sample counts as new (the filter updates with the group).
#: "on_sample": at every logged sample (a sensor's own rows); "on_change": only at steps where one
#: of its channels' held values changed (a wide CSV that forward-fills a slow sensor on every row).
FRESH_MODES = ("on_sample", "on_change")
GATE_KEYS = ("channel", "min")
MODE_KEYS = ("channel", "stale_s", "labels")
REDUNDANT_KEYS = ("sensors", "rate_hz", "stale_s")
SENSOR_KEYS = ("channel", "poly")
ONBOARD_KEYS = ("state", "variance", "stale_s")
#: keys of an input's inline table, ``gyro = { channels = [...], frame = "flu", scale = 1, offset = 0 }``
INPUT_TABLE_KEYS = ("channels", "frame", "scale", "offset")
#: ``frame`` of an input table: "flu" (forward, left, up: negate the 2nd and 3rd channels) or "frd"
INPUT_FRAMES = ("frd", "flu")
ALARM_KEYS = (
    "n_persist",
    "min_duration_s",
    "merge_gap_s",
    "ground_channel",
    "after_ground_s",
    "before_ground_s",
    "min_ground_s",
    "ignore_start_s",
)
MAX_SUSPEND_S = 600.0  # after_ground_s, ignore_start_s: a transient, not a flight
#: Upper bounds of the [alarms] floors: they are for one- or two-sample transients; longer floors
#: would hide real faults (documented in docs/profiles.md).
MAX_ALARM_PERSIST = 1000
MAX_ALARM_DURATION_S = 10.0
MAX_MERGE_GAP_S = 60.0  # alarms of one check this close are one alarm (logscan.verdict.incidents)
#: Bounds of every rate and finite staleness limit (documented in docs/profiles.md). Beyond them a
#: value is a slip, and it would overflow downstream: dt**4 in a model's process noise and NaN grid
#: steps (a tiny rate), a limit in int64 nanoseconds (logscan.align.stale_ns). A rate too high for
#: the log is refused by alignment's grid limit (`align.MAX_GRID_STEPS`), with the span and steps.
MIN_RATE_HZ = 0.01  # a 100 s period: slower than any vehicle sensor or filter step
MAX_DELAY_S = 5.0  # a measurement's own latency (a GNSS receiver's: 0.1-0.2 s), not a clock offset
MAX_STALE_S = 1_000_000.0  # 11.6 days, longer than any log (logscan.log.MAX_SPAN_S); inf: never stale

#: Staleness defaults (seconds unless said otherwise), documented in docs/profiles.md.
GROUP_STALE_PERIODS = 2.5  # a measurement group holds for 2.5 of its own sample periods
INPUT_STALE_STEPS = 2  # inputs hold for 2 grid periods
INPUT_STAMPS = ("end", "start")  # [inputs] stamp: see InputSpec.stamp
MODE_STALE_S = 1.0
ONBOARD_STALE_S = 0.5

_INDEX_SUFFIX = re.compile(r"^\[(\d+)\]$")


def channels_under(prefix: str, names) -> list[str]:
    """Channels named ``prefix`` followed by ``/ . _ [`` and more (in ``names``' order)."""
    return [n for n in names if n.startswith(prefix) and len(n) > len(prefix) and n[len(prefix)] in "/._["]


@dataclass
class VehicleSpec:
    """`[vehicle]`: which model, with which parameters, on which analysis grid."""

    model: str
    rate_hz: float
    params: dict[str, Any] = field(default_factory=dict)
    loop: str = ""  # the loop's name in a hierarchical profile ("": the primary's default name)
    # which vehicle the profile describes (a built-in px4 profile: the board, its unique id, the
    # airframe): part of the trained tables' fingerprint (`logscan.training.train`), nothing else reads it
    id: str = ""


def input_channels(value: str | list[str] | dict) -> list[str]:
    """The channels of one ``[inputs]`` value: a channel, an array, or an inline table's ``channels``."""
    if isinstance(value, str):
        return [value]
    if isinstance(value, dict):
        return list(value["channels"])
    return list(value)


def input_transform(value: str | list[str] | dict) -> tuple[list[float], list[float]]:
    """(factor, offset) per channel of one ``[inputs]`` value: held = raw * factor + offset, the
    factor being ``scale`` times -1 for the 2nd and 3rd channels of ``frame = "flu"``."""
    n = len(input_channels(value))
    if not isinstance(value, dict):
        return [1.0] * n, [0.0] * n
    factor = list(value.get("scale", [1.0] * n))
    if value.get("frame") == "flu":
        factor = [factor[0], -factor[1], -factor[2]]
    return factor, list(value.get("offset", [0.0] * n))


@dataclass
class InputSpec:
    """`[inputs]`: model input name (or a prefix of several) -> channel(s), as written.

    A value is a channel, an array of channels, or an inline table ``{ channels = [...], frame,
    scale, offset }`` (stored with ``scale`` / ``offset`` as one number per channel, as validated).
    ``names`` / ``channels`` are the binding in the model's input order, filled in by validation
    (without a model: the file's order, a list ``k = [a, b]`` binding ``k[0]``, ``k[1]``), and
    ``factors`` / ``offsets`` each bound channel's transform (held = raw * factor + offset).
    """

    mapping: dict[str, str | list[str] | dict[str, Any]] = field(default_factory=dict)
    stale_s: float = 0.0
    # "end": a logged input acts over the grid step that ends at its stamp (an IMU's increments, the
    # EKF's x_k = f(x_{k-1}, u_k)); "start": it acts from its stamp on (a command stamped when issued,
    # applied over [t_k, t_k+1)), so alignment holds it from the next step
    stamp: str = "end"
    names: list[str] = field(default_factory=list, compare=False)
    channels: list[str] = field(default_factory=list, compare=False)
    factors: list[float] = field(default_factory=list, compare=False)  # empty: all 1
    offsets: list[float] = field(default_factory=list, compare=False)  # empty: all 0


@dataclass
class MeasurementSpec:
    """`[measurements.<group>]`: channels of one model measurement group and how to hold them.

    ``scale`` multiplies each channel (one factor per channel), then ``offset`` is added; ``source``
    (the TOML key ``from``) converts the held channels (`logscan.conversions`): "quaternion" (w, x,
    y, z) -> roll, pitch, yaw (``frame`` "enu_flu": a ROS orientation, turned into FRD-to-NED
    first); "geodetic" (lat, lon, alt) -> north, east, down about ``origin`` (``frame`` "enu": east,
    north, up). Without ``from``, ``frame`` of a 3-vector: "flu" -> forward, right, down; "enu" ->
    north, east, down ("ned"/"frd": as it is). ``noise_std`` / ``range_*`` have one value per
    converted output (`width`).
    """

    name: str
    channels: list[str]
    rate_hz: float
    stale_s: float
    noise_std: list[float] | None = None  # None: the model's default
    range_lo: list[float] | None = None  # None: the model's physical range
    range_hi: list[float] | None = None
    scale: list[float] | None = None  # one factor per channel, None: 1
    source: str | None = None  # `from`: None, "quaternion" or "geodetic"
    origin: list[float] | None = None  # geodetic: [lat deg, lon deg, alt m]; None: the first fix
    frame: str = "ned"  # geodetic: "ned"/"enu"; quaternion: "ned"/"enu_flu"; a 3-vector: frd/ned/flu/enu
    offset: list[float] | None = None  # one per channel, added after scale; None: 0
    # per-sample noise std channels, one per output (a receiver's eph, eph, epv); None: noise_std
    noise_channels: list[str] | None = None
    noise_channels_scale: float = 1.0  # times each logged std (calibration's factor)
    # the samples describe the vehicle this long before their stamps (a GNSS receiver's latency,
    # PX4's EKF2_GPS_DELAY): alignment holds them delay_s earlier
    delay_s: float = 0.0
    # a sample counts only where this channel (held) is at least gate_min: a GNSS fix type >= 3
    gate_channel: str | None = None
    gate_min: float = 0.0
    # when a sample is fresh (FRESH_MODES): "on_sample" (each logged sample), "on_change" (a held
    # value that changed: a forward-filled CSV column's repeats are not measurements)
    fresh: str = "on_sample"

    @property
    def width(self) -> int:
        """Values per grid step: the converted outputs with ``from``, else one per channel."""
        return len(CONVERSIONS[self.source].output_names(self.frame)) if self.source is not None else len(self.channels)

    def output_names(self) -> tuple[str, ...] | None:
        """Names of the converted outputs (None without ``from`` or a converting ``frame``)."""
        if self.source is not None:
            return CONVERSIONS[self.source].output_names(self.frame)
        return VECTOR_FRAME_OUTPUTS.get(self.frame)

    @property
    def converted(self) -> bool:
        """True when the held channels are converted (``from``, or a ``frame`` that changes them)."""
        return self.source is not None or self.frame in VECTOR_FRAME_OUTPUTS


@dataclass
class ModeSpec:
    """`[mode]`: the operating-mode / set-point channel (e.g. commanded speed). ``labels``: a name
    for each value the channel takes that has one (``labels = { "-1" = "NO_FIX", "0" = "FIX" }``,
    as a message's constants name them); the report draws those values by name."""

    channel: str
    stale_s: float = MODE_STALE_S
    labels: dict[float, str] = field(default_factory=dict)


@dataclass
class SensorSpec:
    """One sensor of a redundant group, with an optional polynomial into the group's unit."""

    name: str
    channel: str
    poly: list[float] | None = None  # coefficients c0, c1, ... (numpy.polynomial order)


@dataclass
class RedundantSpec:
    """`[redundant.<name>]`: sensors measuring one quantity (A-TFM and similar detectors)."""

    name: str
    sensors: dict[str, SensorSpec]
    rate_hz: float | None = None  # detection grid; None: the slowest sensor's rate
    stale_s: float | None = None  # None: 2.5 periods of rate_hz, or 1 s without a rate

    def stale_limit_s(self) -> float:
        if self.stale_s is not None:
            return self.stale_s
        return GROUP_STALE_PERIODS / self.rate_hz if self.rate_hz else 1.0


@dataclass
class OnboardSpec:
    """`[onboard]`: the vehicle's own estimator, when logged.

    ``state`` / ``variance`` are each a channel prefix (str), a list of channels in the model's
    state order, or a table state name -> channel (missing states are NaN columns).
    """

    state: str | list[str] | dict[str, str] | None = None
    variance: str | list[str] | dict[str, str] | None = None
    stale_s: float = ONBOARD_STALE_S


@dataclass
class DetectorSpec:
    """`[detectors.<name>]`: free-form settings of one detector plus `enabled`."""

    name: str
    enabled: bool = True
    settings: dict[str, Any] = field(default_factory=dict)


@dataclass
class ModelFacts:
    """What validation learned from the model (used by alignment, not written back to TOML)."""

    input_names: tuple[str, ...]
    state_names: tuple[str, ...]
    group_sizes: dict[str, int]


@dataclass
class Profile:
    """A validated profile. Compare two with ``==``; ``source`` is not part of equality."""

    vehicle: VehicleSpec
    inputs: InputSpec
    measurements: dict[str, MeasurementSpec]
    mode: ModeSpec | None = None
    redundant: dict[str, RedundantSpec] = field(default_factory=dict)
    onboard: OnboardSpec | None = None
    detectors: dict[str, DetectorSpec] = field(default_factory=dict)
    alarm_policy: AlarmPolicy | None = None  # the [alarms] table: floors under every detector's alarms
    name: str = ""
    description: str = ""
    tables: str = ""  # trained tables file (`logscan train`), relative to the profile's directory
    # what the profile's maker said of it (a built-in profile's: what it left out, `logscan
    # init-profile` writes them): analyze says each as a warning, as it does a built-in profile's
    notes: list[str] = field(default_factory=list, compare=False)
    source: str = field(default="<embedded>", compare=False)
    model_facts: ModelFacts | None = field(default=None, compare=False, repr=False)
    loops: dict[str, Profile] = field(default_factory=dict)  # further loops ([loops.<name>], `loops`)
    recovery: RecoverySpec | None = None  # [recovery]

    @property
    def loop_name(self) -> str:
        return self.vehicle.loop or PRIMARY_LOOP

    def source_file(self) -> str | None:
        """The profile file this profile came from; None when a log embeds it or it is built in
        (a command then passes no --profile: each log brings its own)."""
        return self.source if self.source and os.path.isfile(self.source) else None

    # --- what the readers and alignment need ------------------------------------------------
    def channel_refs(self) -> list[tuple[str, str]]:
        """Every exact channel the profile references, as (where, channel), in file order."""
        refs: list[tuple[str, str]] = []
        for key, value in self.inputs.mapping.items():
            for ch in input_channels(value):
                refs.append((f"[inputs] {key}", ch))
        for group in self.measurements.values():
            refs.extend((f"[measurements.{group.name}] channels", ch) for ch in group.channels)
            refs.extend((f"[measurements.{group.name}] noise_channels", ch) for ch in group.noise_channels or ())
            if group.gate_channel is not None:
                refs.append((f"[measurements.{group.name}] gate", group.gate_channel))
        if self.mode is not None:
            refs.append(("[mode] channel", self.mode.channel))
        if self.alarm_policy is not None and self.alarm_policy.ground_channel:
            refs.append(("[alarms] ground_channel", self.alarm_policy.ground_channel))
        for red in self.redundant.values():
            refs.extend((f"[redundant.{red.name}] sensors.{s.name}", s.channel) for s in red.sensors.values())
        if self.onboard is not None:
            for key in ("state", "variance"):
                value = getattr(self.onboard, key)
                if isinstance(value, list):
                    refs.extend((f"[onboard] {key}", ch) for ch in value)
                elif isinstance(value, dict):
                    refs.extend((f"[onboard] {key}.{s}", ch) for s, ch in value.items())
        for name, loop in self.loops.items():
            refs.extend((f"[loops.{name}] {where.strip('[')}", ch) for where, ch in loop.channel_refs())
        return refs

    def channel_prefixes(self) -> list[tuple[str, str]]:
        """Channel prefixes (on-board estimator given as a prefix), as (where, prefix)."""
        out = []
        if self.onboard is not None:
            for key in ("state", "variance"):
                value = getattr(self.onboard, key)
                if isinstance(value, str):
                    out.append((f"[onboard] {key}", value))
        return out

    def topics(self) -> set[str]:
        """Channel names and prefixes the readers must decode (pass to `read_log(topics=...)`)."""
        return {ch for _, ch in self.channel_refs()} | {p for _, p in self.channel_prefixes()}

    def enabled_detectors(self) -> list[str]:
        return [d.name for d in self.detectors.values() if d.enabled]

    def check_channels(self, log) -> None:
        """Raise ProfileError unless every channel the profile names exists in ``log``.

        Unknown channels come with the closest existing names, read or not (`SourceInfo.unread`);
        all problems are reported.
        """
        names = list(log.channels)
        known = names + [name for name in getattr(log.source, "unread", ()) if name not in log.channels]
        problems = []
        for where, ch in self.channel_refs():
            if ch not in log.channels:
                problems.append(f"{where}: no channel {ch!r} in the log{suggest_channel(ch, known)}")
        for where, prefix in self.channel_prefixes():
            if not channels_under(prefix, names):
                problems.append(f"{where}: no channel starts with {prefix!r} in the log{suggest(prefix, names)}")
        if problems:
            raise profile_error(
                problems,
                self.source,
                hint=f"the log is {log.source.path}; `logscan inspect` lists its channels",
            )

    def onboard_channels(self, which: str, log_channels) -> tuple[list[str | None], list[str]]:
        """Resolve ``[onboard] state`` or ``variance`` to one channel (or None) per column.

        Returns (channels, column names). With a prefix: ``<prefix><sep><state>`` for each model
        state name (sep one of ``/ . _``), else ``<prefix>[i]`` indexed channels.
        """
        value = getattr(self.onboard, which) if self.onboard else None
        states = list(self.model_facts.state_names) if self.model_facts else []
        if value is None:
            return [], []
        if isinstance(value, list):
            cols = states if len(states) == len(value) else [f"{which}[{i}]" for i in range(len(value))]
            return list(value), cols
        if isinstance(value, dict):
            if states:
                return [value.get(s) for s in states], states
            return list(value.values()), list(value)
        names = set(log_channels)
        if states:
            for sep in ("/", ".", "_"):
                found = [f"{value}{sep}{s}" if f"{value}{sep}{s}" in names else None for s in states]
                if any(found):
                    return found, states
        indexed = {}
        for ch in channels_under(value, names):
            m = _INDEX_SUFFIX.match(ch[len(value) :])
            if m:
                indexed[int(m.group(1))] = ch
        n = len(states) if states else (max(indexed) + 1 if indexed else 0)
        cols = states if states else [f"{which}[{i}]" for i in range(n)]
        return [indexed.get(i) for i in range(n)], cols

    # --- writing ------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The profile as plain TOML-ready data (defaults written out explicitly)."""
        out: dict[str, Any] = {}
        if self.name:
            out["name"] = self.name
        if self.description:
            out["description"] = self.description
        if self.notes:
            out["notes"] = list(self.notes)
        if self.tables:
            out["tables"] = self.tables
        out["vehicle"] = {"model": self.vehicle.model, "rate_hz": self.vehicle.rate_hz}
        if self.vehicle.loop:
            out["vehicle"]["loop"] = self.vehicle.loop
        if self.vehicle.id:
            out["vehicle"]["id"] = self.vehicle.id
        if self.vehicle.params:
            out["vehicle"]["params"] = self.vehicle.params
        out["inputs"] = {**self.inputs.mapping, "stale_s": self.inputs.stale_s}
        if self.inputs.stamp != "end":
            out["inputs"]["stamp"] = self.inputs.stamp
        out["measurements"] = {}
        for g in self.measurements.values():
            out["measurements"][g.name] = group_table(g)
        if self.mode is not None:
            out["mode"] = {"channel": self.mode.channel, "stale_s": self.mode.stale_s}
            if self.mode.labels:
                out["mode"]["labels"] = {f"{value:g}": label for value, label in self.mode.labels.items()}
        if self.redundant:
            out["redundant"] = {r.name: redundant_table(r) for r in self.redundant.values()}
        if self.onboard is not None:
            table = {k: getattr(self.onboard, k) for k in ("state", "variance") if getattr(self.onboard, k) is not None}
            table["stale_s"] = self.onboard.stale_s
            out["onboard"] = table
        if self.detectors:
            out["detectors"] = {d.name: {"enabled": d.enabled, **d.settings} for d in self.detectors.values()}
        if self.alarm_policy is not None:
            out["alarms"] = alarms_table(self.alarm_policy)
        if self.loops:
            out["loops"] = {name: _loop_table(loop) for name, loop in self.loops.items()}
        if self.recovery is not None:
            out["recovery"] = self.recovery.to_dict()
        return out

    def to_toml(self) -> str:
        """TOML text that `parse_profile` reads back to an equal Profile."""
        return dumps_toml(self.to_dict())


def _loop_table(loop: Profile) -> dict[str, Any]:
    """A further loop as its ``[loops.<name>]`` table (its name is the table's)."""
    table = loop.to_dict()
    table["vehicle"].pop("loop", None)
    return table
