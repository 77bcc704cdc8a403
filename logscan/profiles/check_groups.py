"""The profile checker's `[measurements.<group>]` section: channels, rates, noise, ranges,
conversions and frames, gates and freshness (`GroupChecker`)."""

from __future__ import annotations

from typing import Any

from logscan.conversions import CONVERSIONS, GROUP_FRAMES, Conversion
from logscan.profiles.check_values import ValueChecker, _choices
from logscan.profiles.problems import suggest, type_name
from logscan.profiles.schema import (
    FRESH_MODES,
    GATE_KEYS,
    GROUP_KEYS,
    GROUP_STALE_PERIODS,
    MAX_DELAY_S,
    MeasurementSpec,
)


class GroupChecker(ValueChecker):
    """`[measurements]`: one MeasurementSpec per valid group."""

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
        given = {"scale": scale, "offset": offset, "frame": frame, "from": conversion, "origin": origin}
        if channels is None or rate is None or any(key in data and given[key] is None for key in given):
            return None  # a problem is reported: a key missing, or given but invalid
        scale = self._sized(scale, len(channels), f"{where} scale") if scale is not None else None
        offset = self._sized(offset, len(channels), f"{where} offset") if offset is not None else None
        outputs = self._outputs(channels, conversion, frame, where)
        if outputs is None:
            return None
        n = len(outputs)
        noun = "outputs" if conversion is not None else "channels"
        noise = self._sized(noise, n, f"{where} noise_std", noun)
        noise_channels = self._noise_channels(data, where, n, noun)
        if "noise_channels" in data and noise_channels is None:
            return None
        timing = self._timing(data, where, noise_channels)
        if timing is None:
            return None
        lo, hi = self._ranges(lo, hi, outputs, where, noun)
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
            **timing,
            **self.gate(data, where),
        )

    def _outputs(self, channels: list[str], conversion, frame: str | None, where: str) -> list[str] | None:
        """The group's outputs: its channels, or what its ``from`` conversion gives (None: the
        conversion's channel count is wrong)."""
        if conversion is None:
            return channels
        if len(channels) != len(conversion.inputs):
            self.add(
                f"{where} channels",
                f'from = "{conversion.name}" needs exactly {len(conversion.inputs)} channels, in the order '
                f"{', '.join(conversion.inputs)}; got {len(channels)}",
            )
            return None
        return list(conversion.output_names(frame or "ned"))

    def _timing(self, data: dict, where: str, noise_channels) -> dict | None:
        """``delay_s``, ``fresh`` and ``noise_channels_scale`` as MeasurementSpec keywords (None: a problem)."""
        delay = self.number(data, "delay_s", where, minimum=0, strict=False, maximum=MAX_DELAY_S)
        if "delay_s" in data and delay is None:
            return None
        fresh = data.get("fresh", FRESH_MODES[0])
        if fresh not in FRESH_MODES:
            self.add(f"{where} fresh", f"expected {_choices(FRESH_MODES)}, got {type_name(fresh)}")
            return None
        # a factor on every logged std (set by `logscan train --calibrate`, or by hand)
        scale = self.number(data, "noise_channels_scale", where, minimum=0, strict=True)
        if "noise_channels_scale" in data and noise_channels is None:
            self.add(f"{where} noise_channels_scale", "scales the noise_channels' std: list noise_channels too")
            return None
        return {
            "delay_s": 0.0 if delay is None else delay,
            "fresh": fresh,
            "noise_channels_scale": 1.0 if scale is None else scale,
        }

    def _noise_channels(self, data: dict, where: str, n: int, noun: str) -> list[str] | None:
        """``noise_channels``: one channel of noise std per output (one channel may serve several
        outputs: eph, eph, epv); None when absent or with a problem."""
        if "noise_channels" not in data:
            return None
        listed = data["noise_channels"]
        if not (isinstance(listed, list) and listed and all(isinstance(v, str) and v for v in listed)):
            self.add(f"{where} noise_channels", f"expected an array of channel names, got {type_name(listed)}")
            return None
        if len(listed) != n:
            self.add(
                f"{where} noise_channels", f"{len(listed)} channels for {n} {noun} (one noise std channel per output)"
            )
            return None
        return list(listed)

    def _ranges(self, lo, hi, outputs: list[str], where: str, noun: str):
        """(range_lo, range_hi) sized to the outputs, lo < hi for each."""
        n = len(outputs)
        lo = self._sized(lo, n, f"{where} range_lo", noun)
        hi = self._sized(hi, n, f"{where} range_hi", noun)
        if lo is not None and hi is not None:
            bad = [i for i in range(n) if not lo[i] < hi[i]]
            if bad:
                i = bad[0]
                self.add(where, f"range_lo must be < range_hi, got {lo[i]:g} >= {hi[i]:g} for {outputs[i]!r}")
        return lo, hi

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
