"""A window's checks of the vehicle's own reports run from before it (`logscan.pipeline.raw_lead`):
the window shows the alarms the whole log has in it, also those whose persistence began earlier."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import SAMPLES, need_testdata

from logscan.needs import Needs
from logscan.pipeline import load_profile_for, prepare
from logscan.pipeline.raw_lead import led_grid

RAW_TOPIC_DETECTORS = ("health", "px4_estimator")


def _raw_alarms(cli, tmp_path, path, *window) -> list[dict]:
    out = tmp_path / f"{'-'.join(window) or 'whole'}.json"
    result = cli("analyze", path, *window, "--no-report", "--json", str(out))
    assert result.exit_code in (0, 1, 2), result.stdout + result.stderr
    log = json.loads(out.read_text())["logs"][0]
    return [a for d in log["detectors"] if d["detector"] in RAW_TOPIC_DETECTORS for a in d["alarms"]]


@pytest.mark.testdata("px4-ulog-extra/robologs_fmu_v5_test.ulg")
@pytest.mark.parametrize("start", [2.0, 2.3, 2.5, 0.5])
def test_a_windows_battery_alarm_is_the_whole_logs_in_it(cli, tmp_path, start):
    """The real robologs flight's battery (PX4's filtered voltage) is under its empty voltage from
    1.15 s (since time zero) to the end and PX4 said "Dangerous battery level" before; the whole
    log's health.battery alarm is 2.14-8.94 s (1 s of persistence). A window from 2.0 s lost it (its
    persistence started again at the window's first step); one from 2.3 s or 2.5 s sees its part
    from there."""
    path = str(need_testdata("px4-ulog-extra/robologs_fmu_v5_test.ulg"))
    whole = _raw_alarms(cli, tmp_path, path)
    assert any(a["signal"] == "health.battery" for a in whole)
    end = 9.0  # the battery alarms end with the log (8.94 s)
    seen = _raw_alarms(cli, tmp_path, path, "--start", str(start), "--end", str(end))
    expected = sorted((a for a in whole if start <= a["end"] <= end), key=lambda a: a["signal"])
    seen = sorted(seen, key=lambda a: a["signal"])  # the alarms ending together, in either order
    assert expected, "the case this pins: an alarm of the whole log inside the window"
    assert [(a["signal"], a["end"]) for a in seen] == [(a["signal"], a["end"]) for a in expected]
    log = json.loads((tmp_path / f"--start-{start}---end-{end}.json").read_text())["logs"][0]
    assert not any("most of the log" in line or "over the log" in line for line in log["unchecked"])
    for a, b in zip(seen, expected):
        assert a["start"] == (b["start"] if b["start"] >= start else pytest.approx(a["first_exceed"]))
        assert a["start"] >= start - 1e-6 and a["first_exceed"] >= start - 1e-6


def test_the_led_grid_is_the_whole_grids_steps_before_and_through_the_window():
    path = str(SAMPLES / "quad_healthy.mcap")
    profile = load_profile_for(path, None)
    whole = prepare(path, profile, Needs.of()).run
    window = prepare(path, profile, Needs.of(), start_s=50.0, end_s=55.0).run
    lead = led_grid(window)
    assert lead is not None and led_grid(whole) is None
    first = int(np.flatnonzero(whole.t == lead.t[0])[0])
    assert np.array_equal(lead.t, whole.t[first : first + lead.n_steps])  # the same floats
    assert lead.t[-1] == window.t[-1] and lead.t[0] == whole.t[0]  # 240 s reaches back to the log's first step


@pytest.mark.testdata("px4-ulog-extra/robologs_fmu_v5_test.ulg")
def test_a_check_with_samples_only_before_the_window_has_nothing_to_judge_in_it(cli, tmp_path):
    """From 8.5 s the real flight's GNSS, motor and timeout checks have samples only in the lead-in:
    cut to the window their statistics hold no value, which read "never computed" and left the
    window not fully checked (exit 2); a window alone says they had nothing to judge there, headed
    as the window's, not the log's (the log has samples of them). (Its battery, under empty to the
    end, alarms there.)"""
    path = str(need_testdata("px4-ulog-extra/robologs_fmu_v5_test.ulg"))
    out, page = tmp_path / "late.json", tmp_path / "late.html"
    result = cli("analyze", path, "--start", "8.5", "-d", "health", "-o", str(page), "--json", str(out))
    log = json.loads(out.read_text())["logs"][0]
    assert result.exit_code == 1 and not log["unchecked"], result.stdout
    alarms = {a["signal"] for d in log["detectors"] for a in d["alarms"]}
    assert alarms == {"health.battery", "health.battery_warning"}, alarms
    assert any("health.gnss_fix: no sample in the --start/--end window" in line for line in log["skipped_checks"])
    assert "  not checked (nothing to judge in the --start/--end window): health: " in result.stdout
    assert "nothing to judge in this log" not in result.stdout
    html = page.read_text(encoding="utf-8")
    assert "<strong>Checks with nothing to judge in the --start/--end window</strong>" in html
    assert "nothing to judge in this log" not in html and "on the whole log" not in html
    early = tmp_path / "early.json"
    cli("analyze", path, "--start", "2", "--end", "6", "--no-report", "--json", str(early))
    health = next(d for d in json.loads(early.read_text())["logs"][0]["detectors"] if d["detector"] == "health")
    assert all(e["time"] >= 2.0 for e in health["info"].get("logged_errors", [])), health["info"]["logged_errors"]
