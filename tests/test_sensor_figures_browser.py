"""The measured-vs-predicted figures of a real report in headless Chromium: `logscan analyze` on
quad_imu_bias draws /imu/accel.x against its prediction, and those figures follow the one time
axis (zoom one figure, every figure follows; the first incident row zooms them all)."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest
from test_report_browser import (
    CHROMIUM,
    PROBE,
    console_errors,
    dump_dom,
    expected_zoom,
    js_errors,
    probe_steps,
    row_interval,
    shown,
)  # fmt: skip

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (Debian: apt-get install -y chromium)"),
]

FIGURE = "accel: /imu/accel.x measured vs predicted"


@pytest.fixture(scope="module")
def bias_page(tmp_path_factory, request):
    """The quad_imu_bias report written by the CLI, with the probe run: (dumped DOM, steps, stderr)."""
    from conftest import SAMPLES

    log = SAMPLES / "quad_imu_bias.mcap"
    if not log.exists():
        pytest.skip(f"{log} missing (run sample_logs/make_samples.py)")
    root = tmp_path_factory.mktemp("sensor")
    page = root / "report.html"
    command = [sys.executable, "-m", "logscan", "analyze", str(log), "-o", str(page), "--plotlyjs", str(root / "js")]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert done.returncode == 1, done.stderr  # alarms
    head, tail = page.read_text(encoding="utf-8").rsplit("</body>", 1)
    page.write_text(head + PROBE + "</body>" + tail, encoding="utf-8")
    dom, stderr = dump_dom(page, root / "profile")
    return dom, probe_steps(dom), stderr


def figure_block(dom: str, title: str) -> str:
    """The DOM of the section figure with a row titled ``title``: from its element to the next figure's."""
    start = re.search(rf'aria-label="(?:[^"]*; )?{re.escape(title)}[;"]', dom).start()
    following = dom.find('role="img"', start + 1)
    return dom[start : following if following > 0 else len(dom)]


def test_the_accelerometer_x_figure_shows_the_channel_and_its_prediction(bias_page):
    dom, _, stderr = bias_page
    assert js_errors(dom) == "" and console_errors(stderr) == []
    block = figure_block(dom, FIGURE)
    assert "plot-container plotly" in block
    legend = re.findall(r'class="legend\d*text"[^>]*>([^<]*)<', block)  # each row's legend: legend2, legend3...
    assert "/imu/accel.x" in legend and any(name.startswith("predicted") for name in legend)
    assert len(re.findall(r'<path class="js-line"', block)) >= 3  # band, prediction, measured drawn


def test_the_sensor_figures_follow_the_time_axis(bias_page):
    dom, steps, _ = bias_page
    ids = steps["drag"]["ids"]
    sensor = r'id="(fig-\d+)" data-rows="\d+" role="img" aria-label="[^"]* measured vs predicted[;"]'
    sensor_ids = re.findall(sensor, dom)
    assert len(sensor_ids) >= 1 and set(sensor_ids) <= set(ids)
    first = steps["drag"]["ranges"][0]
    assert first != "auto" and all(r == pytest.approx(first) for r in shown(steps["drag"]))
    start, end = row_interval(dom, "incident-table", 0)
    low, high = expected_zoom(start, end)
    zoom = [max(low, 0.0), min(high, 60.0)]  # the margins stop at the log's ends (0-60 s; report.js zoomTo)
    assert all(r == pytest.approx(zoom) for r in shown(steps["incident"]))
    # reset restores each figure's first view: autorange, or the 0-60 s range a figure is drawn with
    # (the observability context figure, ctx-observability)
    # (the observability context figure, ctx-observability), or the headline figure's zoom to its alarm
    first_views = dict(zip(ids, steps["start"]["ranges"], strict=True))
    assert steps["reset"]["ranges"] == steps["start"]["ranges"]
    headline = first_views.pop("fig-headline")
    assert 20 < headline[0] < 30 and 41.3 < headline[1] < 50  # the nis.accel alarm, 30.00-41.27 s
    assert all(r in ("auto", [0, 60]) for r in first_views.values())
    assert all(r == "auto" for i, r in first_views.items() if i in sensor_ids)
