"""The fleet index page: `logscan analyze DIR -o reports/` also writes `reports/index.html`.

One row per log (verdict, alarms per detector, possible faults, duration, model, its report) and
one per log that could not be analysed (its one-line reason), from the run's `--json` document;
sortable by clicking a column header and filtered by a text box, in plain JavaScript (no plotly:
the page has no figures). Links are relative, so the folder can be moved or downloaded as an
artifact whole.
"""

from __future__ import annotations

import os
from pathlib import Path

from logscan.report.page_assets import environment

INDEX_NAME = "index.html"


def index_path(reports: list[str | None]) -> str | None:
    """Where the index goes: the folder of several reports (None for one log or no reports)."""
    folders = {str(Path(r).parent) for r in reports if r}
    if len(reports) < 2 or len(folders) != 1:
        return None
    return str(Path(folders.pop()) / INDEX_NAME)


def render_index_html(document: dict, index: str) -> str:
    """The index page of an analyze run's document, with links relative to ``index``."""
    base = Path(index).parent
    detectors = sorted({r["detector"] for log in document.get("logs", []) for r in log.get("detectors", [])})
    rows = []
    for log in document.get("logs", []):
        counts = {r["detector"]: r.get("n_alarms", 0) for r in log.get("detectors", [])}
        report = log.get("report")
        rows.append({
            "file": log["file"],
            "name": os.path.basename(str(log["file"]).rstrip("/")),
            "verdict": log["verdict"],
            "status": "alarm" if log.get("n_alarms") else ("partial" if log.get("exit_code") == 2 else "ok"),
            "exit_code": log.get("exit_code", ""),
            "counts": [counts.get(d, "") for d in detectors],
            "n_alarms": log.get("n_alarms", 0),
            "n_possible": log.get("n_possible", 0),
            "duration": f"{log.get('log', {}).get('duration_s', 0.0):.1f}",
            "model": log.get("model", ""),
            "link": os.path.relpath(report, base) if report else None,
        })  # fmt: skip
    failed = [
        {"file": e["file"], "name": os.path.basename(str(e["file"]).rstrip("/")), "error": e["error"],
         "exit_code": e.get("exit_code", 2)}
        for e in document.get("errors", [])
    ]  # fmt: skip
    return (
        environment()
        .get_template("index.html.j2")
        .render(
            title=f"logscan: {len(rows) + len(failed)} logs",
            detectors=detectors,
            rows=rows,
            failed=failed,
            exit_code=document.get("exit_code", ""),
            version=document.get("logscan_version", ""),
        )
    )
