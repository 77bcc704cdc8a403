"""CI artifacts of `logscan analyze`, made from its JSON document (the `--json` summary of every log):

- JUnit XML (`--junit`): one testsuite per log, one testcase per detector and statistic (a failure
  when it alarmed: the alarms with times and peak/threshold), an error testcase for a detector that
  failed, a log that could not be fully checked, or a log that could not be read;
- Markdown (`--markdown`): a verdict table and an alarm table for a CI job's summary page, linking
  the reports;
- GitHub Actions annotations (`--github-annotations`): one `::error` line per alarm, one
  `::warning` line per possible fault or unchecked part, in the workflow-command format.

Only the JSON document is read, so every artifact agrees with `--json`.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from datetime import UTC, datetime

from logscan.report.overview import is_rejected, rejected_words

MAX_MARKDOWN_ROWS = 200


def _peak(alarm: dict) -> str:
    """peak/threshold, or the plain words of an alarm whose ratio means nothing (refused samples)."""
    if is_rejected(str(alarm.get("signal", ""))):
        return rejected_words(int(alarm.get("n_exceed", 0)))
    ratio = alarm.get("peak_ratio")
    return f"peak/threshold {ratio:.3g}" if isinstance(ratio, (int, float)) else ""


def _alarm_line(alarm: dict) -> str:
    peak = _peak(alarm)
    status = f" [{alarm['baseline']}]" if alarm.get("baseline") else ""  # --baseline: new / unchanged
    where = f"{alarm.get('signal', '')} {alarm['start']:.2f}-{alarm['end']:.2f} s"
    return where + (f", {peak}" if peak else "") + status


def _name(path: str) -> str:
    return os.path.basename(str(path).rstrip("/")) or str(path)


def junit_xml(document: dict) -> str:
    """The JUnit XML of an analyze run (``<testsuites>``; see the module docstring)."""
    stamp = datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%S")
    suites = ET.Element("testsuites", name="logscan analyze")
    totals = {"tests": 0, "failures": 0, "errors": 0}
    for index, log in enumerate(document.get("logs", [])):
        suite = ET.SubElement(suites, "testsuite", name=str(log["file"]), id=str(index), timestamp=stamp)
        cases = []
        for result in log.get("detectors", []):
            detector = result["detector"]
            alarms_by_signal: dict[str, list] = {}
            for alarm in result.get("alarms", []):
                alarms_by_signal.setdefault(alarm.get("signal", ""), []).append(alarm)
            for signal in result.get("series", {}):
                alarms = alarms_by_signal.get(signal, [])
                case = {"name": f"{detector}: {signal}", "failure": None, "error": None}
                if alarms:
                    case["failure"] = (
                        f"{len(alarms)} alarm(s) on {signal}",
                        "\n".join(_alarm_line(a) for a in alarms),
                    )
                cases.append(case)
        for suppressed in log.get("suppressed", []):
            cases.append({
                "name": f"{suppressed.get('detector', '')}: {suppressed.get('signal', '')} (suppressed)",
                "failure": None, "error": None,
                "skipped": f"{_alarm_line(suppressed)}: {suppressed.get('reason', '')}",
            })  # fmt: skip
        for failed in log.get("failed_detectors", []):
            cases.append({"name": f"{failed['detector']}: ran", "failure": None, "error": ("failed", failed["error"])})
        if log.get("unchecked"):
            cases.append({
                "name": "log: fully checked", "failure": None,
                "error": ("not fully checked", "\n".join(str(u) for u in log["unchecked"])),
            })  # fmt: skip
        _cases(suite, cases, _name(log["file"]))
        possible = [p for r in log.get("detectors", []) for p in r.get("possible_faults", [])]
        if possible:
            out = ET.SubElement(suite, "system-out")
            out.text = "possible faults (warnings, not alarms):\n" + "\n".join(_alarm_line(p) for p in possible)
        for key in totals:
            totals[key] += int(suite.get(key, "0"))
    for index, error in enumerate(document.get("errors", []), start=len(document.get("logs", []))):
        suite = ET.SubElement(suites, "testsuite", name=str(error["file"]), id=str(index), timestamp=stamp)
        _cases(suite, [{"name": "log: read", "failure": None, "error": ("bad input", error["error"])}], "logscan")
        for key in totals:
            totals[key] += int(suite.get(key, "0"))
    for key, value in totals.items():
        suites.set(key, str(value))
    ET.indent(suites)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(suites, encoding="unicode") + "\n"


def _cases(suite: ET.Element, cases: list[dict], classname: str) -> None:
    failures = errors = skipped = 0
    for case in cases:
        element = ET.SubElement(suite, "testcase", name=case["name"], classname=classname, time="0")
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
    suite.set("time", "0")


def _cell(text: object) -> str:
    """A Markdown table cell: pipes escaped, one line."""
    return str(text).replace("|", "\\|").replace("\n", " ")


def markdown_summary(document: dict) -> str:
    """Verdict and alarm tables of an analyze run, for a CI job's summary page."""
    logs = document.get("logs", [])
    n_alarms = sum(log.get("n_alarms", 0) for log in logs)
    lines = [
        "## logscan analyze",
        "",
        f"{len(logs) + len(document.get('errors', []))} log(s), {n_alarms} alarm(s), exit code "
        f"{document.get('exit_code', '')}.",
        "",
        "| log | verdict | alarms | possible faults | exit | report |",
        "|---|---|---:|---:|---:|---|",
    ]
    for log in logs:
        report = log.get("report")
        link = f"[{_cell(_name(report))}]({_cell(report)})" if report else "-"
        lines.append(
            f"| {_cell(log['file'])} | {_cell(log['verdict'])} | {log.get('n_alarms', 0)} | "
            f"{log.get('n_possible', 0)} | {log.get('exit_code', '')} | {link} |"
        )
    for error in document.get("errors", []):
        lines.append(f"| {_cell(error['file'])} | error: {_cell(error['error'])} | - | - | {error['exit_code']} | - |")
    alarms = [(log, a) for log in logs for r in log.get("detectors", []) for a in r.get("alarms", [])]
    if alarms:
        lines += [
            "",
            "| log | detector | signal | start (s) | end (s) | peak | baseline |",
            "|---|---|---|---:|---:|---|---|",
        ]
        for log, alarm in alarms[:MAX_MARKDOWN_ROWS]:
            cells = [_name(log["file"]), alarm.get("detector", ""), alarm.get("signal", "")]
            lines.append(
                "| " + " | ".join(_cell(c) for c in cells) + f" | {alarm['start']:.2f} | {alarm['end']:.2f} | "
                f"{_cell(_peak(alarm) or '-')} | {_cell(alarm.get('baseline', '-'))} |"
            )
    gone = [(log, a) for log in logs for a in (log.get("baseline") or {}).get("gone", [])]
    if gone:
        lines += ["", f"{len(gone)} alarm(s) of the baseline gone:", ""]
        lines += [f"- {_cell(_name(log['file']))}: {_cell(_alarm_line(a))}" for log, a in gone[:MAX_MARKDOWN_ROWS]]
        if len(alarms) > MAX_MARKDOWN_ROWS:
            lines.append(f"\n... {len(alarms) - MAX_MARKDOWN_ROWS} more alarm(s) in the JSON summary")
    suppressed = [(log, a) for log in logs for a in log.get("suppressed", [])]
    if suppressed:
        lines += ["", f"{len(suppressed)} alarm(s) suppressed:", ""]
        lines += [f"- {_cell(_name(log['file']))}: {_cell(_alarm_line(a))} ({_cell(a.get('reason', ''))})"
                  for log, a in suppressed[:MAX_MARKDOWN_ROWS]]  # fmt: skip
    return "\n".join(lines) + "\n"


def _escape_data(text: str) -> str:
    """A workflow command's message: %, CR and LF escaped (GitHub Actions' format)."""
    return text.replace("%", "%25").replace("\r", "%0D").replace("\n", "%0A")


def _escape_property(text: str) -> str:
    """A workflow command's property value: as data, plus ':' and ','."""
    return _escape_data(text).replace(":", "%3A").replace(",", "%2C")


def github_annotations(document: dict) -> list[str]:
    """``::error`` per alarm and per log that could not be read, ``::warning`` per possible fault
    and per part of a log that could not be checked."""
    lines = []
    for log in document.get("logs", []):
        where = f"file={_escape_property(str(log['file']))}"
        for result in log.get("detectors", []):
            for alarm in result.get("alarms", []):
                detector = alarm.get("detector") or result.get("detector", "")
                title = _escape_property(f"logscan {detector} {alarm.get('signal', '')}")
                lines.append(f"::error {where},title={title}::{_escape_data(_alarm_line(alarm))}")
            for possible in result.get("possible_faults", []):
                title = _escape_property(f"logscan possible fault {possible.get('signal', '')}")
                lines.append(f"::warning {where},title={title}::{_escape_data(_alarm_line(possible))}")
        for unchecked in log.get("unchecked", []):
            lines.append(f"::warning {where},title=logscan not fully checked::{_escape_data(str(unchecked))}")
    for error in document.get("errors", []):
        where = f"file={_escape_property(str(error['file']))}"
        lines.append(f"::error {where},title=logscan could not analyse the log::{_escape_data(str(error['error']))}")
    return lines
