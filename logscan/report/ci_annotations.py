"""GitHub Actions annotations of `logscan analyze` (`--github-annotations`), from its JSON document.

GitHub shows at most 10 error and 10 warning annotations of a step (50 per job) and drops the
rest, so a log gets one ``::error`` per incident (the alarms of one fault are one incident), at
most `MAX_PER_LOG`, then one ``::notice`` saying how many more there are and where to read them;
likewise for its ``::warning`` lines (possible faults, parts not checked). A log that could not be
read is one ``::error``; a suppression entry that matched nothing and a log of the `--baseline`
not analysed in this run are one ``::warning`` each. Messages and properties are escaped as
GitHub's toolkit does (``@actions/core``: ``escapeData`` and ``escapeProperty``).
"""

from __future__ import annotations

import os

from logscan.report.ci_artifacts import (
    alarm_line,
    incident_of,
    log_clock,
    log_name,
    not_analysed,
    unused_line,
    unused_suppressions,
)

MAX_PER_LOG = 10
MAX_CHECKS_NAMED = 5


def escape_data(text: str) -> str:
    """A workflow command's message: %, CR and LF escaped (``escapeData``)."""
    return text.replace("%", "%25").replace("\r", "%0D").replace("\n", "%0A")


def escape_property(text: str) -> str:
    """A workflow command's property value: as data, plus ':' and ',' (``escapeProperty``)."""
    return escape_data(text).replace(":", "%3A").replace(",", "%2C")


def _command(kind: str, message: str, file: str | None = None, title: str | None = None) -> str:
    properties = [f"{key}={escape_property(value)}" for key, value in (("file", file), ("title", title)) if value]
    return (
        f"::{kind} {','.join(properties)}::{escape_data(message)}"
        if properties
        else f"::{kind}::{escape_data(message)}"
    )


def _incident_message(log: dict, number: int, incident: dict) -> str:
    """The incident's headline, how many alarms on which checks, and how many are new (--baseline)."""
    checks = [c.split(":", 1)[-1] for c in incident.get("checks", [])]
    named = ", ".join(checks[:MAX_CHECKS_NAMED]) + (
        f" and {len(checks) - MAX_CHECKS_NAMED} more" if len(checks) > MAX_CHECKS_NAMED else ""
    )
    message = f"{incident['headline']}; {incident.get('n_alarms', 0)} alarm(s) on {named}"
    statuses = [
        alarm["baseline"]
        for result in log.get("detectors", [])
        for alarm in result.get("alarms", [])
        if alarm.get("baseline") and incident_of(log, alarm, result.get("detector", "")) == number
    ]
    if statuses:
        new = statuses.count("new")
        message += f" [{new} new]" if new else " [unchanged]"
    return message


def _log_annotations(log: dict, see: str) -> list[str]:
    """One log's errors (its incidents) and warnings, each kind capped at MAX_PER_LOG with a notice."""
    file = str(log["file"])
    incidents = log.get("incidents", [])
    errors = [
        _command("error", _incident_message(log, n, incident), file, f"logscan incident {n} of {len(incidents)}")
        for n, incident in enumerate(incidents, start=1)
    ]
    warnings = [
        _command(
            "warning",
            alarm_line(possible, log_clock(log)),
            file,
            f"logscan possible fault {possible.get('signal', '')}",
        )
        for result in log.get("detectors", [])
        for possible in result.get("possible_faults", [])
    ]
    warnings += [_command("warning", str(u), file, "logscan not fully checked") for u in log.get("unchecked", [])]
    lines = errors[:MAX_PER_LOG] + warnings[:MAX_PER_LOG]
    for items, what in ((errors, "incident"), (warnings, "warning")):
        if len(items) > MAX_PER_LOG:
            more = len(items) - MAX_PER_LOG
            message = f"{more} more {what}{'s' if more > 1 else ''} in {log_name(file)}: see {see}"
            lines.append(_command("notice", message, file, "logscan"))
    return lines


def summary_words(markdown_path: str | None, json_path: str | None) -> str | None:
    """Where a user reads what the capped annotations leave out, when a log has no report: the
    job's summary page when the Markdown goes to ``$GITHUB_STEP_SUMMARY``, else the Markdown or
    the JSON file (None: neither is written to a file)."""
    if markdown_path and markdown_path == os.environ.get("GITHUB_STEP_SUMMARY"):
        return "the job summary"
    return markdown_path or (json_path if json_path != "-" else None)


def github_annotations(document: dict, summary: str | None = None) -> list[str]:
    """The workflow commands of an analyze run (see the module docstring). ``summary``: the file
    a user reads for what the capped annotations leave out when a log has no report (the
    Markdown or JSON summary)."""
    lines = []
    for log in document.get("logs", []):
        lines += _log_annotations(log, log.get("report") or summary or "the job's log")
    for error in document.get("errors", []):
        lines.append(_command("error", str(error["error"]), str(error["file"]), "logscan could not analyse the log"))
    unused = unused_suppressions(document)
    suppressions_file = (document.get("suppressions") or {}).get("file")
    lines += [
        _command("warning", unused_line(entry), suppressions_file, "logscan unused suppression") for entry in unused
    ]
    for missing in not_analysed(document):
        lines.append(
            _command(
                "warning",
                "in the --baseline summary, not analysed in this run",
                str(missing),
                "logscan log not analysed",
            )
        )
    return lines
