"""docs/reading-the-report.md describes parts the report has: each part the page names is in the
report of sample_logs/quad_imu_bias.mcap (by its element id or text)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOC = (ROOT / "docs" / "reading-the-report.md").read_text(encoding="utf-8")

# what the page describes -> what the report must contain for it
PARTS = {
    "## Verdict": 'id="verdict"',
    "on accel ax for 11.3 s, 30.00-41.27 s (nis.accel, peak 10.7x)": "on accel ax for 11.3 s, 30.00-41.27 s",
    "**headline sensor figure**": 'id="fig-headline"',
    "behind the toggle": 'id="margin-more"',
    "## Incidents and alarms": 'id="incident-table"',
    "alarm table": 'id="alarm-table"',
    "**ground truth** table": 'id="truth-table"',
    "## Margins": 'id="margin-table"',
    "what the detector can and cannot see": "What it can and cannot see",
    '"reset zoom"': "reset zoom",
    "Shaded red: alarm intervals; shaded blue: ground-truth faults": "Shaded red: alarm intervals",
    "**measurement groups used**": "Measurement groups used",
    "**mean NIS per update**": "mean NIS per update",
    "`accel: /imu/accel.x measured vs predicted`": "; accel: /imu/accel.x measured vs predicted;",
    "normalised innovation": "; accel: normalised innovation per channel;",
    "**one figure**": 'class="figure ls-timeseries ls-section"',
    "one vertical line across every row": '"spikemode":"across"',
    "## Context": 'id="context"',
    "`[mode]` channel": 'data-row-ids="ctx-mode',
    "the path is\ndrawn from above": 'aria-label="path: position"',
    "## Log, profile and model": 'id="log-facts"',
    "## Times: the log's own clock": "times: time since log start (s)",
    "(`clock`)": 'id="log-clock"',
    "what its statistics mean in plain words": 'class="statistics"',
}


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> str:
    out = tmp_path_factory.mktemp("report") / "bias.html"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, "-m", "logscan", "analyze", str(ROOT / "sample_logs" / "quad_imu_bias.mcap"), "-o", str(out)],
        env=env,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 1, done.stderr
    return out.read_text(encoding="utf-8")


@pytest.mark.parametrize("described", list(PARTS))
def test_described_part_is_in_the_report(described, report):
    assert described in DOC, f"docs/reading-the-report.md no longer says {described!r}: update PARTS"
    assert PARTS[described] in report, f"the report has no {PARTS[described]!r}, which the page describes"
