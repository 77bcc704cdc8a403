"""The report in headless Chromium: every figure rendered, no JavaScript error, hostile names inert.

Runs Debian's ``chromium`` with ``--dump-dom`` after a virtual-time budget. The page's own inline
script records window errors, unhandled rejections and console.error into ``<pre id="js-errors">``
and sets ``<body data-plots-rendered="N">`` once every ``Plotly.newPlot`` promise resolved.
Skipped (with the reason) when no Chromium is installed; CI installs it in ``.ci/run``.
"""

from __future__ import annotations

import html
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from test_report import HOSTILE, figures, make_report

from logscan.report import render_report

CHROMIUM = next(
    (
        p
        for p in ("/usr/bin/chromium", shutil.which("chromium"), shutil.which("chromium-browser"))
        if p and Path(p).is_file()
    ),
    None,
)

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (Debian: apt-get install -y chromium)"),
]


def start_chromium(page: Path, profile_dir: Path) -> subprocess.Popen:
    """Chromium dumping the DOM after the page ran (virtual time: timers settle deterministically)."""
    command = [
        CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        "--disable-dev-shm-usage", f"--user-data-dir={profile_dir}", "--virtual-time-budget=10000",
        "--enable-logging=stderr", "--v=0", "--dump-dom", page.resolve().as_uri(),
    ]  # fmt: skip
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def finish(process: subprocess.Popen) -> tuple[str, str]:
    """The dumped DOM and Chromium's stderr."""
    try:
        stdout, stderr = process.communicate(timeout=90)
    except subprocess.TimeoutExpired:
        process.kill()
        process.communicate()
        raise AssertionError("chromium did not finish within 90 s") from None
    assert process.returncode == 0, f"chromium failed ({process.returncode}): {stderr[-2000:]}"
    return stdout, stderr


def dump_dom(page: Path, profile_dir: Path) -> tuple[str, str]:
    return finish(start_chromium(page, profile_dir))


def js_errors(dom: str) -> str:
    match = re.search(r'<pre id="js-errors"[^>]*>(.*?)</pre>', dom, re.S)
    assert match, "the error recorder element is missing from the DOM"
    return html.unescape(match.group(1)).strip()


def console_errors(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if "Uncaught" in line or ":CONSOLE" in line and "rror" in line]


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> dict[str, tuple[str, str, str]]:
    """One-hour report in both plotly.js modes: {mode: (source html, dumped DOM, stderr)}."""
    root = tmp_path_factory.mktemp("browser")
    report = make_report(60_000)  # 10 minutes: the same figures and point budget as an hour
    pages, running = {}, {}
    for mode, option in (("embed", "embed"), ("directory", root / "assets")):
        (root / mode).mkdir()
        pages[mode] = root / mode / "report.html"
        render_report(report, pages[mode], plotlyjs=option)
        running[mode] = start_chromium(pages[mode], root / f"profile-{mode}")  # both run at once
    return {mode: (pages[mode].read_text(encoding="utf-8"), *finish(proc)) for mode, proc in running.items()}


@pytest.mark.parametrize("mode", ["embed", "directory"])
def test_every_figure_renders_without_javascript_errors(rendered, mode):
    source, dom, stderr = rendered[mode]
    assert js_errors(dom) == ""
    assert console_errors(stderr) == []
    specs = figures(source)
    assert len(specs) >= 4
    assert f'data-plots-rendered="{len(specs)}"' in dom  # every Plotly.newPlot promise resolved
    for spec in specs:
        start = dom.index(f'id="{spec["id"]}"')
        block = dom[start : start + 4000]
        assert "plot-container plotly" in block and 'class="main-svg"' in block, spec["id"]
    # the statistic lines were drawn: one scatter layer per figure with SVG paths in it
    assert dom.count('class="scatterlayer mlayer"') >= len(specs)
    assert len(re.findall(r'<path class="js-line"', dom)) >= len(specs)


def test_hostile_names_stay_text_in_the_browser(rendered):
    _, dom, _ = rendered["embed"]
    assert HOSTILE not in dom  # never became an element
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in dom  # shown as text (tables, legend)
    assert len(re.findall(r"<script\b", dom, re.I)) == 4  # only the page's own scripts


def test_the_error_recorder_catches_failures(tmp_path):
    """The checks above could fail: a missing plotly.min.js and a throwing script are caught."""
    page = tmp_path / "report.html"
    render_report(make_report(2_000, truth=False, hostile=False), page, plotlyjs=tmp_path / "js")
    (tmp_path / "js" / "plotly.min.js").unlink()  # e.g. a report copied without its assets
    text = page.read_text(encoding="utf-8")
    page.write_text(text.replace("</body>", "<script>undefinedFunction42();</script></body>"))
    dom, stderr = dump_dom(page, tmp_path / "profile")
    errors = js_errors(dom)
    assert "failed to load" in errors and "plotly.js did not load" in errors
    assert "Uncaught ReferenceError: undefinedFunction42 is not defined" in errors
    assert any("undefinedFunction42" in line for line in console_errors(stderr))
    assert not re.search(r'data-plots-rendered="\d+"', dom)
