"""The log's own clock (logscan/timebase/clock.py) on stdout, in the JSON and on the report's time axis: a
crafted ULog counts PX4 boot time, an MCAP with epoch stamps UTC (a date axis), a simulated log
seconds since its start; ground truth scores the same whatever the clock."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from conftest import SAMPLES, need_testdata, one_state_profile
from test_report import array, figures
from ulog_writer import write_ulog

from logscan.timebase.clock import BOOT_TIME, SINCE_START, UTC, Clock, clock_of, gnss_utc_zero

THRUST = "/vehicle_thrust_setpoint_0/xyz[2]"
ACCEL = "/sensor_combined_0/accelerometer_m_s2[2]"
BOOT_S = 500.0  # the logger started 500 s after PX4 booted
FAULT_S = (20.0, 30.0)  # gps_hpos over its gate, seconds after the logger's start
GNSS_UTC_S = 1_710_773_350.0  # 2024-03-18T14:49:10Z at the logger's start


def boot_time_log(path, *, gnss: bool = False):
    """A 60 s ULog logged from boot time BOOT_S: 100 Hz IMU and thrust, PX4's gps_hpos test ratio 3
    (over its gate) over FAULT_S; with ``gnss`` a 5 Hz GNSS UTC time (0 before its first fix at 3 s)."""
    t_us = int(BOOT_S * 1e6) + np.arange(1, 6001) * 10_000
    n = t_us.size
    rng = np.random.default_rng(3)
    rel = (t_us - BOOT_S * 1e6) / 1e6
    gps = np.where((rel >= FAULT_S[0]) & (rel < FAULT_S[1]), 3.0, 0.3)
    accel = np.column_stack([np.zeros((n, 2)), rng.normal(-9.81, 0.05, n)])
    topics = {
        "sensor_combined": (t_us, {"accelerometer_m_s2": accel}),
        "vehicle_thrust_setpoint": (t_us, {"xyz": np.column_stack([np.zeros((n, 2)), np.full(n, -0.5)])}),
        "estimator_innovation_test_ratios": (t_us[::10], {"gps_hpos": np.column_stack([gps[::10], gps[::10]])}),
    }
    if gnss:
        t_gps = t_us[::20]
        since = (t_gps - BOOT_S * 1e6) / 1e6
        utc_us = np.where(since >= 3.0, np.round((GNSS_UTC_S + since) * 1e6), 0).astype(np.uint64)
        topics["vehicle_gps_position"] = (t_gps, {"time_utc_usec": utc_us})
    return write_ulog(path, topics, parameters={"EKF2_GPS_P_GATE": 5.0}, start_us=int(BOOT_S * 1e6))


@pytest.fixture
def profile(tmp_path):
    path = tmp_path / "one.profile.toml"
    path.write_text(one_state_profile(THRUST, ACCEL), encoding="utf-8")
    return path


def test_clock_arithmetic_and_texts():
    boot = Clock(BOOT_TIME, 500.0)
    assert boot.at(20.0) == 520.0 and boot.span_text(20.0, 30.5) == "520.00-530.50 s"
    assert boot.axis_title() == "PX4 boot time (s)" and not boot.relative
    assert boot.axis_values(np.array([0.0, 1.0])).dtype == np.float32  # small: float32 keeps 1 ms
    assert Clock(BOOT_TIME, 9000.0).axis_values(np.array([0.0])).dtype == np.float64  # 1 ms needs float64
    utc = Clock(UTC, GNSS_UTC_S, utc=True, utc_zero_s=GNSS_UTC_S)
    assert utc.utc_text(1.5) == "2024-03-18T14:49:11.500Z"
    assert utc.span_text(1.5, 2.0) == "2024-03-18 14:49:11.500-14:49:12.000 UTC"
    assert utc.axis_value(1.5) == pytest.approx((GNSS_UTC_S + 1.5) * 1e3)  # epoch ms for a date axis
    stamped = utc.stamp({"start": 1.5, "end": None})
    assert stamped["start_clock"] == GNSS_UTC_S + 1.5 and stamped["start_utc"].endswith("11.500Z")
    assert "end_clock" not in stamped and stamped["start"] == 1.5
    assert Clock().relative and Clock().to_dict()["utc_start"] is None


def test_a_ulog_alarm_at_boot_time_t_shows_t_on_stdout_json_and_the_report_axis(tmp_path, cli, profile):
    log = boot_time_log(tmp_path / "boot.ulg")
    report, summary = tmp_path / "boot.html", tmp_path / "boot.json"
    result = cli("analyze", log, "--profile", profile, "--detector", "px4_estimator", "-o", report, "--json", summary)
    assert result.exit_code == 1, result.stderr
    entry = json.loads(summary.read_text())["logs"][0]
    assert entry["clock"] == {"name": BOOT_TIME, "offset_s": pytest.approx(BOOT_S), "utc": False, "utc_start": None}
    (alarm,) = [a for d in entry["detectors"] for a in d["alarms"] if a["signal"] == "px4.gps_hpos"]
    assert FAULT_S[0] <= alarm["start"] <= FAULT_S[0] + 2.5  # relative field unchanged
    assert alarm["start_clock"] == pytest.approx(BOOT_S + alarm["start"])
    boot_start = f"{BOOT_S + alarm['start']:.2f}"
    assert "times: PX4 boot time (s); time zero at 500.000 s" in result.stdout
    assert re.search(rf"px4\.gps_hpos\s+{re.escape(boot_start)}\s", result.stdout), result.stdout
    incident = entry["incidents"][0]
    assert f"{BOOT_S + incident['start']:.2f}-" in incident["headline"] and incident["headline"] in result.stdout
    html = report.read_text(encoding="utf-8")
    timeseries = [f["figure"] for f in figures(html) if f["figure"]["layout"]["xaxis"]["title"]["text"] != "s"]
    titles = {f["layout"]["xaxis"]["title"]["text"] for f in timeseries if "type" not in f["layout"]["xaxis"]}
    assert titles == {"PX4 boot time (s)"}
    xs = np.concatenate([array(tr["x"]) for f in timeseries for tr in f["data"]])
    xs = xs[np.isfinite(xs)]
    assert BOOT_S <= xs.min() < BOOT_S + 1.0 and xs.max() <= BOOT_S + 61.0  # the axis counts boot time
    assert f">{BOOT_S + alarm['start']:.3f}<" in html  # the alarm table's start


def test_a_ulogs_gnss_time_dates_its_boot_clock(tmp_path):
    from logscan.readers import read_log

    log = read_log(boot_time_log(tmp_path / "gnss.ulg", gnss=True))
    clock = clock_of(log)
    assert clock.name == BOOT_TIME and not clock.utc  # the axis stays boot time
    assert clock.offset_s == pytest.approx(BOOT_S)
    assert clock.utc_zero_s == pytest.approx(GNSS_UTC_S, abs=1e-3)  # samples before the fix ignored
    assert clock.to_dict()["utc_start"] == "2024-03-18T14:49:10.000Z"
    assert gnss_utc_zero(read_log(boot_time_log(tmp_path / "plain.ulg")), int(BOOT_S * 1e9)) is None


def test_analyze_dates_a_ulogs_boot_clock_from_its_gnss_time(tmp_path, cli, profile):
    """The pipeline reads the GNSS time beside the profile's topics and dates the clock before the
    samples are released: the JSON and stdout give the UTC of time zero."""
    log = boot_time_log(tmp_path / "gnss.ulg", gnss=True)
    summary = tmp_path / "gnss.json"
    result = cli("analyze", log, "--profile", profile, "--detector", "px4_estimator", "--no-report", "--json", summary)
    assert result.exit_code == 1, result.stderr
    clock = json.loads(summary.read_text())["logs"][0]["clock"]
    assert clock["name"] == BOOT_TIME and clock["utc_start"] == "2024-03-18T14:49:10.000Z"
    assert "= 2024-03-18T14:49:10.000Z (GNSS)" in result.stdout


def test_an_mcap_with_epoch_stamps_gets_a_utc_date_axis(tmp_path, cli):
    log = SAMPLES / "ros2_ins.mcap"
    if not log.is_file():
        pytest.skip("sample log missing")
    report, summary = tmp_path / "ins.html", tmp_path / "ins.json"
    result = cli("analyze", log, "-o", report, "--json", summary, "--detector", "nis")
    assert result.exit_code in (0, 1), result.stderr
    entry = json.loads(summary.read_text())["logs"][0]
    assert entry["clock"]["name"] == UTC and entry["clock"]["utc"]
    assert entry["clock"]["utc_start"] == "2023-11-14T22:13:20.000Z"  # log_time 1.7e9 s
    assert "times: UTC" in result.stdout
    axes = [f["figure"]["layout"]["xaxis"] for f in figures(report.read_text(encoding="utf-8"))]
    dated = [a for a in axes if a.get("type") == "date"]
    assert dated and all(a["title"]["text"] == "UTC" for a in dated)
    x = array(next(f for f in figures(report.read_text()) if f["figure"]["layout"]["xaxis"].get("type") == "date")[
        "figure"]["data"][-1]["x"])  # fmt: skip
    assert x.dtype == np.float64 and 1.7e12 <= np.nanmin(x) < 1.7e12 + 40e3  # epoch milliseconds


def test_a_simulated_log_keeps_time_since_log_start(tmp_path, cli):
    log = SAMPLES / "quad_imu_bias.mcap"
    if not log.is_file():
        pytest.skip("sample log missing")
    report, summary = tmp_path / "quad.html", tmp_path / "quad.json"
    result = cli("analyze", log, "-o", report, "--json", summary, "--detector", "nis")
    entry = json.loads(summary.read_text())["logs"][0]
    assert entry["clock"] == {"name": SINCE_START, "offset_s": 0.0, "utc": False, "utc_start": None}
    assert "times:" not in result.stdout  # seconds since the start, as the span says
    titles = {f["figure"]["layout"]["xaxis"]["title"]["text"] for f in figures(report.read_text())}
    assert "time since log start (s)" in titles and "PX4 boot time (s)" not in titles
    # ground truth in log time still scores the same: the injected bias is detected
    assert entry["scores"]["nis"]["tp"] >= 1


def test_utc_ground_truth_scores_the_same_as_log_time_truth(tmp_path, cli):
    log = SAMPLES / "ros2_ins.mcap"
    if not log.is_file():
        pytest.skip("sample log missing")
    relative = {"events": [{"kind": "bias", "target": "imu", "start": 10.0, "end": 20.0}]}
    span = {"start_utc": "2023-11-14T22:13:30Z", "end_utc": "2023-11-14T22:13:40Z"}
    utc = {"events": [{"kind": "bias", "target": "imu", **span}]}
    scores = []
    for name, truth in (("rel", relative), ("utc", utc)):
        path = tmp_path / f"{name}.truth.json"
        path.write_text(json.dumps(truth))
        out = tmp_path / f"{name}.json"
        cli("analyze", log, "--truth", path, "--no-report", "--json", out, "--detector", "nis")
        entry = json.loads(out.read_text())["logs"][0]
        (event,) = entry["truth_events"]
        assert event["start"] == pytest.approx(10.0) and event["start_utc"] == "2023-11-14T22:13:30.000Z"
        scores.append(entry["scores"])
    assert scores[0] == scores[1]


@pytest.mark.parametrize("name", ["sample_log_small.ulg", "sample_px4_events.ulg"])
def test_real_ulogs_name_their_clock_on_stdout(cli, tmp_path, name):
    log = need_testdata("px4-ulog") / name
    if not log.is_file():
        pytest.skip(f"{name} missing")
    result = cli("analyze", log, "--no-report", "--json", tmp_path / "out.json")
    assert result.exit_code in (0, 1, 2), result.stderr
    clock = json.loads((tmp_path / "out.json").read_text())["logs"][0]["clock"]
    # a real PX4 flight counts boot time; PX4 SITL stamps wall-clock time (2024): UTC
    expected = UTC if clock["offset_s"] > 9.46e8 else BOOT_TIME
    assert clock["name"] == expected and f"times: {expected}" in result.stdout


# once every figure is drawn: clicks the alarm row, then records the x range and type of the first figure
ZOOM_PROBE = """<script>
(function () {
  function probe() {
    if (!document.body.getAttribute("data-time-axis")) { setTimeout(probe, 50); return; }
    var row = document.querySelector("#alarm-table tr[data-start]");
    row.click();
    setTimeout(function () {
      var plot = document.querySelector(".ls-timeseries.js-plotly-plot");
      document.body.setAttribute("data-probe", JSON.stringify({range: plot.layout.xaxis.range,
        type: plot._fullLayout.xaxis.type, label: document.getElementById("ls-zoom").textContent}));
    }, 1000);
  }
  probe();
})();
</script>
"""


def test_a_row_click_zooms_a_utc_date_axis_to_its_alarm(tmp_path):
    from test_report_browser import CHROMIUM, dump_dom, js_errors
    from test_report_overview import quiet_and_alarming, report_of

    from logscan.report import render_report

    if CHROMIUM is None:
        pytest.skip("chromium not installed")
    report = report_of(quiet_and_alarming(), verdict="2 alarms")
    report.clock = Clock(UTC, GNSS_UTC_S, utc=True, utc_zero_s=GNSS_UTC_S)
    path = tmp_path / "report.html"
    render_report(report, path, plotlyjs=tmp_path / "js")
    page = path.read_text(encoding="utf-8")
    assert "<th>start (UTC)</th>" in page and ">14:49:13.000<" in page  # the alarm at 3.00 s
    path.write_text(page.replace("</body>", ZOOM_PROBE + "</body>"), encoding="utf-8")
    dom, _ = dump_dom(path, tmp_path / "profile")
    assert js_errors(dom) == ""
    probe = json.loads(re.search(r"data-probe=\"([^\"]*)\"", dom).group(1).replace("&quot;", '"'))
    assert probe["type"] == "date"
    # plotly keeps the range as given: epoch ms from report.js, a date string from its own zoom
    low, high = (
        np.datetime64(int(v), "ms") if isinstance(v, (int, float)) else np.datetime64(v.replace(" ", "T"))
        for v in probe["range"]
    )
    alarm = np.datetime64("2024-03-18T14:49:13")
    # zoomed around the alarm (3.00-3.19 s) with a margin of at least 2 s, not the whole 10 s
    assert low < alarm < high and (high - low) < np.timedelta64(9, "s"), probe
    assert "14:49:1" in probe["label"] and "UTC" in probe["label"]
