"""Profiles: the TOML that maps a log's channels to a vehicle model, sensors and detectors.

A profile is parsed with tomllib, checked section by section (every problem is collected, then
raised as one ProfileError naming the file, the first problem and how many more), bound to the
vehicle model's input and measurement-group names through the model registry, and written back
with `Profile.to_toml()` (the simulator embeds that text in MCAP metadata `logscan.profile`).
The schema is documented in docs/profiles.md; keep the two in step.
"""

from __future__ import annotations

import datetime
import difflib
import math
import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from logscan.errors import ProfileError

DOCS_HINT = "see docs/profiles.md"

TOP_KEYS = (
    "name",
    "description",
    "vehicle",
    "inputs",
    "measurements",
    "mode",
    "redundant",
    "onboard",
    "detectors",
)
VEHICLE_KEYS = ("model", "rate_hz", "params")
GROUP_KEYS = ("channels", "rate_hz", "stale_s", "noise_std", "range_lo", "range_hi")
MODE_KEYS = ("channel", "stale_s")
REDUNDANT_KEYS = ("sensors", "rate_hz", "stale_s")
SENSOR_KEYS = ("channel", "poly")
ONBOARD_KEYS = ("state", "variance", "stale_s")

#: Staleness defaults (seconds unless said otherwise), documented in docs/profiles.md.
GROUP_STALE_PERIODS = 2.5  # a measurement group holds for 2.5 of its own sample periods
INPUT_STALE_STEPS = 2  # inputs hold for 2 grid periods
MODE_STALE_S = 1.0
ONBOARD_STALE_S = 0.5

_INDEX_SUFFIX = re.compile(r"^\[(\d+)\]$")


# ------------------------------------------------------------------------------------------------
# Dataclasses
# ------------------------------------------------------------------------------------------------


@dataclass
class VehicleSpec:
    """`[vehicle]`: which model, with which parameters, on which analysis grid."""

    model: str
    rate_hz: float
    params: dict[str, Any] = field(default_factory=dict)


@dataclass
class InputSpec:
    """`[inputs]`: model input name (or a prefix of several) -> channel(s), as written.

    ``names`` / ``channels`` are the binding in the model's input order, filled in by validation
    (without a model: the file's order, a list ``k = [a, b]`` binding ``k[0]``, ``k[1]``).
    """

    mapping: dict[str, str | list[str]] = field(default_factory=dict)
    stale_s: float = 0.0
    names: list[str] = field(default_factory=list, compare=False)
    channels: list[str] = field(default_factory=list, compare=False)


@dataclass
class MeasurementSpec:
    """`[measurements.<group>]`: channels of one model measurement group and how to hold them."""

    name: str
    channels: list[str]
    rate_hz: float
    stale_s: float
    noise_std: list[float] | None = None  # None: the model's default
    range_lo: list[float] | None = None  # None: the model's physical range
    range_hi: list[float] | None = None


@dataclass
class ModeSpec:
    """`[mode]`: the operating-mode / set-point channel (e.g. commanded speed)."""

    channel: str
    stale_s: float = MODE_STALE_S


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
    name: str = ""
    description: str = ""
    source: str = field(default="<embedded>", compare=False)
    model_facts: ModelFacts | None = field(default=None, compare=False, repr=False)

    # --- what the readers and alignment need ------------------------------------------------
    def channel_refs(self) -> list[tuple[str, str]]:
        """Every exact channel the profile references, as (where, channel), in file order."""
        refs: list[tuple[str, str]] = []
        for key, value in self.inputs.mapping.items():
            for ch in [value] if isinstance(value, str) else value:
                refs.append((f"[inputs] {key}", ch))
        for group in self.measurements.values():
            refs.extend((f"[measurements.{group.name}] channels", ch) for ch in group.channels)
        if self.mode is not None:
            refs.append(("[mode] channel", self.mode.channel))
        for red in self.redundant.values():
            refs.extend(
                (f"[redundant.{red.name}] sensors.{s.name}", s.channel) for s in red.sensors.values()
            )
        if self.onboard is not None:
            for key in ("state", "variance"):
                value = getattr(self.onboard, key)
                if isinstance(value, list):
                    refs.extend((f"[onboard] {key}", ch) for ch in value)
                elif isinstance(value, dict):
                    refs.extend((f"[onboard] {key}.{s}", ch) for s, ch in value.items())
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

        Unknown channels come with the closest existing names; all problems are reported.
        """
        names = list(log.channels)
        problems = []
        for where, ch in self.channel_refs():
            if ch not in log.channels:
                problems.append(f"{where}: no channel {ch!r} in the log{_suggest(ch, names)}")
        for where, prefix in self.channel_prefixes():
            if not channels_under(prefix, names):
                problems.append(
                    f"{where}: no channel starts with {prefix!r} in the log{_suggest(prefix, names)}"
                )
        if problems:
            raise _profile_error(
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
        out["vehicle"] = {"model": self.vehicle.model, "rate_hz": self.vehicle.rate_hz}
        if self.vehicle.params:
            out["vehicle"]["params"] = self.vehicle.params
        out["inputs"] = {**self.inputs.mapping, "stale_s": self.inputs.stale_s}
        out["measurements"] = {}
        for g in self.measurements.values():
            table: dict[str, Any] = {"channels": g.channels, "rate_hz": g.rate_hz, "stale_s": g.stale_s}
            for key in ("noise_std", "range_lo", "range_hi"):
                if getattr(g, key) is not None:
                    table[key] = getattr(g, key)
            out["measurements"][g.name] = table
        if self.mode is not None:
            out["mode"] = {"channel": self.mode.channel, "stale_s": self.mode.stale_s}
        if self.redundant:
            out["redundant"] = {}
            for r in self.redundant.values():
                sensors = {
                    s.name: ({"channel": s.channel, "poly": s.poly} if s.poly is not None else s.channel)
                    for s in r.sensors.values()
                }
                table = {"sensors": sensors}
                if r.rate_hz is not None:
                    table["rate_hz"] = r.rate_hz
                if r.stale_s is not None:
                    table["stale_s"] = r.stale_s
                out["redundant"][r.name] = table
        if self.onboard is not None:
            table = {
                k: getattr(self.onboard, k)
                for k in ("state", "variance")
                if getattr(self.onboard, k) is not None
            }
            table["stale_s"] = self.onboard.stale_s
            out["onboard"] = table
        if self.detectors:
            out["detectors"] = {
                d.name: {"enabled": d.enabled, **d.settings} for d in self.detectors.values()
            }
        return out

    def to_toml(self) -> str:
        """TOML text that `parse_profile` reads back to an equal Profile."""
        return dumps_toml(self.to_dict())


# ------------------------------------------------------------------------------------------------
# Loading and resolving
# ------------------------------------------------------------------------------------------------


def load_profile(path: str | os.PathLike, *, model=None) -> Profile:
    """Read and validate the profile file at ``path``."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise _single_error("no such profile file", str(p)) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise _single_error(f"cannot read profile: {exc}", str(p)) from None
    return parse_profile(text, source=str(p), model=model)


def resolve_profile(log, profile_path: str | os.PathLike | None = None, *, model=None) -> Profile:
    """The ``--profile`` file when given, else the profile embedded in the log, else an error."""
    if profile_path is not None:
        return load_profile(profile_path, model=model)
    text = getattr(log, "profile_text", None) if log is not None else None
    if text:
        return parse_profile(text, source=f"{log.source.path} (embedded logscan.profile)", model=model)
    where = log.source.path if log is not None else None
    raise _single_error(
        "no profile: pass --profile or analyse a log that embeds one "
        "(MCAP metadata record 'logscan.profile', as `logscan simulate` writes)",
        where,
    )


def parse_profile(text: str, source: str = "<embedded>", *, model=None, check_model: bool = True) -> Profile:
    """Parse and validate profile TOML ``text``; ``source`` names it in messages.

    ``model``: a built Model to validate against (tests pass fakes); default: the registry's model
    named in ``[vehicle] model``. ``check_model=False`` checks only the structure.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise _single_error(f"invalid TOML: {exc}", source) from None
    checker = _Checker()
    profile = checker.profile(data, source)
    if profile is not None and check_model and not checker.problems:
        _check_against_model(profile, model, checker.problems)
    elif profile is not None and not checker.problems:
        _bind_inputs_without_model(profile)
    if checker.problems:
        raise _profile_error(checker.problems, source)
    return profile


def validate(profile: Profile, model=None) -> Profile:
    """Re-check ``profile`` against ``model`` (default: the registry's); raise ProfileError."""
    problems: list[str] = []
    _check_against_model(profile, model, problems)
    if problems:
        raise _profile_error(problems, profile.source)
    return profile


# ------------------------------------------------------------------------------------------------
# Validation
# ------------------------------------------------------------------------------------------------


def _profile_error(problems: list[str], source: str, hint: str = DOCS_HINT) -> ProfileError:
    more = f" ({len(problems) - 1} more)" if len(problems) > 1 else ""
    err = ProfileError(f"invalid profile: {problems[0]}{more}", path=source, hint=hint)
    err.problems = list(problems)
    return err


def _single_error(message: str, source: str | None) -> ProfileError:
    err = ProfileError(message, path=source, hint=DOCS_HINT)
    err.problems = [message]
    return err


def _suggest(word: str, choices, label: str = "did you mean") -> str:
    close = difflib.get_close_matches(word, list(choices), n=3, cutoff=0.6)
    if close:
        return f" ({label} {', '.join(repr(c) for c in close)}?)"
    return ""


def channels_under(prefix: str, names) -> list[str]:
    """Channels named ``prefix`` followed by ``/ . _ [`` and more (in ``names``' order)."""
    return [n for n in names if n.startswith(prefix) and len(n) > len(prefix) and n[len(prefix)] in "/._["]


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def _type_name(value: Any) -> str:
    if isinstance(value, bool):
        return f"boolean {str(value).lower()}"
    if isinstance(value, str):
        return f"string {value!r}"
    if isinstance(value, (int, float)):
        return f"number {value!r}"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, dict):
        return "a table"
    return type(value).__name__


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


class _Checker:
    """Walks the parsed TOML, building dataclasses and collecting problems."""

    def __init__(self) -> None:
        self.problems: list[str] = []

    def add(self, where: str, what: str) -> None:
        self.problems.append(f"{where}: {what}" if where else what)

    # --- generic checks -----------------------------------------------------------------------
    def table(self, data: Any, where: str) -> dict | None:
        if not isinstance(data, dict):
            self.add(where, f"expected a table, got {_type_name(data)}")
            return None
        return data

    def keys(self, data: dict, where: str, allowed, required=()) -> None:
        for key in data:
            if key not in allowed:
                close = difflib.get_close_matches(key, allowed, n=1, cutoff=0.6)
                tip = f"did you mean {close[0]!r}?" if close else f"valid keys: {', '.join(allowed)}"
                self.add(where, f"unknown key {key!r} ({tip})")
        for key in required:
            if key not in data:
                self.add(where, f"missing required key {key!r}")

    def number(self, data: dict, key: str, where: str, *, minimum: float, strict: bool, allow_inf=False):
        if key not in data:
            return None
        value = data[key]
        if not _is_number(value):
            self.add(f"{where} {key}", f"expected a number, got {_type_name(value)}")
            return None
        value = float(value)
        if math.isnan(value) or (math.isinf(value) and not (allow_inf and value > 0)):
            self.add(f"{where} {key}", f"must be a finite number, got {value!r}")
            return None
        if (strict and value <= minimum) or (not strict and value < minimum):
            op = ">" if strict else ">="
            self.add(f"{where} {key}", f"must be {op} {minimum:g}, got {value:g}")
            return None
        return value

    def string(self, data: dict, key: str, where: str) -> str | None:
        if key not in data:
            return None
        value = data[key]
        if not isinstance(value, str) or not value:
            self.add(f"{where} {key}", f"expected a non-empty string, got {_type_name(value)}")
            return None
        return value

    def string_list(self, value: Any, where: str) -> list[str] | None:
        if not isinstance(value, list) or not value:
            self.add(where, f"expected a non-empty array of channel names, got {_type_name(value)}")
            return None
        bad = [v for v in value if not isinstance(v, str) or not v]
        if bad:
            self.add(where, f"expected channel names (strings), got {_type_name(bad[0])}")
            return None
        dup = sorted({v for v in value if value.count(v) > 1})
        if dup:
            self.add(where, f"channel {dup[0]!r} listed twice")
            return None
        return list(value)

    def float_list(self, data: dict, key: str, where: str, *, positive: bool) -> list[float] | None:
        """A number or an array of numbers (kept as given: scalar -> [x])."""
        if key not in data:
            return None
        value = data[key]
        items = value if isinstance(value, list) else [value]
        if not items or not all(_is_number(v) for v in items):
            self.add(f"{where} {key}", f"expected a number or an array of numbers, got {_type_name(value)}")
            return None
        out = [float(v) for v in items]
        if positive:
            bad = [v for v in out if not (v > 0 and math.isfinite(v))]
            if bad:
                self.add(f"{where} {key}", f"must be > 0 and finite, got {bad[0]:g}")
                return None
        elif any(math.isnan(v) for v in out):
            self.add(f"{where} {key}", "must not be nan")
            return None
        return out

    # --- sections -----------------------------------------------------------------------------
    def profile(self, data: dict, source: str) -> Profile | None:
        self.keys(data, "", TOP_KEYS, required=("vehicle", "measurements"))
        for key in ("name", "description"):
            if key in data and not isinstance(data[key], str):
                self.add(key, f"expected a string, got {_type_name(data[key])}")
        vehicle = self.vehicle(data["vehicle"]) if "vehicle" in data else None
        inputs = self.inputs(data.get("inputs", {}), vehicle)
        measurements = self.measurements(data["measurements"]) if "measurements" in data else {}
        mode = self.mode(data["mode"]) if "mode" in data else None
        redundant = self.redundant(data["redundant"]) if "redundant" in data else {}
        onboard = self.onboard(data["onboard"]) if "onboard" in data else None
        detectors = self.detectors(data["detectors"]) if "detectors" in data else {}
        if vehicle is None or inputs is None or self.problems:
            return None
        return Profile(
            vehicle=vehicle,
            inputs=inputs,
            measurements=measurements,
            mode=mode,
            redundant=redundant,
            onboard=onboard,
            detectors=detectors,
            name=data.get("name", ""),
            description=data.get("description", ""),
            source=source,
        )

    def vehicle(self, raw: Any) -> VehicleSpec | None:
        where = "[vehicle]"
        data = self.table(raw, where)
        if data is None:
            return None
        self.keys(data, where, VEHICLE_KEYS, required=("model", "rate_hz"))
        model = self.string(data, "model", where)
        rate = self.number(data, "rate_hz", where, minimum=0, strict=True)
        params = data.get("params", {})
        if not isinstance(params, dict):
            self.add(f"{where} params", f"expected a table, got {_type_name(params)}")
            params = None
        if model is None or rate is None or params is None:
            return None
        return VehicleSpec(model=model, rate_hz=rate, params=dict(params))

    def inputs(self, raw: Any, vehicle: VehicleSpec | None) -> InputSpec | None:
        where = "[inputs]"
        data = self.table(raw, where)
        if data is None:
            return None
        mapping: dict[str, str | list[str]] = {}
        ok = True
        for key, value in data.items():
            if key == "stale_s":
                continue
            if isinstance(value, str) and value:
                mapping[key] = value
            elif isinstance(value, list):
                chans = self.string_list(value, f"{where} {key}")
                ok &= chans is not None
                if chans is not None:
                    mapping[key] = chans
            else:
                self.add(
                    f"{where} {key}",
                    f"expected a channel name or an array of them, got {_type_name(value)}",
                )
                ok = False
        stale = self.number(data, "stale_s", where, minimum=0, strict=False, allow_inf=True)
        if "stale_s" in data and stale is None:
            ok = False
        if stale is None:
            stale = INPUT_STALE_STEPS / vehicle.rate_hz if vehicle else 0.0
        return InputSpec(mapping=mapping, stale_s=stale) if ok else None

    def measurements(self, raw: Any) -> dict[str, MeasurementSpec]:
        data = self.table(raw, "[measurements]")
        if data is None:
            return {}
        if not data:
            self.add("[measurements]", "no measurement group: add at least one [measurements.<group>]")
        out = {}
        for name, table in data.items():
            group = self.group(name, table)
            if group is not None:
                out[name] = group
        return out

    def group(self, name: str, raw: Any) -> MeasurementSpec | None:
        where = f"[measurements.{name}]"
        data = self.table(raw, where)
        if data is None:
            return None
        self.keys(data, where, GROUP_KEYS, required=("channels", "rate_hz"))
        channels = self.string_list(data["channels"], f"{where} channels") if "channels" in data else None
        rate = self.number(data, "rate_hz", where, minimum=0, strict=True)
        stale = self.number(data, "stale_s", where, minimum=0, strict=False, allow_inf=True)
        noise = self.float_list(data, "noise_std", where, positive=True)
        lo = self.float_list(data, "range_lo", where, positive=False)
        hi = self.float_list(data, "range_hi", where, positive=False)
        if channels is None or rate is None:
            return None
        n = len(channels)
        noise = self._sized(noise, n, f"{where} noise_std")
        lo = self._sized(lo, n, f"{where} range_lo")
        hi = self._sized(hi, n, f"{where} range_hi")
        if lo is not None and hi is not None:
            bad = [i for i in range(n) if not lo[i] < hi[i]]
            if bad:
                i = bad[0]
                self.add(
                    where,
                    f"range_lo must be < range_hi, got {lo[i]:g} >= {hi[i]:g} for {channels[i]!r}",
                )
        if stale is None and "stale_s" not in data:
            stale = GROUP_STALE_PERIODS / rate
        if stale is None:
            return None
        return MeasurementSpec(name, channels, rate, stale, noise, lo, hi)

    def _sized(self, values: list[float] | None, n: int, where: str) -> list[float] | None:
        if values is None:
            return None
        if len(values) == 1:
            return values * n
        if len(values) != n:
            self.add(where, f"{len(values)} values for {n} channels (give one number or {n})")
            return None
        return values

    def mode(self, raw: Any) -> ModeSpec | None:
        where = "[mode]"
        data = self.table(raw, where)
        if data is None:
            return None
        self.keys(data, where, MODE_KEYS, required=("channel",))
        channel = self.string(data, "channel", where)
        stale = self.number(data, "stale_s", where, minimum=0, strict=False, allow_inf=True)
        if channel is None or ("stale_s" in data and stale is None):
            return None
        return ModeSpec(channel, MODE_STALE_S if stale is None else stale)

    def redundant(self, raw: Any) -> dict[str, RedundantSpec]:
        data = self.table(raw, "[redundant]")
        out = {}
        for name, table in (data or {}).items():
            where = f"[redundant.{name}]"
            t = self.table(table, where)
            if t is None:
                continue
            self.keys(t, where, REDUNDANT_KEYS, required=("sensors",))
            rate = self.number(t, "rate_hz", where, minimum=0, strict=True)
            stale = self.number(t, "stale_s", where, minimum=0, strict=False, allow_inf=True)
            sensors = self.sensors(t.get("sensors"), f"{where} sensors") if "sensors" in t else None
            if sensors is None or ("rate_hz" in t and rate is None) or ("stale_s" in t and stale is None):
                continue
            out[name] = RedundantSpec(name, sensors, rate, stale)
        return out

    def sensors(self, raw: Any, where: str) -> dict[str, SensorSpec] | None:
        data = self.table(raw, where)
        if data is None:
            return None
        if len(data) < 2:
            self.add(where, f"a redundant group needs at least 2 sensors, got {len(data)}")
            return None
        out = {}
        for name, value in data.items():
            if isinstance(value, str) and value:
                out[name] = SensorSpec(name, value)
                continue
            if not isinstance(value, dict):
                self.add(
                    f"{where}.{name}",
                    f"expected a channel name or a table {{ channel, poly }}, got {_type_name(value)}",
                )
                continue
            self.keys(value, f"{where}.{name}", SENSOR_KEYS, required=("channel",))
            channel = self.string(value, "channel", f"{where}.{name}")
            poly = self.float_list(value, "poly", f"{where}.{name}", positive=False)
            if poly is not None and not all(math.isfinite(c) for c in poly):
                self.add(f"{where}.{name} poly", "coefficients must be finite")
                poly = None
            if channel is not None:
                out[name] = SensorSpec(name, channel, poly)
        return out if len(out) == len(data) else None

    def onboard(self, raw: Any) -> OnboardSpec | None:
        where = "[onboard]"
        data = self.table(raw, where)
        if data is None:
            return None
        self.keys(data, where, ONBOARD_KEYS)
        if "state" not in data and "variance" not in data:
            self.add(where, "give 'state' and/or 'variance' (a channel prefix, an array or a table)")
        values = {}
        for key in ("state", "variance"):
            if key not in data:
                continue
            value = data[key]
            if isinstance(value, str) and value:
                values[key] = value
            elif isinstance(value, list):
                values[key] = self.string_list(value, f"{where} {key}")
            elif isinstance(value, dict) and value and all(isinstance(v, str) and v for v in value.values()):
                values[key] = dict(value)
            else:
                self.add(
                    f"{where} {key}",
                    "expected a channel prefix, an array of channels or a table state -> channel, "
                    f"got {_type_name(value)}",
                )
        stale = self.number(data, "stale_s", where, minimum=0, strict=False, allow_inf=True)
        return OnboardSpec(
            state=values.get("state"),
            variance=values.get("variance"),
            stale_s=ONBOARD_STALE_S if stale is None else stale,
        )

    def detectors(self, raw: Any) -> dict[str, DetectorSpec]:
        data = self.table(raw, "[detectors]")
        out = {}
        for name, table in (data or {}).items():
            where = f"[detectors.{name}]"
            t = self.table(table, where)
            if t is None:
                continue
            enabled = t.get("enabled", True)
            if not isinstance(enabled, bool):
                self.add(f"{where} enabled", f"expected true or false, got {_type_name(enabled)}")
                continue
            out[name] = DetectorSpec(name, enabled, {k: v for k, v in t.items() if k != "enabled"})
        return out


# ------------------------------------------------------------------------------------------------
# Model-dependent checks
# ------------------------------------------------------------------------------------------------


def _registry():
    """(get_model, MODEL_NAMES) of logscan.models, imported lazily (profiles load without numba)."""
    from logscan.models import MODEL_NAMES, get_model

    return get_model, tuple(MODEL_NAMES)


def _check_against_model(profile: Profile, model, problems: list[str]) -> None:
    """Bind inputs and check group names and sizes against the model; append problems."""
    if model is None:
        get_model, names = _registry()
        name = profile.vehicle.model
        if name not in names:
            problems.append(
                f"[vehicle] model: unknown model {name!r}{_suggest(name, names)} "
                f"(known models: {', '.join(sorted(names))})"
            )
            return
        try:
            model = get_model(name, profile.vehicle.params)
        except Exception as exc:  # noqa: BLE001 - any failure to build is a profile problem
            msg = getattr(exc, "message", None) or str(exc)
            problems.append(f"[vehicle] params: model {name!r} cannot be built: {msg}")
            return
    label = f"model {profile.vehicle.model!r}"
    params = profile.vehicle.params
    if params.get("continuous") is False and _is_number(params.get("dt")) and params["dt"] > 0:
        # discrete matrices step once per grid period: the grid must run at 1 / dt
        if abs(params["dt"] * profile.vehicle.rate_hz - 1.0) > 1e-9:
            problems.append(
                f"[vehicle] params.dt: discrete matrices of period {params['dt']:g} s need "
                f"rate_hz = {1.0 / params['dt']:g}, got {profile.vehicle.rate_hz:g}"
            )
    input_names = tuple(model.input_names)
    _bind_inputs(profile, input_names, label, problems)

    groups = dict(model.groups)
    for g in profile.measurements.values():
        where = f"[measurements.{g.name}]"
        spec = groups.get(g.name)
        if spec is None:
            problems.append(
                f"{where}: {label} has no measurement group {g.name!r}"
                f"{_suggest(g.name, groups)} (groups: {', '.join(groups)})"
            )
            continue
        if len(g.channels) != spec.size:
            problems.append(
                f"{where} channels: {_count(len(g.channels), 'channel')} but {label} group {g.name!r} has "
                f"{spec.size} outputs ({', '.join(spec.outputs)})"
            )
    if not problems:
        profile.model_facts = ModelFacts(
            input_names=input_names,
            state_names=tuple(model.state_names),
            group_sizes={name: spec.size for name, spec in groups.items()},
        )
        _check_onboard_sizes(profile, problems)


def _check_onboard_sizes(profile: Profile, problems: list[str]) -> None:
    if profile.onboard is None or profile.model_facts is None:
        return
    states = profile.model_facts.state_names
    for key in ("state", "variance"):
        value = getattr(profile.onboard, key)
        if isinstance(value, list) and len(value) != len(states):
            problems.append(
                f"[onboard] {key}: {_count(len(value), 'channel')} but model {profile.vehicle.model!r} has "
                f"{len(states)} states ({', '.join(states)})"
            )
        elif isinstance(value, dict):
            for s in value:
                if s not in states:
                    problems.append(
                        f"[onboard] {key}: model {profile.vehicle.model!r} has no state {s!r}"
                        f"{_suggest(s, states)} (states: {', '.join(states)})"
                    )


def _members(key: str, input_names: tuple[str, ...]) -> list[str]:
    """Model inputs a list-valued key binds: ``key`` + ``_ . [`` or a digit + anything."""
    return [
        n for n in input_names
        if n.startswith(key) and len(n) > len(key) and (n[len(key)] in "_.[" or n[len(key)].isdigit())
    ]


def _bind_inputs(profile: Profile, input_names: tuple[str, ...], label: str, problems: list[str]) -> None:
    bound: dict[str, str] = {}
    reported: set[str] = set()
    for key, value in profile.inputs.mapping.items():
        where = f"[inputs] {key}"
        if isinstance(value, str) or (key in input_names and len(value) == 1):
            if key not in input_names:
                problems.append(
                    f"{where}: {label} has no input {key!r}{_suggest(key, input_names)} "
                    f"(inputs: {', '.join(input_names)})"
                )
                continue
            targets, chans = [key], [value if isinstance(value, str) else value[0]]
        else:
            targets, chans = _members(key, input_names), value
            if not targets:
                problems.append(
                    f"{where}: {label} has no inputs named {key!r} or {key}_*{_suggest(key, input_names)} "
                    f"(inputs: {', '.join(input_names)})"
                )
                continue
            if len(targets) != len(chans):
                problems.append(
                    f"{where}: {_count(len(chans), 'channel')} but {label} has {len(targets)} inputs "
                    f"starting with {key!r} ({', '.join(targets)})"
                )
                reported.update(targets)  # not "missing" as well
                continue
        for name, ch in zip(targets, chans):
            if name in bound:
                problems.append(f"{where}: input {name!r} is bound twice")
            bound[name] = ch
    missing = [n for n in input_names if n not in bound and n not in reported]
    if missing:
        problems.append(
            f"[inputs]: {label} input{'s' if len(missing) > 1 else ''} "
            f"{', '.join(repr(m) for m in missing)} {'have' if len(missing) > 1 else 'has'} no channel "
            f"(inputs: {', '.join(input_names)})"
        )
    profile.inputs.names = [n for n in input_names if n in bound]
    profile.inputs.channels = [bound[n] for n in profile.inputs.names]


def _bind_inputs_without_model(profile: Profile) -> None:
    names, chans = [], []
    for key, value in profile.inputs.mapping.items():
        if isinstance(value, str):
            names.append(key)
            chans.append(value)
        else:
            names.extend(f"{key}[{i}]" for i in range(len(value)))
            chans.extend(value)
    profile.inputs.names, profile.inputs.channels = names, chans


# ------------------------------------------------------------------------------------------------
# A small TOML writer (the subset profiles use: tables, arrays, inline tables, scalars)
# ------------------------------------------------------------------------------------------------

_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(key: str) -> str:
    return key if _BARE_KEY.match(key) else _string(key)


def _string(text: str) -> str:
    out = ['"']
    for ch in text:
        if ch == '"':
            out.append('\\"')
        elif ch == "\\":
            out.append("\\\\")
        elif ch == "\n":
            out.append("\\n")
        elif ch == "\t":
            out.append("\\t")
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    out.append('"')
    return "".join(out)


def _value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return _string(value)
    if isinstance(value, (datetime.datetime, datetime.date, datetime.time)):
        return value.isoformat()
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, dict):
        if not value:
            return "{}"
        return "{ " + ", ".join(f"{_key(str(k))} = {_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def dumps_toml(data: dict[str, Any]) -> str:
    """TOML text of ``data``: dicts up to two levels deep become ``[a.b]`` headers, deeper ones
    (and dicts inside arrays) are written inline."""
    lines: list[str] = []
    _emit_table(data, [], lines)
    return "\n".join(lines).strip() + "\n"


def _emit_table(table: dict[str, Any], path: list[str], lines: list[str]) -> None:
    def header_child(v: Any) -> bool:
        return isinstance(v, dict) and bool(v) and len(path) < 2

    inline = [k for k, v in table.items() if not header_child(v)]
    if path and (inline or not table):
        lines.append("")
        lines.append("[" + ".".join(_key(p) for p in path) + "]")
    for k in inline:
        lines.append(f"{_key(str(k))} = {_value(table[k])}")
    for k, v in table.items():
        if header_child(v):
            _emit_table(v, [*path, str(k)], lines)
