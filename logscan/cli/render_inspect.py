"""`logscan inspect`'s text view: a log's topics, fields, channels, metadata and what was skipped."""

from __future__ import annotations

import re
import shutil
import textwrap
from datetime import UTC, datetime
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    pass

from logscan.cli.render import _lines, printable

_EPOCH_MIN_NS = 946_684_800 * 10**9  # 2000-01-01: later start times are wall-clock (epoch) time
_FIELD_LINES = 3  # wrapped lines of fields per topic before truncating (--full shows all)
_LIST_LIMIT = 40  # skipped items, warnings and metadata entries shown before truncating
_ARRAY_RE = re.compile(r"^(?P<base>.*)\[(?P<index>\d+)\]$")
_INFO_KEYS = ("sys_name", "ver_hw", "ver_sw", "ver_sw_release", "ver_sw_branch", "sys_os_name",
              "sys_uuid", "time_ref_utc")  # fmt: skip


def compact_fields(fields: list[str]) -> list[str]:
    """Runs of array elements ``q[0], q[1], q[2]`` shown as ``q[0..2]``; other names unchanged."""
    out: list[str] = []
    run_base, run_first, run_last = None, -1, -1

    def flush() -> None:
        if run_base is not None:
            out.append(f"{run_base}[{run_first}]" if run_first == run_last else f"{run_base}[{run_first}..{run_last}]")

    for name in fields:
        match = _ARRAY_RE.match(name)
        if match and match.group("base") == run_base and int(match.group("index")) == run_last + 1:
            run_last += 1
            continue
        flush()
        if match:
            run_base, run_first = match.group("base"), int(match.group("index"))
            run_last = run_first
        else:
            run_base = None
            out.append(name)
    flush()
    return out


def _wrap_fields(fields: list[str], indent: str, width: int, full: bool) -> list[str]:
    """Fields as wrapped lines; beyond ``_FIELD_LINES`` lines a count of the rest (unless full)."""
    shown = compact_fields(fields)
    prefix = indent + "fields: "
    lines = textwrap.wrap(
        ", ".join(shown), width=max(40, width - len(prefix)), break_long_words=False, break_on_hyphens=False
    )
    if not full and len(lines) > _FIELD_LINES:
        kept = lines[:_FIELD_LINES]
        listed = " ".join(kept).count(",")  # each line ends "name," while more follow
        kept[-1] = kept[-1].rstrip(",") + ","
        lines = kept + [f"... +{len(shown) - listed} more (--full lists all)"]
    return [(prefix if i == 0 else " " * len(prefix)) + line for i, line in enumerate(lines)]


def _rate(hz: float) -> str:
    """A rate in a 9-character column (scientific notation beyond what fits)."""
    return f"{hz:>9.3f}" if hz < 1e5 else f"{hz:>9.3g}"


def _fmt_time(ns: int) -> str:
    if ns >= _EPOCH_MIN_NS:
        stamp = datetime.fromtimestamp(ns / 1e9, tz=UTC)
        return stamp.isoformat(timespec="milliseconds").replace("+00:00", "Z")
    return f"{ns / 1e9:.6f} s"


def _limited(items: list[str], full: bool, what: str) -> list[str]:
    if full or len(items) <= _LIST_LIMIT:
        return items
    return items[:_LIST_LIMIT] + [f"... {len(items) - _LIST_LIMIT} more {what} (--full lists all)"]


def render_inspect(facts: dict, show_channels: bool, *, full: bool = False, width: int | None = None) -> str:
    """Plain-text view of ``inspect_facts`` / ``Log.summary()`` for the terminal."""
    width = width or max(60, min(shutil.get_terminal_size((100, 24)).columns, 160))
    lines = _source_lines(facts) + _topic_lines(facts, width, full) + _channel_lines(facts, show_channels)
    return _lines(lines + _skipped_lines(facts, full))


def _source_lines(facts: dict) -> list[str]:
    """The file, its format and time column(s), time span, what was not read, and its metadata."""
    metadata = facts.get("metadata", {})
    lines = [
        f"file:      {facts['file']}",
        f"format:    {facts['format']}  (time from {facts['time_source']}, source unit {facts['time_unit']})",
    ]
    by_rule: dict[str, list[str]] = {}
    for label, column in metadata.get("csv.time_columns", {}).items():
        by_rule.setdefault(column, []).append(label)
    for column, labels in by_rule.items():
        who = (
            labels[0]
            if len(labels) == 1
            else (f"{len(labels)} files ({', '.join(labels[:3])}{', ...' if len(labels) > 3 else ''})")
        )
        lines.append(f"time col:  {who}: {column}")
    if facts["start_ns"] is not None:
        lines.append(
            f"time span: {_fmt_time(facts['start_ns'])} .. {_fmt_time(facts['end_ns'])} ({facts['duration_s']:.3f} s)"
        )
    else:
        lines.append("time span: (no messages)")
    if facts["partial"]:
        lines.append(f"PARTIAL:   only part of the file was read: {facts['partial_reason']}")
    lines.append(
        f"extras:    ground truth: {'yes' if facts['has_truth'] else 'no'}, "
        f"embedded profile: {'yes' if facts['has_profile'] else 'no'}"
    )
    lines.extend(_render_metadata(metadata))

    return lines


def _topic_lines(facts: dict, width: int, full: bool) -> list[str]:
    """The topics with counts, rates, encodings and (wrapped) fields."""
    topics = [(printable(name), info) for name, info in facts["topics"].items()]  # escaped before measured
    total = sum(info["message_count"] for _, info in topics)
    lines = ["", f"{len(topics)} topic(s), {total} message(s):"]
    if topics:
        name_width = min(max(len(name) for name, _ in topics), 48)
        lines.append(f"  {'topic':<{name_width}}  {'messages':>9}  {'rate Hz':>9}  encoding / schema")
        for name, info in topics:
            kind = " / ".join(x for x in (info["encoding"], info["schema"]) if x)
            lines.append(f"  {name:<{name_width}}  {info['message_count']:>9}  {_rate(info['rate_hz'])}  {kind}")
            if info["fields"]:
                lines.extend(_wrap_fields([printable(f) for f in info["fields"]], "    ", width, full))

    return lines


def _channel_lines(facts: dict, show_channels: bool) -> list[str]:
    """The count of numeric channels and, with --channels, one line each."""
    channels = [(printable(name), info) for name, info in facts["channels"].items()]
    with_nan = sum(1 for _, info in channels if info.get("nonfinite"))
    lines = [
        "",
        f"{len(channels)} numeric channel(s)"
        + (f", {with_nan} with NaN/inf values" if with_nan else "")
        + ("" if show_channels or not channels else " (--channels lists them)"),
    ]
    if show_channels and channels:
        name_width = min(max(len(name) for name, _ in channels), 60)
        lines.append(f"  {'channel':<{name_width}}  {'samples':>9}  {'rate Hz':>9}  {'NaN/inf':>7}  range")
        for name, info in channels:
            low, high = info.get("min"), info.get("max")
            span = "-" if low is None else f"{low:.6g} .. {high:.6g}"
            rate = _rate(info.get("rate_hz", 0.0))
            lines.append(f"  {name:<{name_width}}  {info['samples']:>9}  {rate}  {info.get('nonfinite', 0):>7}  {span}")
    return lines


def _skipped_lines(facts: dict, full: bool) -> list[str]:
    """What was skipped (kinds with counts) and the warnings."""
    lines: list[str] = []
    if facts["skipped"]:
        total_skipped = sum(item["count"] for item in facts["skipped"])
        lines += ["", f"skipped ({len(facts['skipped'])} kind(s), {total_skipped} item(s)):"]
        items = [f"  {item['what']}: {item['why']} (x{item['count']})" for item in facts["skipped"]]
        lines.extend(_limited(items, full, "skipped kinds"))
    if facts["warnings"]:
        lines += ["", f"warnings ({len(facts['warnings'])}):"]
        lines.extend(_limited([f"  {w}" for w in facts["warnings"]], full, "warnings"))
    return lines


def _render_metadata(metadata: dict) -> list[str]:
    """A few lines on the source's metadata: ULog system info and counts, other records by name."""
    lines: list[str] = []
    info = metadata.get("ulog.info", {})
    if info:
        shown = [f"{key}={info[key]}" for key in _INFO_KEYS if key in info]
        lines.append(f"system:    {', '.join(shown) if shown else '(no system info)'}")
    log_facts = metadata.get("ulog.log")
    if log_facts:
        lines.append(
            f"ulog:      {len(metadata.get('ulog.parameters', {}))} parameter(s), "
            f"{log_facts.get('changed_parameters', '0')} changed in flight, "
            f"{log_facts.get('logged_messages', '0')} logged message(s), "
            f"{log_facts.get('dropouts', '0')} dropout(s) ({log_facts.get('dropout_total_ms', '0')} ms)"
        )
    others = [k for k in metadata if not k.startswith(("ulog.", "csv."))]
    if others:
        lines.append("metadata:  " + ", ".join(f"{k} ({len(metadata[k])} key(s))" for k in others))
    return lines
