"""Ground truth for any log: embedded (logs of `logscan simulate`), a `<log>.truth.json` beside the
log in any format, or a file given with ``--truth``.

A truth document is JSON with ``events`` (and optionally ``transients``): each an object with
``kind``, ``target`` and its interval, either ``start`` / ``end`` in seconds on the log's time axis
(seconds since the log's start, as every report and alarm time) or ``start_utc`` / ``end_utc``
(ISO 8601, e.g. "2024-03-18T14:49:30Z") for logs with an absolute clock (MCAP and ULog times are
UTC when the log carries it). ``end`` / ``end_utc`` may be null (to the log's end).
"""

from __future__ import annotations

import datetime as _dt
import json
import os
from pathlib import Path
from typing import Any

from logscan.errors import InputError, where_in_text
from logscan.input_files import MAX_TRUTH_BYTES, read_input_text

ABSOLUTE_NS = 10**15  # log times above this are epoch nanoseconds (later than 1970-01-12)


def read_truth_file(path: str | os.PathLike) -> dict[str, Any]:
    """The truth JSON at ``path`` (InputError naming the file on anything unreadable)."""
    text = read_input_text(path, what="ground truth", limit=MAX_TRUTH_BYTES)
    try:
        document = json.loads(text)
    except RecursionError:
        raise InputError("ground truth is nested too deeply to be truth JSON", path=str(path)) from None
    except ValueError as exc:
        raise InputError(
            f"ground truth is not valid JSON{where_in_text(exc)}",
            path=str(path),
            hint="give a JSON object with a list of events (kind, target, start and end in seconds)",
        ) from None
    if not isinstance(document, dict) or not isinstance(document.get("events", []), list):
        raise InputError(
            "ground truth must be a JSON object with a list of events",
            path=str(path),
            hint='{"events": [{"kind": "bias", "target": "gps", "start": 30.0, "end": 40.0}]}',
        )
    return document


def truth_beside(log_path: str | os.PathLike) -> Path | None:
    """``flight.ulg`` -> ``flight.truth.json`` (or ``flight.ulg.truth.json``), when one exists."""
    p = Path(os.path.abspath(log_path))  # "." names its folder
    for candidate in (p.with_suffix(".truth.json"), p.with_name(p.name + ".truth.json")):
        if candidate != p and candidate.is_file():
            return candidate
    return None


def in_log_time(document: dict[str, Any], start_ns: int, path: str | None = None) -> dict[str, Any]:
    """``document`` with every ``start_utc`` / ``end_utc`` turned into ``start`` / ``end`` seconds
    since ``start_ns`` (the log's start); InputError when the log's clock is not absolute."""
    out = dict(document)
    for key in ("events", "transients"):
        items = []
        for i, item in enumerate(document.get(key) or []):
            item = dict(item) if isinstance(item, dict) else item
            if isinstance(item, dict) and ("start_utc" in item or "end_utc" in item):
                if start_ns is None or start_ns < ABSOLUTE_NS:
                    raise InputError(
                        f"ground-truth {key[:-1]} {i} is in UTC, but the log's clock is not absolute",
                        path=path,
                        hint="give start / end in seconds since the log's start instead",
                    )
                for name in ("start", "end"):
                    if f"{name}_utc" in item:
                        item[name] = _seconds_since(item.pop(f"{name}_utc"), start_ns, f"{key[:-1]} {i}", path)
            items.append(item)
        if key in document:
            out[key] = items
    return out


def _seconds_since(text: Any, start_ns: int, what: str, path: str | None) -> float | None:
    if text is None:
        return None
    try:
        stamp = _dt.datetime.fromisoformat(str(text).replace("Z", "+00:00"))
    except ValueError:
        raise InputError(
            f"ground-truth {what}: {text!r} is not an ISO 8601 time", path=path, hint='e.g. "2024-03-18T14:49:30Z"'
        ) from None
    if stamp.tzinfo is None:
        stamp = stamp.replace(tzinfo=_dt.UTC)
    return (stamp.timestamp() * 1e9 - start_ns) / 1e9
