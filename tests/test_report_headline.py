"""The report's first screen on quad_imu_bias (+1.0 m/s² on accelerometer x, 30-40 s): the verdict line
gives the span of the check it quotes and the physical size of the deviation, the headline sensor's
figure comes first and is zoomed to it, and the margin table shows the checks that matter."""

from __future__ import annotations

import re

import pytest
from test_report import figures, table

from logscan.report.headline import quoted_alarm, significant
from logscan.report.page import render_html


@pytest.fixture(scope="module")
def bias():
    """(ReportInput, page) of quad_imu_bias, analysed as `logscan analyze` does for a report."""
    from conftest import SAMPLES

    from logscan.pipeline import analyze_log

    log = SAMPLES / "quad_imu_bias.mcap"
    if not log.exists():
        pytest.skip(f"{log} missing (run sample_logs/make_samples.py)")
    analysis = analyze_log(log, sensor_views=True, free_series=True)
    report = analysis.report_input()
    return report, render_html(report, plotlyjs_src="plotly.min.js"), analysis


def verdict_lines(page: str) -> list[str]:
    block = re.search(r'<ul id="verdict-lines">(.*?)</ul>', page, re.S)
    assert block, "no verdict lines"
    return re.findall(r"<li>(.*?)</li>", block.group(1))


def test_the_headline_gives_the_quoted_checks_span_and_the_deviation_in_the_sensors_units(bias):
    report, page, _ = bias
    (incident,) = report.incidents
    assert (incident.start, incident.end) == (30.0, 60.0)  # every alarm of the incident
    quoted = quoted_alarm(incident, list(report.model["groups"]))
    assert quoted.signal == "nis.accel"
    (line,) = verdict_lines(page)
    match = re.fullmatch(
        r"accelerometer inconsistent: ([+-][\d.]+) m/s² \(([\d.]+)σ\) on accel ax for ([\d.]+) s, "
        r"30\.00-([\d.]+) s \(nis\.accel, peak 10\.7x\)",
        line,
    )
    assert match, line
    size, sigmas, duration, end = (float(g) for g in match.groups())
    assert end == pytest.approx(float(quoted.end), abs=0.01) and end < 45  # not the incident's 60 s
    assert duration == pytest.approx(float(quoted.end - quoted.start), abs=0.05)
    assert 0.8 <= size <= 1.2  # the injected bias is +1.0 m/s²; the filter absorbs a part of it
    assert sigmas > 5
    # the incident table says the same line
    assert line in page[page.index('id="incident-table"') :]
    # incidents, alarms and ground-truth events are all numbered from 1
    assert table(page, "incident-table")[1][0] == "1" and min(int(r[1]) for r in table(page, "alarm-table")[1:]) == 1
    assert table(page, "truth-table")[1][0] == "1" and table(page, "alarm-table")[1][10] == "#1 bias accel.x"


def test_the_headline_sensor_figure_is_first_and_zoomed_to_the_alarm(bias):
    report, page, _ = bias
    assert page.index('id="fig-headline"') < page.index('id="incident-table"') < page.index('id="alarm-table"')
    spec = figures(page)[0]
    assert spec["id"] == "fig-headline"
    layout = spec["figure"]["layout"]
    start, end = layout["xaxis"]["range"]
    assert 20 < start < 30 and 41.3 < end < 50  # the alarm 30.00-41.27 s with the zoom margin
    names = [trace.get("name") for trace in spec["figure"]["data"]]
    assert "/imu/accel.x" in names and "predicted ± 3σ" in names
    assert "+0." in layout["title"]["text"] or "+1." in layout["title"]["text"]


def test_the_margin_table_shows_the_checks_that_matter_and_folds_the_rest(bias):
    report, page, _ = bias
    shown, folded = table(page, "margin-table")[1:], table(page, "margin-table-more")[1:]
    assert len(shown) + len(folded) == sum(len(r.series) for r in report.results)
    assert 3 <= len(shown) < len(folded)
    for row in shown:
        ratio = float(row[3]) if row[3] not in ("—", "inf") else 0.0
        assert int(row[6]) > 0 or ratio > 0.8 or len(shown) == 3
    for row in folded:
        assert int(row[6]) == 0 and (row[3] in ("—",) or float(row[3]) <= 0.8)
    assert re.search(r'<details id="margin-more"><summary>\d+ more checks, each at most [\d.]+ of its threshold', page)


def test_significant_figures_keep_the_sign_and_trailing_zeros():
    assert significant(1.0) == "+1.0"
    assert significant(-0.03418) == "-0.034"
    assert significant(0.9234) == "+0.92"
    assert significant(123.4) == "+123"
    assert significant(5.62716, 3) == "+5.63"


def test_a_saturated_cusum_alarm_shows_its_uncapped_size_not_the_cap(bias):
    report, page, _ = bias
    (cusum,) = [r for r in report.results if r.detector == "cusum"]
    capped = [a for a in cusum.alarms if a.signal == "cusum.accel.ax" and a.peak_ratio == pytest.approx(1.5)]
    assert capped, "the accelerometer x CUSUM no longer saturates: pick another statistic"
    uncapped = cusum.info["uncapped_peaks"]["cusum.accel.ax"]
    rows = [row for row in table(page, "alarm-table")[1:] if row[3] == "cusum.accel.ax"]
    ratios = sorted(float(row[9]) for row in rows)
    assert ratios == pytest.approx(sorted(abs(r["peak_ratio"]) for r in uncapped), rel=1e-2)
    assert max(ratios) > 10  # a 1 m/s² bias over 10 s is far past the threshold, not 1.5 times it
    assert all(row[-1].startswith("uncapped peak") for row in rows)
    margin = next(row for row in table(page, "margin-table")[1:] if row[1] == "cusum.accel.ax")
    assert float(margin[3]) == pytest.approx(max(ratios), rel=1e-2)


def test_the_terminal_and_the_json_say_the_reports_headline(bias):
    """One wording (`Incident.headline_in`): the headline check's span and the deviation's size, not
    the incident's 30-60 s, in the terminal summary and the JSON document as on the report."""
    from logscan.cli.render import render_summary

    report, page, analysis = bias
    (line,) = verdict_lines(page)
    assert "30.00-60.00" not in line and " m/s² (" in line
    (incident,) = analysis.summary()["incidents"]
    assert incident["headline"] == line
    assert (incident["start"], incident["end"]) == (30.0, 60.0)  # the incident's own span stays in the JSON
    assert f"incident 1: {line}" in render_summary(analysis, None)


def test_without_the_innovations_the_headline_keeps_the_checks_span_and_says_no_size():
    from logscan.alarms import AlarmInterval
    from logscan.results import Incident

    quoted = AlarmInterval(30.0, 41.27, 30.0, 31.0, 10.7, 1.0, 10.7, "upper", 100, "nis.accel", "nis")
    late = AlarmInterval(35.0, 60.0, 35.0, 36.0, 2.0, 1.0, 2.0, "upper", 100, "nis.all", "nis")
    incident = Incident(30.0, 60.0, "accel", "", [quoted, late], "accelerometer inconsistent", "nis.accel, peak 10.7x",
                        quoted)  # fmt: skip
    assert incident.headline_in() == "accelerometer inconsistent 30.00-41.27 s (nis.accel, peak 10.7x)"
    assert incident.headline_in(size="+1.0 m/s² (9.0σ) on accel ax for 11.3 s") == (
        "accelerometer inconsistent: +1.0 m/s² (9.0σ) on accel ax for 11.3 s, 30.00-41.27 s (nis.accel, peak 10.7x)"
    )


def test_an_instant_check_heads_its_incident_at_its_time_not_as_a_span():
    """A logged error is one sample: the real robologs flight's incident read "the autopilot logged an
    error 3.24-3.24 s"; it reads "at 3.24 s", in the log's clock too."""
    from logscan.alarms import AlarmInterval
    from logscan.results import Incident
    from logscan.timebase.clock import BOOT_TIME, Clock

    error = AlarmInterval(0.11, 0.11, 0.11, 0.11, 2.0, 1.0, 2.0, "upper", 1, "health.logged_error", "health")
    battery = AlarmInterval(0.14, 8.94, 0.14, 0.14, 2.0, 1.0, 2.0, "upper", 40, "health.battery_warning", "health")
    incident = Incident(0.11, 8.94, "", "", [error, battery], "the autopilot logged an error",
                        "health.logged_error, peak 2x", error)  # fmt: skip
    assert incident.headline_in() == "the autopilot logged an error at 0.11 s (health.logged_error, peak 2x)"
    boot = Clock(BOOT_TIME, 3.129)
    assert incident.headline_in(boot) == "the autopilot logged an error at 3.24 s (health.logged_error, peak 2x)"
