"""The analysis report of one log: build time, size, figure count and page height in headless Chromium.

    python bench/bench_report_page.py sample_logs/quad_imu_bias.mcap [--out DIR] [--screenshot]

Analyses the log once (not timed; glibc's allocator set up as the CLI sets it), then renders its
report with ``--plotlyjs`` shared (plotly.min.js beside the page, as `logscan analyze --plotlyjs DIR`
writes it) five times and prints the best time (wall, and the process' CPU time: on a loaded machine
the wall time is the other processes' too), the page's size, how many figures it draws, and, with
Chromium installed, the page's height at a 1400 px wide window after every figure is drawn (the
page's own `<body data-plots-rendered>`) and the time a click on the first incident row takes to
zoom every figure (the median of five: the JavaScript the click runs, every `Plotly.relayout`
included).
``--screenshot`` also writes the first screen (1400x900) as DIR/<log>.png.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from logscan.memory import reuse_freed_arrays
from logscan.pipeline import analyze_log
from logscan.report.page import render_report

# appended to the page: writes the document's height once every figure is drawn
PROBE = """<script>
(function () {
  function done() {
    var h = Math.max(document.documentElement.scrollHeight, document.body.scrollHeight);
    document.body.setAttribute("data-page-height", String(h));
  }
  var observer = new MutationObserver(function () {
    if (document.body.hasAttribute("data-plots-rendered")) { observer.disconnect(); done(); }
  });
  if (document.body.hasAttribute("data-plots-rendered")) { done(); }
  else { observer.observe(document.body, { attributes: true, attributeFilter: ["data-plots-rendered"] }); }
})();
</script></body>"""


# appended to the page: times a click on the first incident (or alarm) row, then "reset zoom", five
# times, as soon as report.js has linked the time axes; writes the click times (ms). Synchronous, in
# the page's first task: headless Chromium's virtual time (--virtual-time-budget) stops the page's
# clocks between tasks, and plotly's relayout does its work before it returns.
ZOOM_PROBE = """<script>
(function () {
  function run() {
    var row = document.querySelector("#incident-table tbody tr, #alarm-table tbody tr"), times = [];
    for (var i = 0; row && i < 5; i++) {
      var t0 = performance.now();
      row.click();
      times.push(performance.now() - t0);
      document.getElementById("ls-reset-zoom").click();
    }
    document.body.setAttribute("data-zoom-ms", JSON.stringify(times));
  }
  if (document.body.hasAttribute("data-time-axis")) { run(); return; }
  var observer = new MutationObserver(function () {
    if (document.body.hasAttribute("data-time-axis")) { observer.disconnect(); run(); }
  });
  observer.observe(document.body, { attributes: true, attributeFilter: ["data-time-axis"] });
})();
</script></body>"""


def chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


def browser(page: Path, *options: str) -> str:
    with tempfile.TemporaryDirectory() as profile:
        command = [
            chromium() or "chromium", "--headless", "--no-sandbox", "--disable-gpu", "--window-size=1400,900",
            f"--user-data-dir={profile}", "--virtual-time-budget=20000", *options, page.resolve().as_uri(),
        ]  # fmt: skip
        return subprocess.run(command, capture_output=True, text=True, timeout=180).stdout


def probed(page: Path, probe_script: str, attribute: str) -> str | None:
    """The value the probe script wrote into ``<body attribute>`` once the page ran."""
    probe = page.with_name(page.stem + ".probe.html")
    probe.write_text(page.read_text(encoding="utf-8").replace("</body>", probe_script, 1), encoding="utf-8")
    match = re.search(rf'{attribute}="([^"]*)"', browser(probe, "--dump-dom"))
    probe.unlink()
    return match.group(1) if match else None


def page_height(page: Path) -> int | None:
    value = probed(page, PROBE, "data-page-height")
    return None if value is None else int(value)


def zoom_ms(page: Path) -> float | None:
    """The median of five clicks on the first incident (or alarm) row, ms until every figure moved."""
    value = probed(page, ZOOM_PROBE, "data-zoom-ms")
    times = json.loads(value.replace("&quot;", '"')) if value else []
    return round(float(sorted(times)[len(times) // 2]), 1) if times else None


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log")
    parser.add_argument("--out", default=None, help="directory for the page (default: a temporary one)")
    parser.add_argument("--screenshot", action="store_true", help="also the first screen, 1400x900")
    args = parser.parse_args(argv)
    out = Path(args.out or tempfile.mkdtemp(prefix="logscan-report-"))
    out.mkdir(parents=True, exist_ok=True)
    page = out / (Path(args.log).stem + ".html")
    reuse_freed_arrays()  # as the CLI does: freed arrays reused, not returned to the system and faulted in again
    analysis = analyze_log(args.log, sensor_views=True, free_series=True)
    analysis.prepared.release_series()
    report = analysis.report_input()
    times, cpu = [], []
    for _ in range(5):
        start, start_cpu = time.perf_counter(), time.process_time()
        render_report(report, page, plotlyjs=out / "js")
        times.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    text = page.read_text(encoding="utf-8")
    n_figures = len(json.loads(re.search(r'id="logscan-figures">(.*?)</script>', text, re.S).group(1)))
    row = {"log": Path(args.log).name, "build_s": round(min(times), 3), "build_cpu_s": round(min(cpu), 3),
           "kb": round(len(text.encode()) / 1024), "figures": n_figures, "page": str(page)}  # fmt: skip
    if chromium():
        row["height_px"] = page_height(page)
        row["click_zoom_ms"] = zoom_ms(page)
        if args.screenshot:
            browser(page, f"--screenshot={out / (page.stem + '.png')}")
            row["screenshot"] = str(out / (page.stem + ".png"))
    print(json.dumps(row))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
