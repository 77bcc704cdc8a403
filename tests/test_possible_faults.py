"""The warning level below alarms: "possible fault" intervals (`DetectorResult.add_possible`) are
listed apart from alarms in the verdict, the summary, the JSON and the report, and fail a run only
with `--fail-on warning`."""

from __future__ import annotations

import numpy as np

from logscan.results import DetectorResult


def result_with(alarm: bool, possible: bool) -> DetectorResult:
    t = np.arange(1000) * 0.01
    result = DetectorResult("probe")
    lower = np.zeros(t.size)
    upper = np.zeros(t.size)
    if alarm:
        lower[100:150] = 5.0
    if possible:
        upper[100:160] = 5.0  # overlaps the alarm: not a possible fault of its own
        upper[600:640] = 5.0
    result.add_statistic(t, "probe.lo", lower, upper=1.0)
    result.add_possible(t, "probe.hi", upper, 1.0)
    return result


def test_possible_faults_exclude_what_an_alarm_covers():
    both = result_with(alarm=True, possible=True)
    assert len(both.alarms) == 1
    assert [(round(p.start, 2), round(p.end, 2)) for p in both.possible] == [(6.0, 6.39)]
    alone = result_with(alarm=False, possible=True)
    assert len(alone.possible) == 2 and alone.alarms == []
    doc = alone.to_dict()
    assert doc["n_possible"] == 2 and doc["n_alarms"] == 0 and len(doc["possible_faults"]) == 2


def test_verdict_exit_code_and_summary_distinguish_possible_faults(sample):
    from logscan.pipeline import analyze_log

    analysis = analyze_log(sample("quad_healthy.mcap"), free_series=True)
    assert analysis.verdict() == "no alarms" and int(analysis.exit_code()) == 0
    analysis.results.append(result_with(alarm=False, possible=True))
    assert analysis.verdict() == "no alarms; 2 possible faults"
    assert int(analysis.exit_code()) == 0 and int(analysis.exit_code(fail_on_warning=True)) == 1
    summary = analysis.summary()
    assert summary["n_alarms"] == 0 and summary["n_possible"] == 2
    from logscan.cli.render import render_summary

    text = render_summary(analysis, None)
    assert text.count("possible fault: probe probe.hi") == 2
    analysis.prepared.release_series()
    from logscan.report import render_html

    page = render_html(analysis.report_input())
    assert "2 possible faults (warnings, not alarms): probe probe.hi, 1.00-6.39 s" in page
    assert '"possible fault"' in page or "possible fault" in page
