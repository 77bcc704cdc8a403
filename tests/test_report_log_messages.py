"""The autopilot's logged messages in the report: every level in a folded table, and as markers on
the mode figure's time axis."""

from __future__ import annotations

import json
import re
from types import SimpleNamespace

import numpy as np
from test_report import HOSTILE, figures, make_report
from test_run_context import quad_run, sample_context

from logscan.log import Channel
from logscan.models import get_model
from logscan.report import render_html
from logscan.report.context_figures import mode_figure
from logscan.report.run_context import run_context
from logscan.timebase.clock import Clock

START_NS = 5_000_000_000
LINES = {
    "00000": "5.500000 s [INFO] Takeoff detected",
    "00001": "6.000000 s [WARNING] Compass needs calibration",
    "00002": f"7.250000 s [DEBUG] {HOSTILE}",
    "00003": "not a message line",
}


def _log(lines: dict = LINES, count: str = "4"):
    metadata = {"ulog.messages": lines, "ulog.log": {"logged_messages": count}}
    return SimpleNamespace(source=SimpleNamespace(metadata=metadata), channels={})


def test_the_context_keeps_every_level_and_the_warnings_apart():
    run = quad_run(2_000)
    run.start_ns = START_NS
    context = run_context(run, get_model("quadcopter", {}), _log(count="900"))
    found = [(m.level, round(m.t, 3)) for m in context.log_messages]
    assert found == [("INFO", 0.5), ("WARNING", 1.0), ("DEBUG", 2.25)]
    assert [m.level for m in context.messages] == ["WARNING"]  # the verdict's list: warnings and above
    assert context.n_log_messages == 900  # the log's own count, beyond the 500 the reader kept


def _report_with_messages():
    report = make_report(6_000, truth=False)
    report.context = sample_context(6_000)
    run = quad_run(200)
    run.start_ns = START_NS
    report.context.log_messages = run_context(run, get_model("quadcopter", {}), _log()).log_messages
    report.context.n_log_messages = 3
    return report


def test_the_report_folds_a_table_of_every_logged_message_escaped():
    page = render_html(_report_with_messages())
    block = re.search(r'<details id="log-messages">(.*?)</details>', page, re.S)
    assert block, "the folded message table is missing"
    assert "the 3 messages the autopilot logged (every level)" in block.group(1)
    rows = re.findall(r'<tr class="log-(\w+)" data-start="([^"]+)"[^>]*><td class="num">([^<]+)</td>', block.group(1))
    assert [(level, float(t0)) for level, t0, _ in rows] == [("info", 0.5), ("warning", 1.0), ("debug", 2.25)]
    assert HOSTILE not in page and "&lt;script&gt;alert(1)&lt;/script&gt;" in block.group(1)


def test_the_mode_figure_marks_each_logged_message_on_its_time_axis():
    report = _report_with_messages()
    spec = json.loads(mode_figure(report.context.mode, Clock(), report.context.log_messages)["json"])
    marks = next(trace for trace in spec["data"] if trace["name"] == "logged messages")
    assert marks["yaxis"] == "y2" and len(marks["text"]) == 3
    assert marks["text"][0] == "info: Takeoff detected" and marks["text"][1].startswith("warning: Compass")
    page = figures(render_html(report))
    mode = next(s["figure"] for s in page if s["id"] == "ctx-time")  # the Context section's one figure
    assert any(trace["name"] == "logged messages" for trace in mode["data"])


def test_a_warning_row_zooms_in_the_time_axis_units_on_a_utc_clock():
    from logscan.verdict.autopilot_messages import AutopilotMessage

    report = _report_with_messages()
    report.clock = Clock("UTC", 1_700_000_000.0, utc=True, utc_zero_s=1_700_000_000.0)
    report.messages = [AutopilotMessage("WARNING", "Compass needs calibration", 1.0, 2.0)]
    table = render_html(report).split('id="autopilot-messages"', 1)[1]
    start, end = re.search(r'<tr data-start="([^"]+)" data-end="([^"]+)"', table).groups()
    assert (float(start), float(end)) == (1_700_000_001_000.0, 1_700_000_002_000.0)  # epoch ms, as the axis


def test_colour_codes_are_dropped_and_other_control_characters_shown_as_escapes():
    from logscan.report.context import message_text

    assert message_text("[commander] \x1b[32mReady for takeoff!\x1b[0m") == "[commander] Ready for takeoff!"
    assert message_text("a\x1b[2Jb\u202ec") == "a\\x1b[2Jb\\u202ec"


def test_a_window_s_context_keeps_only_its_own_messages_and_states_and_says_so():
    # a --start/--end window from 0.8 s to 1.8 s: its grid, one step beyond its last the span's end
    run = quad_run(100, mode=np.zeros(100))
    run.t, run.start_ns, run.window = run.t + 0.8, START_NS, (0.8, 1.8)
    t_ns = START_NS + np.array([0, 1, 2]) * 10**9
    status = Channel("/vehicle_status_0/arming_state", t_ns, np.array([2.0, 1.0, 2.0]))
    log = _log()
    log.channels = {"/vehicle_status_0/arming_state": status}  # armed 0-1 s and from 2 s
    context = run_context(run, get_model("quadcopter", {}), log)
    assert context.window == (0.8, 1.8)
    assert [(m.level, round(m.t, 3)) for m in context.log_messages] == [("WARNING", 1.0)]
    assert [m.text for m in context.messages] == ["Compass needs calibration"]
    assert (context.n_log_messages, context.n_outside) == (1, 3)  # the log counts 4
    assert context.states["armed"] == [(0.8, 1.0)]  # the intervals cut to the window
    report = make_report(6_000, truth=False)
    report.context = context
    page = render_html(report)
    block = re.search(r'<details id="log-messages"><summary>(.*?)</summary>', page, re.S)
    assert block and block.group(1) == (
        "the 1 message the autopilot logged in the --start/--end window (every level); 3 outside it, not listed"
    )
    assert "the 1 message(s) the autopilot logged in the --start/--end window" in page  # the mode row's caption
    assert "1 message(s) of level warning and above the autopilot logged in the --start/--end window" in page
