"""The profile checker's other sections: `[vehicle]`, `[inputs]`, `[mode]`, `[redundant]`,
`[onboard]`, `[alarms]`, `[recovery]` and `[detectors]` (`SectionChecker`)."""

from __future__ import annotations

import math
from typing import Any

from logscan.profiles.check_groups import GroupChecker
from logscan.profiles.check_values import _choices
from logscan.profiles.loops import RecoverySpec, parse_recovery
from logscan.profiles.problems import type_name
from logscan.profiles.schema import (
    ALARM_KEYS,
    INPUT_FRAMES,
    INPUT_STALE_STEPS,
    INPUT_STAMPS,
    INPUT_TABLE_KEYS,
    MAX_ALARM_DURATION_S,
    MAX_ALARM_PERSIST,
    MAX_MERGE_GAP_S,
    MAX_SUSPEND_S,
    MODE_KEYS,
    MODE_STALE_S,
    ONBOARD_KEYS,
    ONBOARD_STALE_S,
    REDUNDANT_KEYS,
    SENSOR_KEYS,
    VEHICLE_KEYS,
    DetectorSpec,
    InputSpec,
    ModeSpec,
    OnboardSpec,
    RedundantSpec,
    SensorSpec,
    VehicleSpec,
)
from logscan.results import AlarmPolicy


class SectionChecker(GroupChecker):
    """Every section of a profile but its measurement groups."""

    vehicle_spec: VehicleSpec | None

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

    def mode(self, raw: Any) -> ModeSpec | None:
        where = "[mode]"
        data = self.table(raw, where)
        if data is None:
            return None
        self.keys(data, where, MODE_KEYS, required=("channel",))
        channel = self.string(data, "channel", where)
        stale = self.stale(data, "stale_s", where)
        problems = len(self.problems)
        labels = self.mode_labels(data.get("labels", {}), f"{where} labels")
        if channel is None or ("stale_s" in data and stale is None) or len(self.problems) > problems:
            return None
        return ModeSpec(channel, MODE_STALE_S if stale is None else stale, labels)

    def mode_labels(self, raw: Any, where: str) -> dict[float, str]:
        """``{ "<value>" = "<name>" }`` -> {value: name}; each key that is not a finite number and each
        name that is not a non-empty string is a problem of its own."""
        if not isinstance(raw, dict):
            self.add(where, f'expected a table of value = name (e.g. {{ "0" = "FIX" }}), got {type_name(raw)}')
            return {}
        labels: dict[float, str] = {}
        for key, name in raw.items():
            try:
                value = float(key)
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                self.add(where, f"key {key!r} is not a number (a value the mode channel takes)")
            elif not isinstance(name, str) or not name.strip():
                self.add(where, f"the name of {key!r} must be a non-empty string, not {name!r}")
            elif value in labels:
                self.add(where, f"key {key!r} names the value {value:g} again (as {labels[value]!r})")
            else:
                labels[value] = name.strip()
        return labels

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
