"""The report's context: the log's facts, the measurement groups the profile used, the model.

Plain views (strings and lists) of what the analysis read, for the "Log" and "Profile and model"
sections: the log's format, span and topics (in the log vs read), each measurement group as the
profile mapped it with the filter's counts, and the model's states, inputs and parameters.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
import re
from collections.abc import Mapping
from typing import Any

import numpy as np

from logscan.report.parameters import parameter_rows


def number_text(value: Any, digits: int = 4) -> str:
    """A number in ``digits`` significant digits, plain ("—" for None, "NaN", "inf")."""
    if value is None:
        return "—"
    try:
        x = float(value)
    except (TypeError, ValueError):
        return str(value)
    if math.isnan(x):
        return "NaN"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:.{digits}g}"


def info_rows(info: Mapping) -> list[tuple[str, str]]:
    """(key, text) rows of a JSON-ready mapping, long values cut to 400 characters."""
    rows = []
    for key, value in info.items():
        if isinstance(value, np.ndarray):
            value = value.tolist()
        text = value if isinstance(value, str) else json.dumps(value, default=str)
        if len(text) > 400:
            text = text[:400] + " …"
        rows.append((str(key), text))
    return rows


def _time_text(ns: Any) -> str:
    if ns is None:
        return "—"
    ns = int(ns)
    if ns > 10**15:  # absolute epoch time (later than 1970-01-12)
        stamp = _dt.datetime.fromtimestamp(ns / 1e9, tz=_dt.UTC)
        return stamp.isoformat(timespec="milliseconds").replace("+00:00", " UTC")
    return f"{ns / 1e9:.3f} s"


def _topic_rows(facts: Mapping) -> list[dict]:
    """Each topic of the log: name, messages, rate, and whether the analysis read it (a channel
    ``<topic>/<field>`` of it was decoded)."""
    channels = facts.get("channels") or {}
    rows = []
    for name, info in (facts.get("topics") or {}).items():
        info = info if isinstance(info, Mapping) else {}
        fields = info.get("fields") or []
        rows.append({
            "name": str(name),
            "messages": str(info.get("message_count", "—")),
            "rate": number_text(info.get("rate_hz"), 3),
            # MCAP topics start with "/" as their channels do; a ULog topic (sensor_combined_0) does not
            "read": any(f"{name}/{f}" in channels or f"/{name}/{f}" in channels for f in fields),
        })  # fmt: skip
    return sorted(rows, key=lambda r: (not r["read"], r["name"]))


def log_view(facts: Mapping) -> dict:
    topics = _topic_rows(facts)
    return {
        "file": str(facts.get("file", "")),
        "name": os.path.basename(str(facts.get("file", ""))) or "log",
        "format": str(facts.get("format", "")),
        "start": _time_text(facts.get("start_ns")),
        "end": _time_text(facts.get("end_ns")),
        "duration": number_text(facts.get("duration_s"), 6),
        "time_source": str(facts.get("time_source", "")),
        "n_topics": len(topics),
        "n_read": sum(1 for t in topics if t["read"]),
        "n_channels": len(facts.get("channels") or {}),
        "partial": bool(facts.get("partial")),
        "partial_reason": str(facts.get("partial_reason", "")),
        "skipped": [
            f"{s.get('what', '')}: {s.get('why', '')} (x{s.get('count', 1)})" for s in facts.get("skipped") or []
        ],
        "warnings": [str(w) for w in facts.get("warnings") or []],
        "topics": topics,
    }


def model_view(model: Mapping) -> dict:
    return {
        "name": str(model.get("name", "")),
        "states": [str(s) for s in model.get("states", [])],
        "inputs": [str(s) for s in model.get("inputs", [])],
        "groups": [str(g) for g in (model.get("groups") or {})],
        "params": info_rows(model.get("params") or {}),
    }


def measurement_groups(profile, filter_summary: Mapping | None) -> list[dict]:
    """The profile's measurement groups as the analysis used them, with the filter's counts:
    ``{name, channels, size, conversion, rate_hz, noise_std, updates, rejected, mean_nis}`` (counts
    None without a filter). ``profile``: a `logscan.profiles.schema.Profile`."""
    counts = filter_summary or {}
    out = []
    for name, spec in profile.measurements.items():
        out.append({
            "name": name,
            "channels": list(spec.channels),
            "size": spec.width,  # the model outputs the channels give (after a `from` conversion)
            "conversion": spec.source,
            "rate_hz": spec.rate_hz,
            "noise_std": list(spec.noise_std) if spec.noise_std is not None else None,
            "updates": (counts.get("updates") or {}).get(name),
            "rejected": (counts.get("rejected") or {}).get(name),
            "mean_nis": (counts.get("mean_nis") or {}).get(name),
        })  # fmt: skip
    return out


def group_rows(groups: list[dict]) -> list[dict]:
    """Table rows of :func:`measurement_groups`."""
    return [
        {
            "name": str(g.get("name", "")),
            "channels": ", ".join(str(c) for c in g.get("channels") or [])
            + (f" (from {g['conversion']})" if g.get("conversion") else ""),
            "rate": number_text(g.get("rate_hz"), 4),
            "noise": ", ".join(number_text(v, 3) for v in g.get("noise_std") or []) or "—",
            "updates": number_text(g.get("updates"), 12),
            "rejected": number_text(g.get("rejected"), 12),
            "mean_nis": number_text(g.get("mean_nis"), 3),
            "dof": g.get("size") or len(g.get("channels") or []),
        }
        for g in groups
    ]


_COLOUR_CODES = re.compile(r"\x1b\[[0-9;]*m")  # a terminal's colour codes (PX4 colours "Ready for takeoff!")
_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f\u202a-\u202e\u2066-\u2069]")


def message_text(text: str) -> str:
    """A logged message as the page shows it: terminal colour codes dropped, any other control
    character (or bidirectional override) as a visible escape (``\\x1b``)."""
    text = _COLOUR_CODES.sub("", text)
    return _CONTROL.sub(_escape, text)


def _escape(match: re.Match) -> str:
    code = ord(match.group())
    return f"\\x{code:02x}" if code < 256 else f"\\u{code:04x}"


def log_message_rows(context, clock) -> dict:
    """The folded table of every message the autopilot logged (a `logscan.report.run_context.RunContext`'s
    ``log_messages``, any level): ``{"rows": [{time, level, text, t0}], "n": count in the log (in a
    --start/--end window: in it), "outside": count outside the window, "window": whether there is
    one}``; ``t0`` in the time axis' units, where a click zooms."""
    messages = list(getattr(context, "log_messages", None) or [])
    rows = [
        {
            "time": clock.short(m.t),
            "level": m.level.lower(),
            "text": message_text(m.text),
            "t0": repr(clock.axis_value(m.t)),
        }
        for m in messages
    ]
    return {
        "rows": rows,
        "n": max(int(getattr(context, "n_log_messages", 0) or 0), len(rows)),
        "outside": int(getattr(context, "n_outside", 0) or 0),
        "window": getattr(context, "window", None) is not None,
    }


def context_tables(context, clock) -> dict:
    """The report's tables of the flight beside its figures: the autopilot's logged messages and
    its parameters (PX4)."""
    parameters = parameter_rows(getattr(context, "parameters", None), clock)
    return {"log_messages": log_message_rows(context, clock), "parameters": parameters}


def message_row(message, clock) -> dict:
    """One autopilot message as the report's table shows it."""
    return {
        "level": message.level,
        "text": message.text,
        "time": clock.short(message.first),
        "last": clock.short(message.last) if message.count > 1 else "",
        "count": message.count,
        "incident": "" if message.incident is None else str(message.incident),
        "start": repr(clock.axis_value(message.first)),  # where a click zooms: the time axis' units
        "end": repr(clock.axis_value(message.last)),
    }
