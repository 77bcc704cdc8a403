"""The analysis report of one log: build time, size, figure count and page height in headless Chromium.

    python bench/bench_report_page.py sample_logs/quad_imu_bias.mcap [--out DIR] [--screenshot]

Analyses the log once (not timed), then renders its report with ``--plotlyjs`` shared (plotly.min.js
beside the page, as `logscan analyze --plotlyjs DIR` writes it) five times and prints the best time,
the page's size, how many figures it draws, and, with Chromium installed, the page's height at a
1400 px wide window after every figure is drawn (the page's own `<body data-plots-rendered>`).
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


def chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


def browser(page: Path, *options: str) -> str:
    with tempfile.TemporaryDirectory() as profile:
        command = [
            chromium() or "chromium", "--headless", "--no-sandbox", "--disable-gpu", "--window-size=1400,900",
            f"--user-data-dir={profile}", "--virtual-time-budget=20000", *options, page.resolve().as_uri(),
        ]  # fmt: skip
        return subprocess.run(command, capture_output=True, text=True, timeout=180).stdout


def page_height(page: Path) -> int | None:
    probe = page.with_name(page.stem + ".probe.html")
    probe.write_text(page.read_text(encoding="utf-8").replace("</body>", PROBE, 1), encoding="utf-8")
    match = re.search(r'data-page-height="(\d+)"', browser(probe, "--dump-dom"))
    probe.unlink()
    return int(match.group(1)) if match else None


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log")
    parser.add_argument("--out", default=None, help="directory for the page (default: a temporary one)")
    parser.add_argument("--screenshot", action="store_true", help="also the first screen, 1400x900")
    args = parser.parse_args(argv)
    out = Path(args.out or tempfile.mkdtemp(prefix="logscan-report-"))
    out.mkdir(parents=True, exist_ok=True)
    page = out / (Path(args.log).stem + ".html")
    analysis = analyze_log(args.log, sensor_views=True, free_series=True)
    analysis.prepared.release_series()
    report = analysis.report_input()
    times = []
    for _ in range(5):
        start = time.perf_counter()
        render_report(report, page, plotlyjs=out / "js")
        times.append(time.perf_counter() - start)
    text = page.read_text(encoding="utf-8")
    n_figures = len(json.loads(re.search(r'id="logscan-figures">(.*?)</script>', text, re.S).group(1)))
    row = {"log": Path(args.log).name, "build_s": round(min(times), 3), "kb": round(len(text.encode()) / 1024),
           "figures": n_figures, "page": str(page)}  # fmt: skip
    if chromium():
        row["height_px"] = page_height(page)
        if args.screenshot:
            browser(page, f"--screenshot={out / (page.stem + '.png')}")
            row["screenshot"] = str(out / (page.stem + ".png"))
    print(json.dumps(row))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
