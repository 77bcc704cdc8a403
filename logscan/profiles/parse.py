"""Profile parsing: TOML text -> a validated Profile, every problem collected and reported at once."""

from __future__ import annotations

import difflib
import math
import os
import stat
import tomllib
from pathlib import Path
from typing import Any

from logscan.conversions import CONVERSIONS, GROUP_FRAMES, Conversion
from logscan.input_files import SPECIAL_FILE_HINT, os_error_text, special_kind
from logscan.profiles.bind import bind_inputs_without_model, build_model, check_against_model
from logscan.profiles.loops import PRIMARY_LOOP, RecoverySpec, parse_loops, parse_recovery
from logscan.profiles.problems import DOCS_HINT, is_number, profile_error, single_error, suggest, type_name
from logscan.profiles.schema import (
    ALARM_KEYS,
    FRESH_MODES,
    GATE_KEYS,
    GROUP_KEYS,
    GROUP_STALE_PERIODS,
    INPUT_FRAMES,
    INPUT_STALE_STEPS,
    INPUT_STAMPS,
    INPUT_TABLE_KEYS,
    MAX_ALARM_DURATION_S,
    MAX_ALARM_PERSIST,
    MAX_DELAY_S,
    MAX_MERGE_GAP_S,
    MAX_STALE_S,
    MAX_SUSPEND_S,
    MIN_RATE_HZ,
    MODE_KEYS,
    MODE_STALE_S,
    ONBOARD_KEYS,
    ONBOARD_STALE_S,
    REDUNDANT_KEYS,
    SENSOR_KEYS,
    TOP_KEYS,
    VEHICLE_KEYS,
    DetectorSpec,
    InputSpec,
    MeasurementSpec,
    ModeSpec,
    OnboardSpec,
    Profile,
    RedundantSpec,
    SensorSpec,
    VehicleSpec,
)
from logscan.results import AlarmPolicy

_STD_LIMITS = (1e-150, 1e150)  # a noise std whose square (the variance) is a normal float
# A profile is a few KB of TOML; a larger one is the wrong file (or hostile), refused before parsing.
MAX_PROFILE_BYTES = 1 << 20
_SIZE_HINT = "a profile is a few KB of TOML: check that this is the right file"


def load_profile(path: str | os.PathLike, *, model=None) -> Profile:
    """Read and validate the profile file at ``path``."""
    p = Path(path)
    return parse_profile(_profile_text(p), source=str(p), model=model)


def _profile_text(p: Path) -> str:
    """The text of the profile file ``p``: a regular file of at most MAX_PROFILE_BYTES of UTF-8,
    checked with ``os.stat`` before it is opened (opening a FIFO blocks); else a ProfileError."""
    try:
        st = os.stat(p)
        kind = "a directory" if stat.S_ISDIR(st.st_mode) else special_kind(st.st_mode)
        if kind is not None:
            raise single_error(f"profile is {kind}, not a regular file", str(p), hint=SPECIAL_FILE_HINT)
        if st.st_size > MAX_PROFILE_BYTES:
            raise _too_large(st.st_size, str(p))
        with open(p, "rb") as fh:
            data = fh.read(MAX_PROFILE_BYTES + 1)  # the file may have grown since the stat
    except FileNotFoundError:
        raise single_error("no such profile file", str(p)) from None
    except OSError as exc:
        message, hint = os_error_text(exc)
        raise single_error(f"cannot read profile: {message}", str(p), hint=hint or DOCS_HINT) from None
    if len(data) > MAX_PROFILE_BYTES:
        raise _too_large(len(data), str(p))
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise single_error(
            f"profile is not UTF-8 text (bad byte at offset {exc.start})", str(p), hint="save it as UTF-8"
        ) from None


def _too_large(size: int, source: str):
    return single_error(
        f"profile is {size} bytes, more than the {MAX_PROFILE_BYTES} a profile may have", source, hint=_SIZE_HINT
    )


def resolve_profile(log, profile_path: str | os.PathLike | None = None, *, model=None) -> Profile:
    """The ``--profile`` file when given, else the profile embedded in the log, else an error."""
    if profile_path is not None:
        return load_profile(profile_path, model=model)
    text = getattr(log, "profile_text", None) if log is not None else None
    if text:
        return parse_profile(text, source=f"{log.source.path} (embedded logscan.profile)", model=model)
    where = log.source.path if log is not None else None
    raise single_error(
        "no profile: pass --profile or analyse a log that embeds one "
        "(MCAP metadata record 'logscan.profile', as `logscan simulate` writes)",
        where,
    )


def parse_profile(text: str, source: str = "<embedded>", *, model=None, check_model: bool = True) -> Profile:
    """Parse and validate profile TOML ``text``; ``source`` names it in messages.

    ``model``: a built Model to validate against (tests pass fakes); default: the registry's model
    named in ``[vehicle] model``. ``check_model=False`` checks only the structure.
    """
    if len(text) > MAX_PROFILE_BYTES:  # characters: at least as many bytes
        raise _too_large(len(text), source)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise single_error(f"invalid TOML: {exc}", source) from None
    except ValueError:  # not a TOMLDecodeError: Python's int() refuses integers of over 4300 digits
        raise single_error("invalid TOML: an integer has more than 4300 digits", source) from None
    except RecursionError:  # tomllib recurses once per level of nested arrays and inline tables
        raise single_error("invalid TOML: arrays, tables or keys nested too deeply", source) from None
    checker = _Checker(check_model and model is None)
    profile = checker.profile(data, source)
    if profile is not None and check_model and not checker.problems:
        check_against_model(profile, model, checker.problems)
    elif checker.vehicle_spec is not None and check_model and model is None:
        build_model(checker.vehicle_spec, checker.problems)  # its parameter problems too, all at once
    elif profile is not None and not checker.problems:
        bind_inputs_without_model(profile)
    if checker.problems:
        raise profile_error(checker.problems, source)
    return profile


def validate(profile: Profile, model=None) -> Profile:
    """Re-check ``profile`` against ``model`` (default: the registry's); raise ProfileError."""
    problems: list[str] = []
    check_against_model(profile, model, problems)
    if problems:
        raise profile_error(problems, profile.source)
    return profile


def _choices(values) -> str:
    """``'a', 'b' or 'c'``."""
    quoted = [repr(v) for v in values]
    return quoted[0] if len(quoted) == 1 else f"{', '.join(quoted[:-1])} or {quoted[-1]}"


class _Checker:
    """Walks the parsed TOML, building dataclasses and collecting problems."""

    def __init__(self, check_model: bool = True) -> None:
        self.check_model = check_model  # further loops are checked against their models here
        self.problems: list[str] = []
        self.vehicle_spec: VehicleSpec | None = None  # [vehicle], when it is valid

    def add(self, where: str, what: str) -> None:
        self.problems.append(f"{where}: {what}" if where else what)

    # --- generic checks -----------------------------------------------------------------------
    def table(self, data: Any, where: str) -> dict | None:
        if not isinstance(data, dict):
            self.add(where, f"expected a table, got {type_name(data)}")
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

    def number(
        self, data: dict, key: str, where: str, *, minimum: float, strict: bool, allow_inf=False, maximum=math.inf
    ):
        """``data[key]`` as a finite float (``inf`` too with ``allow_inf``) above ``minimum`` (or
        equal, unless ``strict``) and at most ``maximum``; None when absent or with a problem."""
        if key not in data:
            return None
        value = data[key]
        if not is_number(value):
            self.add(f"{where} {key}", f"expected a number, got {type_name(value)}")
            return None
        try:
            value = float(value)
        except OverflowError:  # TOML integers have no size limit in tomllib: 10**400 is one
            self.add(f"{where} {key}", "must be a finite number, got an integer beyond float range")
            return None
        if math.isnan(value) or (math.isinf(value) and not (allow_inf and value > 0)):
            self.add(f"{where} {key}", f"must be a finite number, got {value!r}")
            return None
        if (strict and value <= minimum) or (not strict and value < minimum):
            op = ">" if strict else ">="
            self.add(f"{where} {key}", f"must be {op} {minimum:g}, got {value:g}")
            return None
        if value > maximum:
            self.add(f"{where} {key}", f"must be <= {maximum:g}, got {value:g}")
            return None
        return value

    def rate(self, data: dict, key: str, where: str) -> float | None:
        """A finite rate in Hz of at least MIN_RATE_HZ: a tiny one overflows the model's process noise
        (dt**4) or gives NaN grid steps. Too high a rate for the log's span is alignment's to refuse
        (its grid limit), naming the span and the steps."""
        value = self.number(data, key, where, minimum=0, strict=True)
        if value is not None and value < MIN_RATE_HZ:
            self.add(f"{where} {key}", f"must be >= {MIN_RATE_HZ:g} Hz (a {1 / MIN_RATE_HZ:g} s period), got {value:g}")
            return None
        return value

    def stale(self, data: dict, key: str, where: str) -> float | None:
        """A staleness limit: > 0 and at most MAX_STALE_S, or inf (never stale); a larger finite
        limit overflows int64 nanoseconds in alignment."""
        value = self.number(data, key, where, minimum=0, strict=True, allow_inf=True)
        if value is not None and math.isfinite(value) and value > MAX_STALE_S:
            self.add(f"{where} {key}", f"must be at most {MAX_STALE_S:.0f} s (or inf: never stale), got {value:g}")
            return None
        return value

    def string(self, data: dict, key: str, where: str) -> str | None:
        if key not in data:
            return None
        value = data[key]
        if not isinstance(value, str) or not value:
            self.add(f"{where} {key}", f"expected a non-empty string, got {type_name(value)}")
            return None
        return value

    def string_list(self, value: Any, where: str) -> list[str] | None:
        if not isinstance(value, list) or not value:
            self.add(where, f"expected a non-empty array of channel names, got {type_name(value)}")
            return None
        bad = [v for v in value if not isinstance(v, str) or not v]
        if bad:
            self.add(where, f"expected channel names (strings), got {type_name(bad[0])}")
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
        if not items or not all(is_number(v) for v in items):
            self.add(f"{where} {key}", f"expected a number or an array of numbers, got {type_name(value)}")
            return None
        try:
            out = [float(v) for v in items]
        except OverflowError:  # an integer beyond float range (tomllib reads any size)
            self.add(f"{where} {key}", "must be finite, got an integer beyond float range")
            return None
        if positive:
            bad = [v for v in out if not (v > 0 and math.isfinite(v))]
            if bad:
                self.add(f"{where} {key}", f"must be > 0 and finite, got {bad[0]:g}")
                return None
        elif not all(math.isfinite(v) for v in out):
            self.add(f"{where} {key}", f"must be finite, got {next(v for v in out if not math.isfinite(v))!r}")
            return None
        return out

    # --- sections -----------------------------------------------------------------------------
    def profile(self, data: dict, source: str) -> Profile | None:
        self.keys(data, "", TOP_KEYS, required=("vehicle", "measurements"))
        for key in ("name", "description", "tables"):
            if key in data and not isinstance(data[key], str):
                self.add(key, f"expected a string, got {type_name(data[key])}")
        vehicle = self.vehicle_spec = self.vehicle(data["vehicle"]) if "vehicle" in data else None
        inputs = self.inputs(data.get("inputs", {}), vehicle)
        measurements = self.measurements(data["measurements"]) if "measurements" in data else {}
        mode = self.mode(data["mode"]) if "mode" in data else None
        redundant = self.redundant(data["redundant"]) if "redundant" in data else {}
        onboard = self.onboard(data["onboard"]) if "onboard" in data else None
        detectors = self.detectors(data["detectors"]) if "detectors" in data else {}
        alarm_policy = self.alarms(data["alarms"]) if "alarms" in data else None
        check = check_against_model if self.check_model else None
        loops = parse_loops(self, data["loops"], source, check) if "loops" in data else {}
        primary = vehicle.loop if vehicle is not None and vehicle.loop else PRIMARY_LOOP
        if primary in loops:
            self.add(f"[loops.{primary}]", f"the top level is already the loop {primary!r}: rename one")
        recovery = self.recovery_table(data, {primary, *loops})
        if vehicle is None or inputs is None or self.problems:
            return None
        return Profile(
            loops=loops,
            recovery=recovery,
            vehicle=vehicle,
            inputs=inputs,
            measurements=measurements,
            mode=mode,
            redundant=redundant,
            onboard=onboard,
            detectors=detectors,
            alarm_policy=alarm_policy,
            name=data.get("name", ""),
            description=data.get("description", ""),
            tables=data.get("tables", ""),
            source=source,
        )

    def vehicle(self, raw: Any) -> VehicleSpec | None:
        where = "[vehicle]"
        data = self.table(raw, where)
        if data is None:
            return None
        self.keys(data, where, VEHICLE_KEYS, required=("model", "rate_hz"))
        model = self.string(data, "model", where)
        rate = self.rate(data, "rate_hz", where)
        params = data.get("params", {})
        if not isinstance(params, dict):
            self.add(f"{where} params", f"expected a table, got {type_name(params)}")
            params = None
        loop = self.string(data, "loop", where) if "loop" in data else ""
        if loop is not None and loop and not loop.isidentifier():
            self.add(f"{where} loop", "a loop name must be a plain identifier (letters, digits, _)")
        vehicle_id = self.string(data, "id", where) if "id" in data else ""
        if model is None or rate is None or params is None or loop is None or vehicle_id is None:
            return None
        return VehicleSpec(model=model, rate_hz=rate, params=dict(params), loop=loop, id=vehicle_id)

    def inputs(self, raw: Any, vehicle: VehicleSpec | None) -> InputSpec | None:
        where = "[inputs]"
        data = self.table(raw, where)
        if data is None:
            return None
        mapping: dict[str, str | list[str]] = {}
        ok = True
        for key, value in data.items():
            if key in ("stale_s", "stamp"):
                continue
            if isinstance(value, str) and value:
                mapping[key] = value
            elif isinstance(value, list):
                chans = self.string_list(value, f"{where} {key}")
                ok &= chans is not None
                if chans is not None:
                    mapping[key] = chans
            elif isinstance(value, dict):
                table = self.input_table(value, f"{where} {key}")
                ok &= table is not None
                if table is not None:
                    mapping[key] = table
            else:
                self.add(
                    f"{where} {key}",
                    "expected a channel name, an array of them or a table { channels = [...] }, "
                    f"got {type_name(value)}",
                )
                ok = False
        stale = self.stale(data, "stale_s", where)
        if "stale_s" in data and stale is None:
            ok = False
        if stale is None:
            stale = INPUT_STALE_STEPS / vehicle.rate_hz if vehicle else 0.0
        stamp = data.get("stamp", "end")
        if stamp not in INPUT_STAMPS:
            self.add(f"{where} stamp", f"must be {_choices(INPUT_STAMPS)}, got {stamp!r}")
            ok = False
        return InputSpec(mapping=mapping, stale_s=stale, stamp=stamp) if ok else None

    def input_table(self, data: dict, where: str) -> dict | None:
        """An input's inline table ``{ channels = [...], frame = "flu", scale = 1, offset = 0 }``,
        normalised: ``scale`` / ``offset`` one number per channel, ``frame`` only when given."""
        problems = len(self.problems)
        self.keys(data, where, INPUT_TABLE_KEYS, required=("channels",))
        chans = self.string_list(data["channels"], f"{where} channels") if "channels" in data else None
        scale = self.scale(data, where)
        offset = self.float_list(data, "offset", where, positive=False)
        frame = data.get("frame")
        if "frame" in data:
            if frame not in INPUT_FRAMES:
                self.add(f"{where} frame", f"expected {_choices(INPUT_FRAMES)}, got {type_name(frame)}")
            elif chans is not None and len(chans) != 3:
                self.add(f"{where} frame", f'frame = "{frame}" needs exactly 3 channels (x, y, z), got {len(chans)}')
        if chans is not None:
            scale = self._sized(scale, len(chans), f"{where} scale")
            offset = self._sized(offset, len(chans), f"{where} offset")
        if chans is None or len(self.problems) > problems:
            return None
        out: dict[str, Any] = {"channels": chans}
        if "frame" in data:
            out["frame"] = frame
        if scale is not None:
            out["scale"] = scale
        if offset is not None:
            out["offset"] = offset
        return out

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
        rate = self.rate(data, "rate_hz", where)
        stale = self.stale(data, "stale_s", where)
        noise = self.noise_std(data, where)
        lo = self.float_list(data, "range_lo", where, positive=False)
        hi = self.float_list(data, "range_hi", where, positive=False)
        scale = self.scale(data, where)
        offset = self.float_list(data, "offset", where, positive=False)
        conversion = self.conversion(data, where)
        source = conversion.name if conversion is not None else None
        frame = self.frame(data, where, source, channels)
        origin = self.origin(data, where, source)
        bad_keys = any(
            key in data and value is None for key, value in (("scale", scale), ("offset", offset), ("frame", frame))
        )
        if channels is None or rate is None or bad_keys or ("from" in data and conversion is None):
            return None
        if "origin" in data and origin is None:
            return None
        if scale is not None:
            scale = self._sized(scale, len(channels), f"{where} scale")
        if offset is not None:
            offset = self._sized(offset, len(channels), f"{where} offset")
        if conversion is not None and len(channels) != len(conversion.inputs):
            self.add(
                f"{where} channels",
                f'from = "{source}" needs exactly {len(conversion.inputs)} channels, in the order '
                f"{', '.join(conversion.inputs)}; got {len(channels)}",
            )
            return None
        outputs = list(conversion.output_names(frame or "ned")) if conversion is not None else channels
        n = len(outputs)
        noun = "outputs" if conversion is not None else "channels"
        noise = self._sized(noise, n, f"{where} noise_std", noun)
        noise_channels = None
        if "noise_channels" in data:
            listed = data["noise_channels"]  # one channel may serve several outputs (eph, eph, epv)
            if isinstance(listed, list) and listed and all(isinstance(v, str) and v for v in listed):
                noise_channels = list(listed)
            else:
                self.add(f"{where} noise_channels", f"expected an array of channel names, got {type_name(listed)}")
            if noise_channels is not None and len(noise_channels) != n:
                self.add(
                    f"{where} noise_channels",
                    f"{len(noise_channels)} channels for {n} {noun} (one noise std channel per output)",
                )
                return None
            if noise_channels is None:
                return None
        delay = self.number(data, "delay_s", where, minimum=0, strict=False, maximum=MAX_DELAY_S)
        if "delay_s" in data and delay is None:
            return None
        fresh = data.get("fresh", FRESH_MODES[0])
        if fresh not in FRESH_MODES:
            self.add(f"{where} fresh", f"expected {_choices(FRESH_MODES)}, got {type_name(fresh)}")
            return None
        # a factor on every logged std (set by `logscan train --calibrate`, or by hand)
        noise_channels_scale = self.number(data, "noise_channels_scale", where, minimum=0, strict=True)
        if "noise_channels_scale" in data and noise_channels is None:
            self.add(f"{where} noise_channels_scale", "scales the noise_channels' std: list noise_channels too")
            return None
        lo = self._sized(lo, n, f"{where} range_lo", noun)
        hi = self._sized(hi, n, f"{where} range_hi", noun)
        if lo is not None and hi is not None:
            bad = [i for i in range(n) if not lo[i] < hi[i]]
            if bad:
                i = bad[0]
                self.add(
                    where,
                    f"range_lo must be < range_hi, got {lo[i]:g} >= {hi[i]:g} for {outputs[i]!r}",
                )
        if stale is None and "stale_s" not in data:
            stale = GROUP_STALE_PERIODS / rate
        if stale is None or ("scale" in data and scale is None) or ("offset" in data and offset is None):
            return None
        return MeasurementSpec(
            name,
            channels,
            rate,
            stale,
            noise,
            lo,
            hi,
            scale=scale,
            source=source,
            origin=origin,
            frame=frame or "ned",
            offset=offset,
            noise_channels=noise_channels,
            noise_channels_scale=1.0 if noise_channels_scale is None else noise_channels_scale,
            delay_s=0.0 if delay is None else delay,
            fresh=fresh,
            **self.gate(data, where),
        )

    def gate(self, data: dict, where: str) -> dict:
        """``gate = { channel = "...", min = 3 }``: the keyword arguments of MeasurementSpec."""
        if "gate" not in data:
            return {}
        table = self.table(data["gate"], f"{where} gate")
        if table is None:
            return {}
        self.keys(table, f"{where} gate", GATE_KEYS, required=("channel", "min"))
        channel = self.string(table, "channel", f"{where} gate")
        minimum = self.number(table, "min", f"{where} gate", minimum=-1e12, strict=False, maximum=1e12)
        if channel is None or minimum is None:
            return {}
        return {"gate_channel": channel, "gate_min": float(minimum)}

    def scale(self, data: dict, where: str) -> list[float] | None:
        """``scale``: finite, non-zero factors (a number or one per channel)."""
        scale = self.float_list(data, "scale", where, positive=False)
        if scale is not None and any(v == 0.0 for v in scale):
            self.add(f"{where} scale", "must be non-zero, got 0")
            return None
        return scale

    def conversion(self, data: dict, where: str) -> Conversion | None:
        """``from``: one of `CONVERSIONS`, None when absent or with a problem."""
        if "from" not in data:
            return None
        value = data["from"]
        choices = ", ".join(f'"{c}"' for c in CONVERSIONS)
        if not isinstance(value, str):
            self.add(f"{where} from", f"expected a string ({choices}), got {type_name(value)}")
            return None
        if value not in CONVERSIONS:
            self.add(f"{where} from", f"unknown conversion {value!r}{suggest(value, CONVERSIONS)} (choices: {choices})")
            return None
        return CONVERSIONS[value]

    def frame(self, data: dict, where: str, source: str | None, channels: list[str] | None) -> str | None:
        """``frame``: of a geodetic group "ned" (the default), "enu", or horizontal "ne" / "en"; of a
        quaternion group "ned" (the default: FRD to NED) or "enu_flu" (a ROS orientation); of a
        group without ``from``, a 3-vector's frame: "frd" / "ned" (as it is), "flu" or "enu"
        (converted)."""
        if "frame" not in data:
            return None
        value = data["frame"]
        if "from" in data and source is None:  # an unknown `from` is reported already
            return None
        choices = GROUP_FRAMES[source]
        if not isinstance(value, str) or value not in choices:
            what = {None: " (a 3-vector without from)", "quaternion": ' (from = "quaternion")'}.get(source, "")
            self.add(f"{where} frame", f"expected {_choices(choices)}{what}, got {type_name(value)}")
            return None
        if source is None and channels is not None and len(channels) != 3:
            self.add(f"{where} frame", f'frame = "{value}" needs exactly 3 channels (x, y, z), got {len(channels)}')
            return None
        return value

    def origin(self, data: dict, where: str, source: str | None) -> list[float] | None:
        """``origin`` of a geodetic group: [latitude deg in [-90, 90], longitude deg in [-180, 180],
        altitude m], all finite."""
        if "origin" not in data:
            return None
        if source != "geodetic":
            if "from" not in data or source is not None:
                self.add(f"{where} origin", 'only allowed with from = "geodetic"')
            return None
        value = self.float_list(data, "origin", where, positive=False)
        if value is None:
            return None
        if not isinstance(data["origin"], list) or len(value) != 3:
            self.add(f"{where} origin", "expected [latitude_deg, longitude_deg, altitude_m] (3 numbers)")
            return None
        if not -90.0 <= value[0] <= 90.0:
            self.add(f"{where} origin", f"latitude must be within [-90, 90] degrees, got {value[0]:g}")
            return None
        if not -180.0 <= value[1] <= 180.0:
            self.add(f"{where} origin", f"longitude must be within [-180, 180] degrees, got {value[1]:g}")
            return None
        return value

    def noise_std(self, data: dict, where: str) -> list[float] | None:
        """``noise_std``: > 0 and within `_STD_LIMITS` (its square, the variance, a normal float);
        the bound by the group's range span needs the model (`bind`)."""
        noise = self.float_list(data, "noise_std", where, positive=True)
        if noise is None:
            return None
        smallest, largest = _STD_LIMITS
        if max(noise) > largest:
            self.add(f"{where} noise_std", f"{max(noise):g} would hide every fault of the group (at most {largest:g})")
        elif min(noise) < smallest:
            self.add(
                f"{where} noise_std", f"{min(noise):g} is too small: its square underflows (at least {smallest:g})"
            )
        else:
            return noise
        return None

    def _sized(self, values: list[float] | None, n: int, where: str, noun: str = "channels") -> list[float] | None:
        if values is None:
            return None
        if len(values) == 1:
            return values * n
        if len(values) != n:
            self.add(where, f"{len(values)} values for {n} {noun} (give one number or {n})")
            return None
        return values

    def mode(self, raw: Any) -> ModeSpec | None:
        where = "[mode]"
        data = self.table(raw, where)
        if data is None:
            return None
        self.keys(data, where, MODE_KEYS, required=("channel",))
        channel = self.string(data, "channel", where)
        stale = self.stale(data, "stale_s", where)
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
            rate = self.rate(t, "rate_hz", where)
            stale = self.stale(t, "stale_s", where)
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
                    f"expected a channel name or a table {{ channel, poly }}, got {type_name(value)}",
                )
                continue
            self.keys(value, f"{where}.{name}", SENSOR_KEYS, required=("channel",))
            channel = self.string(value, "channel", f"{where}.{name}")
            poly = self.float_list(value, "poly", f"{where}.{name}", positive=False)
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
                    f"got {type_name(value)}",
                )
        stale = self.stale(data, "stale_s", where)
        return OnboardSpec(
            state=values.get("state"),
            variance=values.get("variance"),
            stale_s=ONBOARD_STALE_S if stale is None else stale,
        )

    def alarms(self, raw: Any) -> AlarmPolicy | None:
        """`[alarms]`: floors under every detector's alarm options (see `AlarmPolicy`)."""
        where = "[alarms]"
        data = self.table(raw, where)
        if data is None:
            return None
        self.keys(data, where, ALARM_KEYS)
        n_persist = data.get("n_persist", 1)
        if isinstance(n_persist, bool) or not isinstance(n_persist, int):
            self.add(f"{where} n_persist", f"expected an integer, got {type_name(n_persist)}")
            n_persist = None
        elif not 1 <= n_persist <= MAX_ALARM_PERSIST:
            self.add(f"{where} n_persist", f"must be between 1 and {MAX_ALARM_PERSIST}, got {n_persist}")
            n_persist = None
        duration = self.number(data, "min_duration_s", where, minimum=0, strict=False, maximum=MAX_ALARM_DURATION_S)
        gap = self.number(data, "merge_gap_s", where, minimum=0, strict=False, maximum=MAX_MERGE_GAP_S)
        after = self.number(data, "after_ground_s", where, minimum=0, strict=False, maximum=MAX_SUSPEND_S)
        before = self.number(data, "before_ground_s", where, minimum=0, strict=False, maximum=MAX_SUSPEND_S)
        blip = self.number(data, "min_ground_s", where, minimum=0, strict=False, maximum=MAX_SUSPEND_S)
        start = self.number(data, "ignore_start_s", where, minimum=0, strict=False, maximum=MAX_SUSPEND_S)
        ground = self.string(data, "ground_channel", where) if "ground_channel" in data else None
        numbers = (("min_duration_s", duration), ("merge_gap_s", gap), ("after_ground_s", after))
        numbers += (("before_ground_s", before), ("min_ground_s", blip), ("ignore_start_s", start))
        if n_persist is None or any(key in data and value is None for key, value in numbers):
            return None
        if "ground_channel" in data and ground is None:
            return None
        return AlarmPolicy(
            n_persist=n_persist,
            min_duration_s=0.0 if duration is None else duration,
            merge_gap_s=AlarmPolicy.merge_gap_s if gap is None else gap,
            ground_channel=ground,
            after_ground_s=AlarmPolicy.after_ground_s if after is None else after,
            before_ground_s=0.0 if before is None else before,
            min_ground_s=0.0 if blip is None else blip,
            ignore_start_s=0.0 if start is None else start,
        )

    def recovery_table(self, data: dict, loop_names: set[str]) -> RecoverySpec | None:
        if "recovery" not in data:
            return None
        return parse_recovery(self, data["recovery"], loop_names)

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
                self.add(f"{where} enabled", f"expected true or false, got {type_name(enabled)}")
                continue
            out[name] = DetectorSpec(name, enabled, {k: v for k, v in t.items() if k != "enabled"})
        return out
