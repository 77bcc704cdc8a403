"""The report of quad_imu_bias in headless Chromium at 1400x900: the first screen holds the verdict and
the headline sensor's figure (measured vs predicted, zoomed to the alarm), drawn; a detector section is
one figure whose rows share one crosshair (hovering one row draws one spike line through every row
and one hover box with every row's values).

The page gets a probe script that, once every figure is drawn, writes what it measured into an
attribute of ``<body>``, which the tests read from the DOM Chromium dumps. Skipped (with the
reason) when no Chromium is installed.
"""

from __future__ import annotations

import html
import json
import re
import subprocess

import pytest
from test_report_browser import CHROMIUM, js_errors

from logscan.report.page import render_report

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (Debian: apt-get install -y chromium)"),
]

WIDTH, HEIGHT = 1400, 900

PROBE = """<script>
(function () {
  function box(el) {
    if (!el) { return null; }
    var r = el.getBoundingClientRect();
    return { top: r.top, bottom: r.bottom, drawn: !!el.querySelector(".main-svg"),
             lines: el.querySelectorAll("path.js-line").length };
  }
  function record() {
    var out = { verdict: box(document.getElementById("verdict")), width: window.innerWidth,
                headline: box(document.getElementById("fig-headline")) };
    document.body.setAttribute("data-first-screen", JSON.stringify(out));
  }
  var observer = new MutationObserver(function () {
    if (document.body.hasAttribute("data-plots-rendered")) { observer.disconnect(); record(); }
  });
  if (document.body.hasAttribute("data-plots-rendered")) { record(); }
  else { observer.observe(document.body, { attributes: true, attributeFilter: ["data-plots-rendered"] }); }
})();
</script>"""


HOVER = """<script>
(function () {
  function hover() {  /* the mouse over the first row of the nis section, 55 % along its time axis */
    var el = document.querySelector('.ls-section[aria-label^="nis"]'), drags = el.querySelectorAll(".nsewdrag");
    var box = drags[0], r = box.getBoundingClientRect();
    box.dispatchEvent(new MouseEvent("mousemove", {bubbles: true, cancelable: true, view: window,
      clientX: r.left + 0.55 * r.width, clientY: r.top + r.height / 2}));
    setTimeout(function () {
      function span(node) { var b = node.getBoundingClientRect(); return [b.left, b.top, b.bottom]; }
      var out = {
        rows: Array.prototype.map.call(drags, span),
        spikes: Array.prototype.map.call(el.querySelectorAll(".spikeline"), span),
        label: (el.querySelector(".hoverlayer") || {}).textContent || "",
        other: Array.prototype.filter.call(document.querySelectorAll(".ls-timeseries"), function (f) {
          return f !== el && f.querySelector(".spikeline");
        }).length
      };
      document.body.setAttribute("data-hover", JSON.stringify(out));
    }, 500);
  }
  var wait = setInterval(function () {
    if (document.body.hasAttribute("data-time-axis")) { clearInterval(wait); hover(); }
  }, 50);
})();
</script>"""


def first_screen(page, profile, attribute: str = "data-first-screen") -> tuple[dict, str]:
    command = [
        CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-dev-shm-usage",
        f"--window-size={WIDTH},{HEIGHT}", f"--user-data-dir={profile}", "--virtual-time-budget=10000",
        "--dump-dom", page.resolve().as_uri(),
    ]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    match = re.search(rf'{attribute}="([^"]*)"', done.stdout)
    assert match, "the probe did not run: figures not drawn"
    return json.loads(html.unescape(match.group(1))), done.stdout


@pytest.fixture(scope="module")
def bias_report():
    from conftest import SAMPLES

    from logscan.pipeline import analyze_log

    log = SAMPLES / "quad_imu_bias.mcap"
    if not log.exists():
        pytest.skip(f"{log} missing (run sample_logs/make_samples.py)")
    return analyze_log(log, sensor_views=True, free_series=True).report_input()


def test_the_first_screen_holds_the_verdict_and_the_headline_sensor_figure(bias_report, tmp_path):
    page = tmp_path / "report.html"
    render_report(bias_report, page, plotlyjs=tmp_path / "js")
    text = page.read_text(encoding="utf-8")
    page.write_text(text.replace("</body>", PROBE + "</body>", 1), encoding="utf-8")
    screen, dom = first_screen(page, tmp_path / "profile")
    assert js_errors(dom) == ""
    assert screen["width"] == WIDTH  # (the viewport's height under --dump-dom is the window's less its frame;
    # the layout depends on the width only, and the screenshot of the same window is 900 px high)
    verdict, headline = screen["verdict"], screen["headline"]
    assert headline is not None, "no headline figure"
    assert 0 <= verdict["top"] < verdict["bottom"] <= headline["top"]
    assert headline["bottom"] <= HEIGHT, f"the headline figure ends at {headline['bottom']} px, below the first screen"
    assert headline["drawn"] and headline["lines"] >= 3  # band, prediction, measured
    assert 'aria-label="accel ax: measured vs predicted' in dom


def test_hovering_one_row_of_a_section_draws_one_crosshair_through_all_its_rows(bias_report, tmp_path):
    page = tmp_path / "report.html"
    render_report(bias_report, page, plotlyjs=tmp_path / "js")
    text = page.read_text(encoding="utf-8")
    page.write_text(text.replace("</body>", HOVER + "</body>", 1), encoding="utf-8")
    hover, dom = first_screen(page, tmp_path / "profile", "data-hover")
    assert js_errors(dom) == ""
    rows, spikes = hover["rows"], hover["spikes"]
    assert len(rows) >= 6  # nis: its ratio, the accelerometer's and the position's channels, ...
    top, bottom = rows[0][1], rows[-1][2]
    assert spikes, "no spike line"
    assert len({round(left) for left, _, _ in spikes}) == 1  # one time, one vertical line
    assert min(s[1] for s in spikes) <= top + 1 and max(s[2] for s in spikes) >= bottom - 1  # through every row
    # one hover box with the values of every row at that time: the first row's and the last row's
    assert "nis.accel" in hover["label"] and "/imu/accel.x" in hover["label"] and "/attitude" in hover["label"]
    assert hover["other"] == 0  # the other sections' figures show no crosshair


def test_the_context_section_is_one_figure_with_one_crosshair_through_its_rows(bias_report, tmp_path):
    """The mode and where a fault could not be seen are rows of one figure on one x axis (ctx-time)."""
    page = tmp_path / "report.html"
    render_report(bias_report, page, plotlyjs=tmp_path / "js")
    text = page.read_text(encoding="utf-8")
    nis = """document.querySelector('.ls-section[aria-label^="nis"]')"""
    probe = HOVER.replace(nis, 'document.getElementById("ctx-time")')
    page.write_text(text.replace("</body>", probe + "</body>", 1), encoding="utf-8")
    hover, dom = first_screen(page, tmp_path / "profile", "data-hover")
    assert js_errors(dom) == ""
    assert re.search(r'id="ctx-time" data-rows="2" data-row-ids="ctx-mode ctx-observability"', dom)
    rows, spikes = hover["rows"], hover["spikes"]
    assert len(rows) == 2
    top, bottom = rows[0][1], rows[-1][2]
    assert spikes and len({round(left) for left, _, _ in spikes}) == 1
    assert min(s[1] for s in spikes) <= top + 1 and max(s[2] for s in spikes) >= bottom - 1  # through both rows
    assert "/flight_mode/mode" in hover["label"]
    assert hover["other"] == 0
