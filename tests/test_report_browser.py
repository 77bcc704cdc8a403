"""The report in headless Chromium: every figure rendered, no JavaScript error, hostile names inert,
one time axis (zoom one figure, all follow; an incident or alarm row zooms them all; reset returns).

Runs Debian's ``chromium`` with ``--dump-dom`` after a virtual-time budget. The page's own inline
script records window errors, unhandled rejections and console.error into ``<pre id="js-errors">``
and sets ``<body data-plots-rendered="N">`` once every ``Plotly.newPlot`` promise resolved.
Interactions are driven by a probe script appended to the page (`PROBE`): it acts as a user would
(a mouse drag on a plot, a click on a row, Enter on a focused row) and writes every time-series
figure's x range after each step into the DOM, which the tests read from the dump.
Skipped (with the reason) when no Chromium is installed; CI installs it in ``.ci/run``.
"""

from __future__ import annotations

import html
import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from test_report import HOSTILE, OWN_SCRIPTS, figures, make_report
from test_run_context import sample_context

from logscan.report import render_report
from logscan.verdict.incidents import find_incidents

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


def report_with_incidents(n: int, **kwargs):
    """`make_report` with its incidents, a mode channel and a path (the "Context" figures)."""
    report = make_report(n, **kwargs)
    report.incidents = find_incidents(report.results, None, ["accel", "gps"])
    report.context = sample_context(n, hostile=kwargs.get("hostile", True))
    return report


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> dict[str, tuple[str, str, str]]:
    """One-hour report in both plotly.js modes: {mode: (source html, dumped DOM, stderr)}."""
    root = tmp_path_factory.mktemp("browser")
    report = report_with_incidents(60_000)  # 10 minutes: the same figures and point budget as an hour
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
    assert len(re.findall(r"<script\b", dom, re.I)) == OWN_SCRIPTS  # only the page's own scripts


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


# --- one time axis --------------------------------------------------------------------------------

PROBE = """<script>
/* test probe: acts as a user, writes every time-series figure's x range after each step */
(function () {
  function figs() { return Array.prototype.slice.call(document.querySelectorAll(".ls-timeseries")); }
  function record(step) {
    var out = document.createElement("pre");
    out.id = "probe-" + step;
    out.textContent = JSON.stringify({
      ranges: figs().map(function (el) { return el.layout.xaxis.autorange ? "auto" : el.layout.xaxis.range; }),
      folded: figs().map(function (el) { return !!el.closest("details:not([open])"); }),
      ids: figs().map(function (el) { return el.id; }),
      path: document.getElementById("ctx-path").layout.xaxis.autorange,
      events: figs().map(function (el) { return el.probeEvents; }),
      label: document.querySelector("#ls-zoom span").textContent,
      reset_disabled: document.getElementById("ls-reset-zoom").disabled,
      focused: document.activeElement === document.querySelector("#alarm-table tbody tr:last-child"),
      cursor: getComputedStyle(document.querySelector("#incident-table tbody tr")).cursor
    });
    document.body.appendChild(out);
  }
  function mouse(type, target, x, y) {
    target.dispatchEvent(new MouseEvent(type, {bubbles: true, cancelable: true, view: window,
      clientX: x, clientY: y, button: 0, buttons: type === "mouseup" ? 0 : 1}));
  }
  function drag() {  /* a box zoom over the middle fifth of the first figure's time axis */
    var box = document.querySelector(".ls-timeseries .nsewdrag"), r = box.getBoundingClientRect();
    var y = r.top + r.height / 2, x0 = r.left + 0.4 * r.width, x1 = r.left + 0.6 * r.width;
    mouse("mousedown", box, x0, y);
    mouse("mousemove", document, x0 + 20, y);
    mouse("mousemove", document, x1, y);
    mouse("mouseup", document, x1, y);
  }
  function doubleClick() {  /* plotly's own reset: a double click on the last figure's plot area */
    var all = document.querySelectorAll(".ls-timeseries .nsewdrag"), box = all[all.length - 1];
    var r = box.getBoundingClientRect(), x = r.left + r.width / 2, y = r.top + r.height / 2;
    [0, 1].forEach(function () { mouse("mousedown", box, x, y); mouse("mouseup", document, x, y); });
  }
  function enter() {
    var row = document.querySelector("#alarm-table tbody tr:last-child");
    row.focus();
    row.dispatchEvent(new KeyboardEvent("keydown", {key: "Enter", bubbles: true, cancelable: true}));
  }
  function clickPathMarker() {  /* plotly's click event on the path's first incident marker */
    var el = document.getElementById("ctx-path");
    var marks = el.data.filter(function (trace) { return trace.name === "incident start"; })[0];
    el.emit("plotly_click", {points: [{customdata: marks.customdata[0], pointIndex: 0}]});
  }
  function count() {  /* plotly_relayout events per figure: a feedback loop would run them up */
    figs().forEach(function (el) {
      el.probeEvents = 0;
      el.on("plotly_relayout", function () { el.probeEvents += 1; });
    });
  }
  var steps = [
    [null, count],
    ["start", drag],
    ["drag", function () { document.querySelector("#incident-table tbody tr").click(); }],
    ["incident", function () { document.getElementById("ls-reset-zoom").click(); }],
    ["reset", enter],
    ["enter", clickPathMarker],
    ["path", function () {  /* open every folded section: its figure catches up with the shared range */
      Array.prototype.forEach.call(document.querySelectorAll("details.detector"), function (d) { d.open = true; });
    }],
    ["opened", doubleClick],
    ["dblclick", function () {}]
  ];
  function run(i) {
    if (i >= steps.length) { document.body.setAttribute("data-probe-done", "1"); return; }
    if (steps[i][0]) { record(steps[i][0]); }
    try { steps[i][1](); } catch (err) { window.logscanError("probe: " + err.message); }
    setTimeout(function () { run(i + 1); }, 500);
  }
  var wait = setInterval(function () {
    if (document.body.hasAttribute("data-time-axis")) { clearInterval(wait); run(0); }
  }, 50);
})();
</script>"""


def probe_steps(dom: str) -> dict[str, dict]:
    found = re.findall(r'<pre id="probe-(\w+)">(.*?)</pre>', dom, re.S)
    return {step: json.loads(html.unescape(text)) for step, text in found}


def shown(step: dict) -> list:
    """The x ranges of the figures not inside a folded section (those follow when it opens)."""
    return [r for r, folded in zip(step["ranges"], step["folded"], strict=True) if not folded]


@pytest.fixture(scope="module")
def interacted(tmp_path_factory) -> tuple[dict, str, dict, str]:
    """The 10-minute report with the probe run: (report incidents/alarms, dumped DOM, steps, stderr)."""
    root = tmp_path_factory.mktemp("zoom")
    report = report_with_incidents(60_000, hostile=False)
    page = root / "report.html"
    render_report(report, page, plotlyjs=root / "assets")
    text = page.read_text(encoding="utf-8")
    head, tail = text.rsplit("</body>", 1)
    page.write_text(head + PROBE + "</body>" + tail, encoding="utf-8")
    dom, stderr = dump_dom(page, root / "profile")
    return report, dom, probe_steps(dom), stderr


def expected_zoom(start: float, end: float) -> list[float]:
    margin = max(2.0, 0.5 * (end - start))
    return [start - margin, end + margin]


def row_interval(dom: str, table_id: str, which: int) -> tuple[float, float]:
    body = re.search(rf'<table id="{table_id}">.*?<tbody>(.*?)</tbody>', dom, re.S).group(1)
    rows = re.findall(r'<tr data-start="([^"]+)" data-end="([^"]+)"', body)
    start, end = rows[which]
    return float(start), float(end)


def test_the_time_axis_works_without_javascript_errors(interacted):
    _, dom, steps, stderr = interacted
    assert js_errors(dom) == ""
    assert console_errors(stderr) == []
    assert 'data-probe-done="1"' in dom
    assert list(steps) == ["start", "drag", "incident", "reset", "enter", "path", "opened", "dblclick"]
    n_figures = int(re.search(r'data-time-axis="(\d+)"', dom).group(1))
    assert n_figures >= 3 and all(len(step["ranges"]) == n_figures for step in steps.values())


def test_zooming_one_figure_zooms_every_figure_once(interacted):
    _, _, steps, _ = interacted
    assert steps["start"]["ranges"] == ["auto"] * len(steps["start"]["ranges"])
    assert steps["start"]["reset_disabled"] and steps["start"]["label"] == "full time range"
    ranges = shown(steps["drag"])
    first = ranges[0]
    assert first != "auto" and 0 < first[0] < first[1]
    assert all(r == pytest.approx(first) for r in ranges)
    # each figure shown moved exactly once (one relayout per section): the followers' own relayout
    # events are not echoed back; a figure in a folded section is not moved until it opens
    folded = steps["drag"]["folded"]
    assert steps["drag"]["events"] == [0 if f else 1 for f in folded]
    assert any(folded) and all(r == "auto" for r, f in zip(steps["drag"]["ranges"], folded) if f)
    assert not steps["drag"]["reset_disabled"]
    assert steps["drag"]["label"] == f"time {first[0]:.2f} to {first[1]:.2f} s"


def test_clicking_the_first_incident_row_zooms_every_figure_around_it(interacted):
    report, dom, steps, _ = interacted
    incident = report.incidents[0]
    assert row_interval(dom, "incident-table", 0) == pytest.approx((incident.start, incident.end))
    expected = expected_zoom(incident.start, incident.end)
    for r in shown(steps["incident"]):
        assert r == pytest.approx(expected)
        assert r[0] < incident.start and incident.end < r[1]
    assert steps["incident"]["cursor"] == "pointer"


def test_reset_returns_every_figure_to_the_full_time_range(interacted):
    _, _, steps, _ = interacted
    assert steps["reset"]["ranges"] == ["auto"] * len(steps["reset"]["ranges"])
    assert steps["reset"]["reset_disabled"] and steps["reset"]["label"] == "full time range"


def test_enter_on_a_focused_alarm_row_zooms_every_figure_to_that_alarm(interacted):
    _, dom, steps, _ = interacted
    start, end = row_interval(dom, "alarm-table", -1)
    assert steps["enter"]["focused"]
    assert all(r == pytest.approx(expected_zoom(start, end)) for r in shown(steps["enter"]))
    body = re.search(r'<table id="alarm-table">.*?<tbody>(.*?)</tbody>', dom, re.S).group(1)
    rows = re.findall(r"<tr [^>]*>", body)
    assert rows and all('tabindex="0"' in row for row in rows)  # every row reachable by Tab


def test_the_mode_figure_follows_the_time_axis_and_the_path_does_not(interacted):
    _, _, steps, _ = interacted
    # the mode is a row of the Context section's one figure on the time axis (ctx-time)
    assert "ctx-time" in steps["drag"]["ids"] and "ctx-path" not in steps["drag"]["ids"]
    mode = steps["drag"]["ids"].index("ctx-time")
    assert steps["incident"]["ranges"][mode] == steps["incident"]["ranges"][0] != "auto"
    assert all(step["path"] is True for step in steps.values())  # x/y axes: never moved by time zoom


def test_clicking_an_incident_on_the_path_zooms_the_time_axis_to_it(interacted):
    report, _, steps, _ = interacted
    first = report.incidents[0]
    assert steps["enter"]["ranges"][0] != pytest.approx(expected_zoom(first.start, first.end))  # moved from
    assert all(r == pytest.approx(expected_zoom(first.start, first.end)) for r in shown(steps["path"]))
    # the folded sections, opened, catch up with it
    assert not any(steps["opened"]["folded"])
    assert all(r == pytest.approx(expected_zoom(first.start, first.end)) for r in steps["opened"]["ranges"])


def test_a_double_click_on_any_figure_returns_every_figure_to_the_full_range(interacted):
    _, _, steps, _ = interacted
    assert steps["opened"]["ranges"][-1] != "auto"
    assert steps["dblclick"]["ranges"] == ["auto"] * len(steps["dblclick"]["ranges"])
    assert steps["dblclick"]["reset_disabled"]
