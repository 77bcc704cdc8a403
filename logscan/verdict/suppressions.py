"""Suppressions: known alarms a team has accepted, silenced with a reason that every artifact shows.

A TOML file (`logscan analyze --suppressions FILE`) of ``[[suppress]]`` entries:

    [[suppress]]
    detector = "nis"                      # required
    check = "nis.gps_speed"               # the statistic; default: every one of the detector
    log = "hangar_*.mcap"                 # a glob on the log's file name or path; default: every log
    start = 10.0                          # seconds since the log's start; an alarm is suppressed
    end = 20.0                            #   when it lies inside [start, end]
    reason = "GPS multipath in the hangar (OPS-12)"   # required
    expires = 2027-01-31                  # optional: after this date the file is refused

An entry without a reason, an expired one, or an unknown key is exit 2 (before any log is read). A
suppressed alarm leaves the verdict, the exit code and the scores; it is listed, with its reason,
in the summary, the JSON, the report and the CI artifacts.

An entry that suppressed no alarm of the run (as ruff reports an unused ``noqa``) is listed by
`mark_unused` under the JSON's ``suppressions.unused`` and shown as a warning in the terminal, the
Markdown summary and the GitHub annotations; it does not change the exit code (one file often
serves several jobs, each analysing a part of the logs).
"""

from __future__ import annotations

import fnmatch
import math
import os
import tomllib
from dataclasses import dataclass
from datetime import date
from typing import NamedTuple

from logscan.errors import InputError
from logscan.input_files import MAX_SUPPRESSIONS_BYTES, read_input_text
from logscan.verdict.incidents import DEFAULT_GAP_S, alarm_onsets, find_incidents, inputs_of, sizes_of

KEYS = {"detector", "check", "log", "start", "end", "reason", "expires"}


@dataclass(frozen=True)
class Suppression:
    detector: str
    reason: str
    check: str | None = None
    log: str | None = None
    start: float = -math.inf
    end: float = math.inf
    expires: date | None = None

    def matches(self, log_path: str, alarm) -> bool:
        if alarm.detector != self.detector or (self.check is not None and alarm.signal != self.check):
            return False
        if self.log is not None:
            name = os.path.basename(str(log_path))
            if not (fnmatch.fnmatch(name, self.log) or fnmatch.fnmatch(str(log_path), self.log)):
                return False
        return self.start <= float(alarm.start) and float(alarm.end) <= self.end


def read_suppressions(path: str, today: date | None = None) -> list[Suppression]:
    """The entries of a suppressions file; InputError (exit 2) naming the entry that is wrong."""
    text = read_input_text(path, what="the suppressions file", limit=MAX_SUPPRESSIONS_BYTES)
    try:
        data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError, ValueError) as exc:
        first = (str(exc).splitlines() or [type(exc).__name__])[0]
        raise InputError(f"cannot read the suppressions: {first}", path=path) from None
    entries = data.get("suppress")
    if not isinstance(entries, list) or set(data) - {"suppress"}:
        raise InputError("a suppressions file holds [[suppress]] entries only", path=path)
    today = today or date.today()
    out = []
    for number, entry in enumerate(entries, 1):
        where = f"[[suppress]] entry {number}"
        unknown = sorted(set(entry) - KEYS)
        if unknown:
            raise InputError(f"{where}: unknown key(s) {', '.join(unknown)}", path=path, hint=f"keys: {sorted(KEYS)}")
        reason = entry.get("reason")
        if not isinstance(reason, str) or not reason.strip():
            raise InputError(f"{where} has no reason", path=path, hint='say why it is accepted: reason = "..."')
        if not isinstance(entry.get("detector"), str):
            raise InputError(f"{where} names no detector", path=path, hint='detector = "nis"')
        expires = entry.get("expires")
        if expires is not None and not isinstance(expires, date):
            raise InputError(f"{where}: expires must be a TOML date (2027-01-31)", path=path)
        if expires is not None and expires < today:
            raise InputError(
                f"{where} expired on {expires.isoformat()} ({reason.strip()})",
                path=path,
                hint="review the alarm it silenced: remove the entry or give it a new date",
            )
        try:
            start, end = float(entry.get("start", -math.inf)), float(entry.get("end", math.inf))
        except (TypeError, ValueError):
            raise InputError(f"{where}: start and end must be numbers of seconds", path=path) from None
        out.append(Suppression(entry["detector"], reason.strip(), entry.get("check"), entry.get("log"), start, end))
    return out


def apply_suppressions(analysis, rules: list[Suppression]) -> int:
    """Move the alarms ``rules`` match out of ``analysis``'s results into ``result.suppressed``
    (with their reason), then redo its incidents; returns how many were suppressed. Its scores
    against ground truth are the pipeline's to redo (`logscan.pipeline.rescore`: `logscan.tasks`)."""
    count = 0
    for result in analysis.results:
        kept = []
        for alarm in result.alarms:
            rule = next((r for r in rules if r.matches(analysis.path, alarm)), None)
            if rule is None:
                kept.append(alarm)
            else:
                result.suppressed.append((alarm, rule.reason))
                count += 1
        result.alarms = kept
    if count:
        prepared = analysis.prepared
        policy = prepared.profile.alarm_policy
        gap_s = policy.merge_gap_s if policy is not None else DEFAULT_GAP_S
        groups = prepared.trace.group_names if prepared.trace is not None else list(prepared.run.groups)
        onsets = alarm_onsets(analysis.results, prepared.run.t, analysis.suspended)
        analysis.incidents = find_incidents(
            analysis.results,
            prepared.trace,
            groups,
            gap_s,
            sizes_of(prepared),
            onsets,
            analysis.input_gaps,
            inputs_of(prepared),
            analysis.kinematic,
        )
    return count


class _Alarm(NamedTuple):
    """An alarm of the JSON summary, as `Suppression.matches` reads it."""

    detector: str
    signal: str
    start: float
    end: float


def _entry(number: int, rule: Suppression) -> dict:
    span = (("start", rule.start), ("end", rule.end))
    bounded = {key: value if math.isfinite(value) else None for key, value in span}
    return {"entry": number, "detector": rule.detector, "check": rule.check, "log": rule.log, **bounded,
            "reason": rule.reason}  # fmt: skip


def mark_unused(document: dict, rules: list[Suppression], path: str) -> list[dict]:
    """List under ``document["suppressions"]`` (the file and its ``unused`` entries) the entries of
    ``rules`` that suppressed no alarm of the run: an alarm is suppressed by the first entry that
    matches it (`apply_suppressions`), so an entry whose alarms an earlier one took is unused too.
    Entries are numbered from 1 in the file's order. Returns the unused entries."""
    used = set()
    for log in document.get("logs", []):
        for alarm in log.get("suppressed", []):
            view = _Alarm(str(alarm.get("detector", "")), str(alarm.get("signal", "")), alarm["start"], alarm["end"])
            number = next((n for n, rule in enumerate(rules) if rule.matches(log["file"], view)), None)
            if number is not None:
                used.add(number)
    unused = [_entry(n + 1, rule) for n, rule in enumerate(rules) if n not in used]
    document["suppressions"] = {"file": path, "unused": unused}
    return unused
