"""Baselines: the alarms of an analyze run compared with a previous run's `--json` summary.

An alarm is "unchanged" when the previous summary has an alarm of the same log (by file name), the
same detector and the same statistic whose interval overlaps it, else "new"; a previous alarm no
current alarm overlaps that way is "gone". `logscan analyze --baseline previous.json --fail-on new`
fails only on new alarms, so a team can accept the known ones and still be told of any other.

A log the previous summary holds (analysed or not readable) that this run neither analysed nor
failed to read is "not analysed" (listed under the JSON's ``baseline.not_analysed``, a warning in
the terminal, Markdown and GitHub annotations, a skipped testcase in JUnit): its alarms are not
"gone", they were not looked for. It does not change the exit code: a job may analyse a part of
the logs on purpose; a log that disappeared by mistake is seen in every artifact.
"""

from __future__ import annotations

import json
import os
from typing import Any

from logscan.errors import InputError, where_in_text
from logscan.input_files import MAX_BASELINE_BYTES, read_input_text

STATUSES = ("new", "unchanged", "gone")


def read_baseline(path: str) -> dict[str, Any]:
    """A previous `--json` summary (InputError naming the file when it is not one)."""
    text = read_input_text(path, what="the baseline", limit=MAX_BASELINE_BYTES)
    try:
        document = json.loads(text)
    except (RecursionError, ValueError) as exc:
        raise InputError(
            f"not a logscan analyze summary: not JSON{where_in_text(exc)}",
            path=path,
            hint="pass a file written by `logscan analyze --json`",
        ) from None
    if not isinstance(document, dict) or not isinstance(document.get("logs"), list):
        raise InputError(
            "not a logscan analyze summary", path=path, hint="pass a file written by `logscan analyze --json`"
        )
    return document


def _key(log: dict) -> str:
    return os.path.basename(str(log.get("file", "")).rstrip("/"))


def _alarms(log: dict) -> list[dict]:
    return [a for result in log.get("detectors", []) for a in result.get("alarms", [])]


def _same(a: dict, b: dict) -> bool:
    """Same detector and statistic, overlapping intervals."""
    return (
        a.get("detector") == b.get("detector")
        and a.get("signal") == b.get("signal")
        and float(a["start"]) <= float(b["end"])
        and float(b["start"]) <= float(a["end"])
    )


def compare(document: dict, previous: dict) -> dict[str, int]:
    """Mark every alarm of ``document`` (in place) "new" or "unchanged" against ``previous``, list
    each log's "gone" alarms under ``baseline`` and return the counts over all logs. A log the
    baseline does not hold has only new alarms."""
    before = {_key(log): _alarms(log) for log in previous.get("logs", [])}
    totals = dict.fromkeys(STATUSES, 0)
    for log in document.get("logs", []):
        old = before.get(_key(log), [])
        current = _alarms(log)
        for alarm in current:
            alarm["baseline"] = "unchanged" if any(_same(alarm, o) for o in old) else "new"
            totals[alarm["baseline"]] += 1
        gone = [o for o in old if not any(_same(o, a) for a in current)]
        totals["gone"] += len(gone)
        log["baseline"] = {
            "new": sum(a["baseline"] == "new" for a in current),
            "unchanged": sum(a["baseline"] == "unchanged" for a in current),
            "gone": gone,
        }
    document["baseline"] = {**totals, "not_analysed": missing_logs(document, previous)}
    return totals


def missing_logs(document: dict, previous: dict) -> list[str]:
    """The logs of ``previous`` (by file name, as `compare` matches them) that ``document`` neither
    analysed nor failed to read, as ``previous`` names them, each once."""
    seen = {_key(entry) for entry in (*document.get("logs", []), *document.get("errors", []))}
    missing: dict[str, str] = {}
    for entry in (*previous.get("logs", []), *previous.get("errors", [])):
        if isinstance(entry, dict) and _key(entry) not in seen:
            missing.setdefault(_key(entry), str(entry.get("file", "")))
    return list(missing.values())


def exit_code_on_new(document: dict) -> int:
    """The run's exit code when only new alarms fail it: a log's 2 or 3 stands, its 1 only with a
    new alarm."""
    codes = [int(e.get("exit_code", 2)) for e in document.get("errors", [])]
    for log in document.get("logs", []):
        code = int(log.get("exit_code", 0))
        if code == 1 and not log.get("baseline", {}).get("new"):
            code = 0
        codes.append(code)
    return max(codes, default=0)
