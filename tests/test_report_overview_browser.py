"""Margin rows in headless Chromium: clicking one opens its folded detector section and zooms every
time-series figure to the moment of the peak."""

from __future__ import annotations

import json
import re

import pytest
from test_report_browser import CHROMIUM, dump_dom, js_errors
from test_report_overview import quiet_and_alarming, report_of

from logscan.report import render_report

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (Debian: apt-get install -y chromium)"),
]

# once every figure is drawn: clicks the margin row of the quiet detector's e_x, then records whether
# its section opened and the x range of the section's figure
PROBE = """<script>
(function () {
  function probe() {
    if (!document.body.getAttribute("data-plots-rendered")) { setTimeout(probe, 50); return; }
    var row = Array.prototype.find.call(document.querySelectorAll("#margin-table tr[data-section]"), function (r) {
      return r.cells[0].textContent === "quiet";
    });
    var section = document.getElementById(row.getAttribute("data-section"));
    var before = section.open;
    row.click();
    setTimeout(function () {
      var plot = section.querySelector(".js-plotly-plot");
      document.body.setAttribute("data-probe", JSON.stringify(
        { before: before, after: section.open, range: plot.layout.xaxis.range }));
    }, 1000);
  }
  probe();
})();
</script>
"""


def test_a_margin_row_opens_its_section_at_the_peak(tmp_path):
    results = quiet_and_alarming()
    results[0].series["e_x"][555] = 0.4  # quiet's peak: 0.4 of its threshold at 5.55 s
    path = tmp_path / "report.html"
    render_report(report_of(results, verdict="2 alarms"), path, plotlyjs=tmp_path / "js")
    page = path.read_text(encoding="utf-8")
    assert re.search(r'<tr class="" data-start="5.55" data-end="5.55" data-section="detector-3"><td>quiet', page)
    path.write_text(page.replace("</body>", PROBE + "</body>"), encoding="utf-8")
    dom, _ = dump_dom(path, tmp_path / "profile")
    assert js_errors(dom) == ""
    probe = json.loads(re.search(r"data-probe=\"([^\"]*)\"", dom).group(1).replace("&quot;", '"'))
    assert (probe["before"], probe["after"]) == (False, True)
    low, high = probe["range"]
    assert low < 5.55 < high and high - low < 9.0  # zoomed around the peak, not the whole 10 s
