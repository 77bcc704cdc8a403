"""CI artifacts of `logscan analyze`, made from its JSON document (the `--json` summary of every log):

- JUnit XML (`--junit`): one testsuite per log, one testcase per detector and statistic (a failure
  when it alarmed: the alarms with times and peak/threshold), an error testcase for a detector that
  failed, a log that could not be fully checked, or a log that could not be read; a skipped
  testcase for a log of the `--baseline` not analysed in this run. Each testsuite's ``time`` is the
  log's analysis time, shared equally by its testcases (the detectors run on one filter pass);
- Markdown (`--markdown`): a verdict table and an alarm table (with the incident each alarm
  belongs to) for a CI job's summary page, linking the reports relative to the Markdown file's
  folder; the suppression entries that matched nothing and the baseline's logs not analysed;
- GitHub Actions annotations (`--github-annotations`, `logscan.report.ci_annotations`).

Only the JSON document is read (and the analysis times, which the JSON leaves out so that it
stays the same from run to run), so every artifact agrees with `--json`.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from datetime import UTC, datetime
from urllib.parse import quote

from logscan.artifacts import check_target
from logscan.report.overview import is_rejected, rejected_words
from logscan.timebase.clock import Clock

MAX_MARKDOWN_ROWS = 200
NOT_ANALYSED = "in the --baseline summary, not analysed in this run"


def _peak(alarm: dict) -> str:
    """peak/threshold, or the plain words of an alarm whose ratio means nothing (refused samples)."""
    if is_rejected(str(alarm.get("signal", ""))):
        return rejected_words(int(alarm.get("n_exceed", 0)))
    ratio = alarm.get("peak_ratio")
    return f"peak/threshold {ratio:.3g}" if isinstance(ratio, (int, float)) else ""


def alarm_line(alarm: dict, clock: Clock | None = None) -> str:
    """``<statistic> <start>-<end> s, peak/threshold <r> [<baseline status>]``, the times in the log's
    ``clock`` (`log_clock`) as the terminal and the report show them."""
    peak = _peak(alarm)
    status = f" [{alarm['baseline']}]" if alarm.get("baseline") else ""  # --baseline: new / unchanged
    where = f"{alarm.get('signal', '')} {(clock or Clock()).span_text(alarm['start'], alarm['end'])}"
    return where + (f", {peak}" if peak else "") + status


def log_clock(log: dict) -> Clock:
    """A summary's log's own clock (PX4 boot time, UTC, or time since its start)."""
    return Clock.from_dict(log.get("clock"))


def _clock_cell(clock: Clock, t: float) -> str:
    """A time in a table cell: "5.27 s" (the log's clock's seconds) or "14:49:36.370 UTC"."""
    return f"{clock.short(t)} UTC" if clock.utc else clock.text(t)


def log_name(path: str) -> str:
    """A log's file name (a directory log's folder name)."""
    return os.path.basename(str(path).rstrip("/")) or str(path)


def incident_of(log: dict, alarm: dict, detector: str = "") -> int | None:
    """The number (from 1, as the summary and the report count them) of the incident of ``log``
    that holds ``alarm``: the first one listing its check whose span covers it; None if none does."""
    check = f"{alarm.get('detector') or detector}:{alarm.get('signal', '')}"
    for number, incident in enumerate(log.get("incidents", []), start=1):
        inside = incident["start"] - 1e-6 <= alarm["start"] and alarm["end"] <= incident["end"] + 1e-6
        if check in incident.get("checks", []) and inside:
            return number
    return None


def not_analysed(document: dict) -> list[str]:
    """The logs of the `--baseline` summary that this run did not analyse (`compare` lists them)."""
    return list((document.get("baseline") or {}).get("not_analysed", []))


def unused_suppressions(document: dict) -> list[dict]:
    """The `--suppressions` entries that matched no alarm of the run (`logscan.verdict.suppressions`)."""
    return list((document.get("suppressions") or {}).get("unused", []))


def unused_line(entry: dict) -> str:
    """One unused suppression entry in words: which entry, what it names, its reason."""
    names = [f"detector {entry['detector']}"]
    names += [f"{key} {entry[key]}" for key in ("check", "log") if entry.get(key) is not None]
    span = (entry.get("start"), entry.get("end"))
    if span != (None, None):
        names.append(f"{_seconds(span[0], '-inf')}-{_seconds(span[1], 'inf')} s")
    return f"[[suppress]] entry {entry['entry']} ({', '.join(names)}) matched no alarm; reason: {entry['reason']}"


def _seconds(value: float | None, unbounded: str) -> str:
    return unbounded if value is None else f"{value:g}"


# --- JUnit XML --------------------------------------------------------------------------------


def junit_xml(document: dict, times: Sequence[float] | None = None) -> str:
    """The JUnit XML of an analyze run (``<testsuites>``; see the module docstring). ``times``:
    each analysed log's analysis time in seconds, in the order of ``document["logs"]``."""
    stamp = datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%S")
    suites = ET.Element("testsuites", name="logscan analyze")
    totals = {"tests": 0, "failures": 0, "errors": 0}  # the schema's <testsuites> has no "skipped"
    logs = document.get("logs", [])
    runs: list[tuple[str, list[dict], str, float]] = []
    for index, log in enumerate(logs):
        seconds = float(times[index]) if times is not None and index < len(times) else 0.0
        runs.append((str(log["file"]), _log_cases(log), log_name(log["file"]), seconds))
    for error in document.get("errors", []):
        case = {"name": "log: read", "failure": None, "error": ("bad input", error["error"])}
        runs.append((str(error["file"]), [case], "logscan", 0.0))
    for missing in not_analysed(document):
        case = {"name": "log: analysed", "failure": None, "error": None, "skipped": NOT_ANALYSED}
        runs.append((str(missing), [case], "logscan", 0.0))
    total_s = 0.0
    for index, (name, cases, classname, seconds) in enumerate(runs):
        suite = ET.SubElement(suites, "testsuite", name=name, id=str(index), timestamp=stamp)
        _cases(suite, cases, classname, seconds)
        if index < len(logs):
            _possible_faults(suite, logs[index])
        for key in totals:
            totals[key] += int(suite.get(key, "0"))
        total_s += seconds
    for key, value in totals.items():
        suites.set(key, str(value))
    suites.set("time", _time(total_s))
    ET.indent(suites)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(suites, encoding="unicode") + "\n"


def _log_cases(log: dict) -> list[dict]:
    """One analysed log's testcases: a statistic each, its suppressed alarms, failed detectors and
    what could not be checked."""
    cases = []
    clock = log_clock(log)
    for result in log.get("detectors", []):
        detector = result["detector"]
        alarms_by_signal: dict[str, list] = {}
        for alarm in result.get("alarms", []):
            alarms_by_signal.setdefault(alarm.get("signal", ""), []).append(alarm)
        for signal in result.get("series", {}):
            alarms = alarms_by_signal.get(signal, [])
            case = {"name": f"{detector}: {signal}", "failure": None, "error": None}
            if alarms:
                lines = "\n".join(alarm_line(a, clock) for a in alarms)
                case["failure"] = (f"{len(alarms)} alarm(s) on {signal}", lines)
            cases.append(case)
    for suppressed in log.get("suppressed", []):
        cases.append({
            "name": f"{suppressed.get('detector', '')}: {suppressed.get('signal', '')} (suppressed)",
            "failure": None, "error": None,
            "skipped": f"{alarm_line(suppressed, clock)}: {suppressed.get('reason', '')}",
        })  # fmt: skip
    for failed in log.get("failed_detectors", []):
        cases.append({"name": f"{failed['detector']}: ran", "failure": None, "error": ("failed", failed["error"])})
    if log.get("unchecked"):
        cases.append({
            "name": "log: fully checked", "failure": None,
            "error": ("not fully checked", "\n".join(str(u) for u in log["unchecked"])),
        })  # fmt: skip
    return cases


def _possible_faults(suite: ET.Element, log: dict) -> None:
    possible = [p for r in log.get("detectors", []) for p in r.get("possible_faults", [])]
    if possible:
        out = ET.SubElement(suite, "system-out")
        clock = log_clock(log)
        out.text = "possible faults (warnings, not alarms):\n" + "\n".join(alarm_line(p, clock) for p in possible)


def _time(seconds: float) -> str:
    """An xs:decimal of seconds (never an exponent)."""
    return f"{max(seconds, 0.0):.3f}"


def _cases(suite: ET.Element, cases: list[dict], classname: str, seconds: float) -> None:
    failures = errors = skipped = 0
    each = _time(seconds / len(cases)) if cases else "0"
    for case in cases:
        element = ET.SubElement(suite, "testcase", name=case["name"], classname=classname, time=each)
        if case["failure"] is not None:
            message, text = case["failure"]
            ET.SubElement(element, "failure", message=message, type="alarm").text = text
            failures += 1
        if case["error"] is not None:
            message, text = case["error"]
            ET.SubElement(element, "error", message=message, type="logscan").text = text
            errors += 1
        if case.get("skipped"):
            ET.SubElement(element, "skipped", message=case["skipped"])
            skipped += 1
    suite.set("tests", str(len(cases)))
    suite.set("failures", str(failures))
    suite.set("errors", str(errors))
    suite.set("skipped", str(skipped))
    suite.set("time", _time(seconds))


# --- Markdown ---------------------------------------------------------------------------------


def _cell(text: object) -> str:
    """A Markdown table cell: pipes escaped, one line."""
    return str(text).replace("|", "\\|").replace("\n", " ")


def link_base(markdown_path: str | None) -> str:
    """The folder the Markdown's links are relative to: the file's own (a link is followed from
    where the file is), or the working directory for stdout, a FIFO or a device."""
    if markdown_path is None or markdown_path == "-" or check_target(markdown_path):
        return os.getcwd()
    return os.path.dirname(os.path.abspath(markdown_path))


def _link(report: str | None, base: str) -> str:
    if not report:
        return "-"
    target = os.path.relpath(os.path.abspath(report), base).replace(os.sep, "/")
    return f"[{_cell(log_name(report))}]({quote(target)})"


def markdown_summary(document: dict, markdown_path: str | None = None) -> str:
    """Verdict and alarm tables of an analyze run, for a CI job's summary page written to
    ``markdown_path`` (the report links are relative to its folder)."""
    logs = document.get("logs", [])
    n_alarms = sum(log.get("n_alarms", 0) for log in logs)
    n_incidents = sum(log.get("n_incidents", 0) for log in logs)
    lines = [
        "## logscan analyze",
        "",
        f"{len(logs) + len(document.get('errors', []))} log(s), {n_incidents} incident(s), {n_alarms} alarm(s), "
        f"exit code {document.get('exit_code', '')}.",
        "",
        "| log | verdict | incidents | alarms | possible faults | exit | report |",
        "|---|---|---:|---:|---:|---:|---|",
    ]
    base = link_base(markdown_path)
    for log in logs:
        lines.append(
            f"| {_cell(log['file'])} | {_cell(log['verdict'])} | {log.get('n_incidents', 0)} | "
            f"{log.get('n_alarms', 0)} | {log.get('n_possible', 0)} | {log.get('exit_code', '')} | "
            f"{_link(log.get('report'), base)} |"
        )
    for error in document.get("errors", []):
        lines.append(
            f"| {_cell(error['file'])} | error: {_cell(error['error'])} | - | - | - | {error['exit_code']} | - |"
        )
    lines += _times_lines(logs) + _alarm_table(logs) + _lists(document)
    return "\n".join(lines) + "\n"


def _times_lines(logs: list[dict]) -> list[str]:
    """What the alarm and suppressed times count, named once as the terminal's ``times:`` line
    does: a boot-time cell "6.38 s" says no clock by itself (a UTC cell does)."""
    timed = [log for log in logs if log.get("suppressed") or any(r.get("alarms") for r in log.get("detectors", []))]
    described = {log_name(log["file"]): log_clock(log).describe() for log in timed}
    if not described:
        return []
    if len(set(described.values())) == 1:
        return ["", f"Times: {next(iter(described.values()))}."]
    return ["", "Times, in each log's own clock:", ""] + [
        f"- {_cell(name)}: {_cell(text)}" for name, text in described.items()
    ]


def _alarm_table(logs: list[dict]) -> list[str]:
    alarms = [(log, r, a) for log in logs for r in log.get("detectors", []) for a in r.get("alarms", [])]
    if not alarms:
        return []
    lines = [
        "",
        "| log | incident | detector | signal | start | end | peak | baseline |",
        "|---|---:|---|---|---:|---:|---|---|",
    ]
    for log, result, alarm in alarms[:MAX_MARKDOWN_ROWS]:
        incident = incident_of(log, alarm, result.get("detector", ""))
        cells = [log_name(log["file"]), incident or "-", alarm.get("detector", ""), alarm.get("signal", "")]
        clock = log_clock(log)
        cells += [_clock_cell(clock, alarm["start"]), _clock_cell(clock, alarm["end"]), _peak(alarm) or "-"]
        lines.append("| " + " | ".join(_cell(c) for c in cells) + f" | {_cell(alarm.get('baseline', '-'))} |")
    if len(alarms) > MAX_MARKDOWN_ROWS:
        lines.append(f"\n... {len(alarms) - MAX_MARKDOWN_ROWS} more alarm(s) in the JSON summary")
    return lines


def _lists(document: dict) -> list[str]:
    """The baseline's gone alarms and logs not analysed, the suppressed alarms, the unused
    suppression entries: one bulleted list each."""
    logs = document.get("logs", [])
    lines: list[str] = []
    gone = [(log, a) for log in logs for a in (log.get("baseline") or {}).get("gone", [])]
    # the baseline's alarms: in seconds since its log's start (its clock is the baseline run's)
    gone_lines = [f"{log_name(log['file'])}: {alarm_line(a)}" for log, a in gone]
    missing = not_analysed(document)
    suppressed = [(log, a) for log in logs for a in log.get("suppressed", [])]
    suppressed_lines = [
        f"{log_name(log['file'])}: {alarm_line(a, log_clock(log))} ({a.get('reason', '')})" for log, a in suppressed
    ]
    unused = [unused_line(entry) for entry in unused_suppressions(document)]
    for items, heading in (
        (gone_lines, f"{len(gone)} alarm(s) of the baseline gone:"),
        (missing, f"**Not analysed**: {len(missing)} log(s) of the baseline not analysed in this run:"),
        (suppressed_lines, f"{len(suppressed)} alarm(s) suppressed:"),
        (unused, f"**Warning**: {len(unused)} suppression entr{'y' if len(unused) == 1 else 'ies'} matched no alarm:"),
    ):
        if items:
            lines += ["", heading, ""] + [f"- {_cell(item)}" for item in items[:MAX_MARKDOWN_ROWS]]
            if len(items) > MAX_MARKDOWN_ROWS:
                lines.append(f"- ... {len(items) - MAX_MARKDOWN_ROWS} more")
    return lines
