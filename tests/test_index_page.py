"""The fleet index page (`logscan analyze LOGS -o DIR/` writes DIR/index.html): one row per log with
its verdict, alarm counts per detector and a link to its report that resolves, failed logs with
their reason; sortable and filterable in headless Chromium."""

from __future__ import annotations

import html
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

CHROMIUM = next(
    (p for p in ("/usr/bin/chromium", shutil.which("chromium")) if p and Path(p).is_file()), None
)  # fmt: skip

PROBE = """<script>
window.addEventListener("load", function () {
  var th = Array.prototype.find.call(document.querySelectorAll("#logs th"), function (h) {
    return h.textContent === "alarms"; });
  th.click(); th.click();  /* descending: the log with the most alarms first */
  var out = document.createElement("pre"); out.id = "probe";
  out.textContent = document.querySelector("#logs tbody tr").cells[0].textContent;
  document.body.appendChild(out);
});
</script>"""


@pytest.fixture(scope="module")
def index(tmp_path_factory):
    from conftest import SAMPLES

    root = tmp_path_factory.mktemp("index")
    logs = [SAMPLES / "quad_healthy.mcap", SAMPLES / "quad_imu_bias.mcap", root / "missing.mcap"]
    if not logs[0].exists():
        pytest.skip("sample logs missing")
    done = subprocess.run(
        [sys.executable, "-m", "logscan", "analyze", *map(str, logs), "-o", f"{root / 'reports'}/",
         "--plotlyjs", str(root / "reports"), "-q"], capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr  # the missing file
    return root / "reports" / "index.html"


def test_every_log_has_a_row_and_every_link_resolves(index):
    text = index.read_text(encoding="utf-8")
    links = re.findall(r'href="([^"]+)"', text)
    assert sorted(links) == ["quad_healthy.report.html", "quad_imu_bias.report.html"]
    assert all((index.parent / html.unescape(link)).is_file() for link in links)
    assert "could not be analysed" in text and "missing.mcap" in text
    assert re.search(r"<th>nis</th>", text) and "14 alarms in 1 incident" in text


@pytest.mark.slow
@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed")
def test_the_index_sorts_in_the_browser(index, tmp_path):
    page = tmp_path / "index.html"
    page.write_text(index.read_text(encoding="utf-8").replace("</body>", PROBE + "</body>"), encoding="utf-8")
    for name in ("quad_healthy.report.html", "quad_imu_bias.report.html"):
        shutil.copy2(index.parent / name, tmp_path / name)
    done = subprocess.run(
        [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", f"--user-data-dir={tmp_path / 'profile'}",
         "--virtual-time-budget=5000", "--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=90,
    )  # fmt: skip
    probe = re.search(r'<pre id="probe">(.*?)</pre>', done.stdout, re.S)
    assert probe and probe.group(1) == "quad_imu_bias.mcap"
    assert "Uncaught" not in done.stderr
