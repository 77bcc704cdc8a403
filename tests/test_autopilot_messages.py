"""The autopilot's own warnings and errors during flight are listed beside the verdict, each with
the incident it falls in, identical ones folded with a count: on crafted messages, and on the real
robologs flight whose autopilot told its pilot "Dangerous battery level!, please land!"."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import need_testdata

from logscan.timebase.clock import Clock
from logscan.verdict.autopilot_messages import flight_messages

START_NS = 10_000_000_000  # the run's time zero: 10 s of the log's clock


def _metadata(*messages: tuple[float, str, str]) -> dict:
    """``ulog.messages`` as the ULog reader writes them: "<seconds> s [<LEVEL>] <text>"."""
    return {"ulog.messages": {f"{k:05d}": f"{t:.6f} s [{level}] {text}" for k, (t, level, text) in enumerate(messages)}}


def test_repeated_messages_are_folded_per_incident_and_disarmed_ones_counted():
    metadata = _metadata(
        (11.0, "WARNING", "[health_and_arming_checks] Preflight: GPS fix too low"),  # before arming
        (13.0, "ERROR", "[commander] Dangerous battery level!, please land!"),
        (14.0, "ERROR", "[commander] Dangerous battery level!, please land!"),
        (15.2, "ERROR", "[commander] Dangerous battery level!, please land!"),
        (20.5, "CRITICAL", "[commander] Failsafe activated"),
        (21.0, "INFO", "[commander] Landing detected"),  # below WARNING: never listed
        (26.0, "ERROR", "[commander] Dangerous battery level!, please land!"),
    )
    incidents = [SimpleNamespace(start=4.0, end=4.1), SimpleNamespace(start=11.0, end=12.0)]
    messages, disarmed, outside = flight_messages(metadata, START_NS, incidents, armed=[(2.0, 15.5)])
    assert outside == 0  # no window: the whole log
    assert disarmed == 2  # the preflight warning at 1 s and the error at 16 s, after disarming
    assert [(m.level, m.first, m.last, m.count, m.incident) for m in messages] == [
        ("ERROR", 3.0, 4.0, 2, 1),  # 3.0 s is within 1 s of incident 1, 4.0 s inside it
        ("ERROR", 5.2, 5.2, 1, None),
        ("CRITICAL", 10.5, 10.5, 1, 2),
    ]
    assert messages[0].line() == (
        "ERROR at 3.0 s: [commander] Dangerous battery level!, please land! (x2, until 4.0 s; in incident 1)"
    )
    # unknown arming state: every message of the log is the flight's
    every, none_disarmed, _ = flight_messages(metadata, START_NS, [], armed=None)
    assert none_disarmed == 0 and sum(m.count for m in every) == 6
    assert flight_messages({}, START_NS, [], armed=None) == ([], 0, 0)


@pytest.mark.testdata("px4-ulog-extra")
def test_the_robologs_flight_lists_its_dangerous_battery_error(cli, tmp_path):
    path = need_testdata("px4-ulog-extra/robologs_fmu_v5_test.ulg")
    summary, report = tmp_path / "s.json", tmp_path / "r.html"
    result = cli("analyze", path, "-o", report, "--json", summary)
    assert "Traceback" not in result.stderr
    (log,) = json.loads(summary.read_text())["logs"]
    battery = [m for m in log["autopilot_messages"] if "Dangerous battery level" in m["text"]]
    assert len(battery) == 1 and battery[0]["level"] == "ERROR" and battery[0]["count"] == 1, log["autopilot_messages"]
    # the ERROR came 0.109 s after the log started (boot time 3.238 s), armed
    assert battery[0]["start_clock"] == pytest.approx(3.238, abs=0.01)
    printed = [line for line in result.stdout.splitlines() if "Dangerous battery level" in line]
    assert len(printed) == 1 and printed[0].startswith("  autopilot: ERROR at 3.24 s: [commander]"), result.stdout
    if battery[0]["incident"] is not None:
        number = battery[0]["incident"]
        incident = log["incidents"][number - 1]
        assert incident["start"] - 1.0 <= battery[0]["start"] <= incident["end"] + 1.0
        assert printed[0].endswith(f"(in incident {number})")
    # PX4 switched its primary EKF twice from instance 1 to 0: one line with its count
    switched = [m for m in log["autopilot_messages"] if m["text"] == "[ekf2] primary EKF changed 1 (filter fault) -> 0"]
    assert sum(m["count"] for m in switched) == 2
    page = report.read_text(encoding="utf-8")
    table = page[page.index('id="autopilot-messages"') :]
    assert "Dangerous battery level!, please land!" in table[: table.index("</table>")]


def test_a_window_lists_only_its_own_messages_and_counts_the_others():
    metadata = _metadata(
        (11.0, "WARNING", "[commander] before the window"),
        (13.0, "ERROR", "[commander] Dangerous battery level!, please land!"),
        (14.5, "WARNING", "[commander] in the window, disarmed"),
        (16.0, "CRITICAL", "[commander] after the window"),
    )
    messages, disarmed, outside = flight_messages(metadata, START_NS, [], armed=[(0.0, 4.0)], window=(2.0, 5.0))
    assert [m.text for m in messages] == ["[commander] Dangerous battery level!, please land!"]
    assert (disarmed, outside) == (1, 2)  # the disarmed count is of the window's messages too


@pytest.mark.testdata("px4-ulog-extra")
def test_a_window_of_the_robologs_flight_leaves_out_the_messages_outside_it(cli, tmp_path):
    """--start 2 --end 6 is 5.13-9.13 s of PX4's boot time: the battery ERROR at 3.24 s and the
    load_mon WARNING at 10.95 s are outside it; the EKF switches at 5.68-5.72 s are inside."""
    path = need_testdata("px4-ulog-extra/robologs_fmu_v5_test.ulg")
    summary, report = tmp_path / "s.json", tmp_path / "r.html"
    result = cli("analyze", path, "--start", "2", "--end", "6", "-o", report, "--json", summary)
    (log,) = json.loads(summary.read_text())["logs"]
    texts = [m["text"] for m in log["autopilot_messages"]]
    assert texts and all(t.startswith("[ekf2] primary EKF changed") for t in texts), texts
    assert all(2.0 <= m["start"] <= 6.0 for m in log["autopilot_messages"])
    assert log["autopilot_messages_outside_window"] == 2
    assert "ERROR at 3.24 s" not in result.stdout and "WARNING at 10.95 s" not in result.stdout
    assert "  autopilot: 2 message(s) of WARNING and above outside the window (not listed)" in result.stdout
    page = report.read_text(encoding="utf-8")
    table = page[page.index('id="autopilot-messages"') :]
    assert "Dangerous battery level" not in table[: table.index("</table>")]
    # and says, as the terminal and the JSON do, how many it left out
    assert "2 message(s) of WARNING and above outside the --start/--end window (not listed" in page
    # the Context section is the window's too: its folded table of every message holds no other
    folded = page[page.index('<details id="log-messages">') :]
    folded = folded[: folded.index("</details>")]
    assert "in the --start/--end window (every level); 8 outside it, not listed" in folded
    assert "Dangerous battery level" not in folded and "gps low on stack" not in folded


def test_the_summary_shows_at_most_max_rows_messages_and_says_how_many_more():
    from logscan.cli.render import render_summary
    from logscan.verdict.autopilot_messages import AutopilotMessage

    messages = [AutopilotMessage("WARNING", f"[ekf2] warning {k}", float(k), float(k)) for k in range(15)]
    run = SimpleNamespace(t=np.arange(0.0, 20.0, 0.01), dt=0.01)
    analysis = SimpleNamespace(
        path="flight.ulg",
        verdict=lambda: "no alarms",
        run=run,
        log=SimpleNamespace(duration_s=20.0),
        model=SimpleNamespace(name="ins"),
        results=[],
        clock=Clock(),
        unchecked=[],
        skipped_checks=[],
        failures=[],
        incidents=[],
        autopilot_messages=lambda: (messages, 0, 0),
        loops={},
        alarms=[],
        recovery=None,
        possible=[],
        scores={},
        against_baseline=lambda: None,
        warnings=[],
    )
    text = render_summary(analysis, None, max_rows=12)
    assert text.count("  autopilot: WARNING at ") == 12
    assert "... 3 more autopilot message(s)" in text


def test_every_distinct_message_is_kept_however_many():
    metadata = _metadata(*[(11.0 + 0.1 * k, "WARNING", f"[navigator] waypoint {k} unreachable") for k in range(80)])
    messages, _, _ = flight_messages(metadata, START_NS, [], armed=None)
    assert len(messages) == 80 and all(m.count == 1 for m in messages)
