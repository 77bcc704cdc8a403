"""HTML report: size bounds on a 1-hour 100 Hz grid, plotly.js once, escaping, alarm table, truth."""

from __future__ import annotations

import base64
import html
import json
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from logscan.errors import InputError
from logscan.report import ReportInput, flat_alarms, render_html, render_report, report_matches
from logscan.report.decimate import DEFAULT_MAX_POINTS
from logscan.report.page_assets import report_js
from logscan.results import DetectorResult, FaultEvent
from logscan.verdict.incidents import signal_label

HOSTILE = "<script>alert(1)</script>"
HOSTILE_SHOWN = "&lt;script&gt;alert(1)&lt;/script&gt;"  # as plotly receives it: text, not markup
GRID_N = 360_000  # 1 hour at 100 Hz
BIAS_START = 2000.0  # ground-truth fault, seconds
OWN_SCRIPTS = 4 + bool(report_js())  # error recorder, plotly.js, figure JSON, drawing, report.js


def make_report(n: int = GRID_N, *, truth: bool = True, hostile: bool = True, seed: int = 0) -> ReportInput:
    """A report from detector results shaped like the encoded and NIS detectors', with known alarms.

    e_x: noise with a spike burst at 2000.5 s (matches the truth event) and at 100 s (false alarm)
    and a NaN gap; e_v: a slow walk inside a constant band; a 12-column coding vector; NIS: three
    groups (one named HOSTILE, one at 10 Hz: NaN between updates) and overall, with per-dof
    extras; the accel group exceeds at 2000.2 s.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    group = HOSTILE if hostile else "gyro"

    encoded = DetectorResult("encoded_ekf")
    e_x = rng.normal(0.0, 1.0, n)
    e_x[200_050:200_060] = 40.0  # 2000.50 s .. 2000.59 s
    e_x[10_000:10_005] = -35.0  # 100.00 s .. 100.04 s
    e_x[50_000:50_020] = np.nan  # a gap the figure must keep
    band = 5.0 + np.abs(np.sin(t / 50.0))
    encoded.add_statistic(t, "e_x", e_x, upper=band, lower=-band, n_persist=3)
    e_v = np.cumsum(rng.normal(0.0, 0.01, n))
    encoded.add_statistic(t, "e_v", e_v, upper=50.0, lower=-50.0, n_persist=3)
    encoded.extras["coding_vector"] = np.exp(np.cumsum(rng.normal(0, 1e-3, (n, 12)), axis=0))
    encoded.info["coverage"] = "catches bit flips and actuator faults; not accelerometer biases"

    nis = DetectorResult("nis")
    for name in ("accel", group, "gps", "all"):
        updated = np.ones(n, dtype=bool) if name != "gps" else (np.arange(n) % 10 == 0)  # gps: 10 Hz
        stat = np.where(updated, rng.chisquare(30, n), np.nan)  # like the NIS detector: NaN between updates
        if name == "accel":
            stat[200_020:200_040] = 500.0  # 2000.20 s .. 2000.39 s
        upper = np.where(updated, 90.0, np.nan)
        nis.add_statistic(t, f"nis.{name}", stat, upper=upper, valid=updated, n_persist=3)
        nis.extras[f"nis.{name}.per_dof"] = stat / 30.0

    facts = {
        "file": f"/logs/{HOSTILE}.mcap",
        "format": "mcap",
        "start_ns": 1_700_000_000_000_000_000,
        "end_ns": 1_700_000_000_000_000_000 + int((n - 1) * 1e7),
        "duration_s": (n - 1) * 0.01,
        "partial": False,
        "partial_reason": "",
        "topics": {f"/{group}/data": {}, "/imu": {}},
        "channels": {f"/{group}/data.x": {"samples": n, "unit": None}},
        "skipped": [],
        "warnings": [],
        "has_truth": truth,
        "has_profile": False,
    }
    events = [FaultEvent(BIAS_START, BIAS_START + 10, "imu-bias", "accel.x", magnitude=1.0)] if truth else []
    results = [encoded, nis]
    n_alarms = len(flat_alarms(results))
    return ReportInput(
        log_facts=facts,
        profile_text=f'[vehicle]\nmodel = "quadcopter"\n# {HOSTILE}\n',
        profile_source="profiles/quadcopter.toml",
        model={
            "name": "quadcopter",
            "states": [f"x{i}" for i in range(12)],
            "inputs": ["thrust"],
            "groups": {"accel": {}},
            "params": {"mass": 1.2},
        },  # fmt: skip
        logscan_version="0.1.0",
        t=t,
        results=results,
        truth_events=events,
        matches=None,
        verdict=f"{n_alarms} alarms",
        warnings=[f"topic {HOSTILE} has no schema"],
    )


class _Tables(HTMLParser):
    """Cells of the table with a given id: list of rows, each a list of cell texts."""

    def __init__(self, table_id: str):
        super().__init__()
        self.table_id, self.inside, self.rows, self.cell = table_id, False, [], None

    def handle_starttag(self, tag, attrs):
        if tag == "table" and dict(attrs).get("id") == self.table_id:
            self.inside = True
        elif self.inside and tag == "tr":
            self.rows.append([])
        elif self.inside and tag in ("td", "th"):
            self.cell = ""
        elif tag == "br" and self.cell is not None:  # a cell's second line (a statistic's words)
            self.cell += "\n"

    def handle_endtag(self, tag):
        if tag == "table":
            self.inside = False
        elif self.inside and tag in ("td", "th") and self.cell is not None:
            self.rows[-1].append(self.cell.strip())
            self.cell = None

    def handle_data(self, data):
        if self.cell is not None:
            self.cell += data


def table(html: str, table_id: str) -> list[list[str]]:
    parser = _Tables(table_id)
    parser.feed(html)
    return parser.rows


def figures(html: str) -> list[dict]:
    match = re.search(r'<script type="application/json" id="logscan-figures">(.*?)</script>', html, re.S)
    assert match, "figure JSON block missing"
    return json.loads(match.group(1))


def rows_of(spec: dict) -> dict[str, list[dict]]:
    """A figure's rows, title -> its traces: a detector section's figure has a row per statistic,
    sensor or extra on one time axis (titled by annotations above them; traces on the row's y axis
    or its span overlay); any other figure is one row titled by its title."""
    layout, data = spec["figure"]["layout"], spec["figure"]["data"]
    notes = layout.get("annotations") or []
    if not notes:
        return {layout["title"]["text"]: data}
    n = len(notes)
    out = {}
    for r, note in enumerate(notes, 1):
        title = re.sub(r"\s*<span.*$", "", note["text"]).replace("<b>", "").replace("</b>", "")
        axes = {f"y{'' if r == 1 else r}", f"y{n + r}"}
        out[title] = [trace for trace in data if trace.get("yaxis", "y") in axes]
    return out


def array(value) -> np.ndarray:
    if isinstance(value, dict):  # plotly typed-array encoding
        return np.frombuffer(base64.b64decode(value["bdata"]), dtype=np.dtype(value["dtype"]))
    return np.asarray(value, dtype=float)


@pytest.fixture(scope="module")
def hour_report() -> ReportInput:
    return make_report()


@pytest.fixture(scope="module")
def embedded(hour_report, tmp_path_factory) -> str:
    path = tmp_path_factory.mktemp("embed") / "report.html"
    render_report(hour_report, path)
    return path.read_text(encoding="utf-8")


def test_embedded_report_of_an_hour_is_under_6_mb_with_plotlyjs_once(embedded):
    size = len(embedded.encode("utf-8"))
    assert size < 6_000_000, size
    assert embedded.count("plotly.js v") == 1  # plotly.min.js's banner: embedded exactly once
    assert "Plotly.newPlot" in embedded
    assert not re.search(r"<script[^>]*\bsrc=", embedded)  # nothing to fetch: works offline


def test_directory_mode_writes_plotlyjs_once_and_reports_stay_small(hour_report, tmp_path):
    from plotly.offline import get_plotlyjs

    js_dir, out_dir = tmp_path / "assets", tmp_path / "reports"
    out_dir.mkdir()
    render_report(hour_report, out_dir / "a.html", plotlyjs=js_dir)
    written = js_dir / "plotly.min.js"
    assert written.read_text(encoding="utf-8") == get_plotlyjs()
    stamp = written.stat().st_mtime_ns
    render_report(hour_report, out_dir / "b.html", plotlyjs=js_dir)
    assert written.stat().st_mtime_ns == stamp  # identical: not rewritten
    assert sorted(p.name for p in js_dir.iterdir()) == ["plotly.min.js"]
    for name in ("a.html", "b.html"):
        page = (out_dir / name).read_text(encoding="utf-8")
        assert len(page.encode("utf-8")) < 300_000
        assert page.count('src="../assets/plotly.min.js"') == 1
        assert "plotly.js v" not in page


def test_plotlyjs_directory_that_is_a_file_is_a_clear_error(hour_report, tmp_path):
    not_a_dir = tmp_path / "file"
    not_a_dir.write_text("x")
    with pytest.raises(InputError, match="directory"):
        render_report(hour_report, tmp_path / "r.html", plotlyjs=not_a_dir)
    assert not (tmp_path / "r.html").exists()


def test_hostile_names_are_text_never_markup(embedded):
    assert HOSTILE not in embedded
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in embedded  # table, topics, profile, warnings
    # the name inside the figure JSON is HTML-escaped for plotly (which draws names as markup), so
    # after JSON decoding it is the escaped text plotly shows literally
    names = [trace.get("name", "") for fig in figures(embedded) for trace in fig["figure"]["data"]]
    assert f"nis.{HOSTILE_SHOWN}" in names and f"nis.{HOSTILE}" not in names
    block = re.search(r'id="logscan-figures">(.*?)</script>', embedded, re.S).group(1)
    assert "<" not in block and ">" not in block
    # exactly the page's own scripts: error recorder, plotly.js, figure JSON, drawing script,
    # and templates/report.js when there is one
    assert len(re.findall(r"<script\b", embedded, re.I)) == OWN_SCRIPTS


def test_alarm_table_lists_every_alarm_with_truth_match_and_latency(hour_report, embedded):
    rows = table(embedded, "alarm-table")
    header, body = rows[0], rows[1:]
    assert header[:9] == ["#", "detector", "signal / sensor", "start (s)", "end (s)", "duration (s)",
                          "peak", "threshold at peak", "peak / threshold"]  # fmt: skip
    assert header[9:] == ["matched ground-truth event", "latency (s)", "note"]
    alarms = flat_alarms(hour_report.results)
    assert len(body) == len(alarms) >= 3
    assert all("\n" not in cell for row in body for cell in row)  # one line per alarm
    # its plain words as the signal's tooltip
    title = html.escape(signal_label("e_x", "encoded_ekf"), quote=True)
    assert f'<td title="{title}">e_x</td>' in embedded
    assert [int(row[0]) for row in body] == list(range(1, len(body) + 1))  # numbered from 1
    for row, alarm in zip(body, alarms):
        assert row[1] == alarm.detector and row[2] == alarm.signal
        assert float(row[3]) == pytest.approx(alarm.start, abs=1e-3)
        assert float(row[5]) == pytest.approx(alarm.end - alarm.start, abs=2e-3)
    e_x_rows = [row for row in body if row[2] == "e_x"]
    assert [row[3] for row in e_x_rows] == ["100.020", "500.020", "2000.520"]  # n_persist = 3
    assert e_x_rows[1][6] == "NaN"  # the gap: a non-finite statistic is an exceedance
    assert [row[9] for row in e_x_rows[:2]] == ["none (false alarm)"] * 2
    burst = [row for row in body if row[2] == "e_x" and row[9] != "none (false alarm)"]
    assert len(burst) == 1 and burst[0][9] == "#1 imu-bias accel.x"
    assert float(burst[0][10]) == pytest.approx(0.52, abs=1e-6)  # 2000.52 - 2000.0
    accel = next(row for row in body if row[2] == "nis.accel")
    assert accel[9] == "#1 imu-bias accel.x" and float(accel[10]) == pytest.approx(0.22, abs=1e-6)
    assert float(accel[6]) == 500.0 and float(accel[7]) == 90.0


def test_truth_columns_and_table_appear_only_with_truth():
    page = render_html(make_report(60_000, truth=False, hostile=False), plotlyjs_src="plotly.min.js")
    header = table(page, "alarm-table")[0]
    assert len(header) == 10 and "latency (s)" not in header
    assert 'id="truth-table"' not in page and "ground truth" not in json.dumps(figures(page))


def test_report_matches_follow_scoring(hour_report):
    matches = report_matches(hour_report.results, hour_report.truth_events)
    alarms = flat_alarms(hour_report.results)
    assert len(matches) == len(alarms)
    for alarm, match in zip(alarms, matches):
        if alarm.start < BIAS_START:
            assert match == {"event": None, "latency_s": None}
        else:
            assert match["event"] == 0 and match["latency_s"] == pytest.approx(alarm.start - BIAS_START)


def test_every_trace_is_decimated_and_keeps_alarm_edges_and_gaps(hour_report, embedded):
    figs = figures(embedded)
    ids = [fig["id"] for fig in figs]
    assert ids == [f"fig-{i}" for i in range(len(figs))]
    for fig_id in ids:
        assert f'id="{fig_id}"' in embedded
    total = 0
    for fig in figs:
        for trace in fig["figure"]["data"]:
            n = array(trace["x"]).size
            assert n <= DEFAULT_MAX_POINTS
            total += n
    assert total < 40_000  # the whole page's point budget, not 360,000 per series
    e_x = next(tr for fig in figs for tr in fig["figure"]["data"] if tr.get("name") == "e_x")
    x, y = array(e_x["x"]), array(e_x["y"])
    full = hour_report.results[0].series["e_x"]
    edges = [edge for a in flat_alarms(hour_report.results) if a.signal == "e_x" for edge in (a.start, a.end)]
    drawable = [edge for edge in edges if np.isfinite(full[round(edge * 100)])]  # not inside the gap
    assert len(drawable) == 4
    for edge in drawable:
        assert np.isclose(x, edge, atol=1e-3).any(), f"alarm edge {edge} missing"
    assert np.isnan(y[(x >= 499.0) & (x <= 501.0)]).any()  # the NaN gap at 500 s still breaks the line
    assert np.nanmax(y) == 40.0 and np.nanmin(y) == -35.0  # spikes kept exactly


def test_figures_per_detector_view(embedded):
    specs = figures(embedded)
    assert len(specs) == 2  # one figure per detector section
    by_title = {title: traces for spec in specs for title, traces in rows_of(spec).items()}
    assert list(rows_of(specs[0])) == ["encoded_ekf: e_x", "encoded_ekf: e_v", "encoded_ekf: coding_vector"]
    assert list(rows_of(specs[1])) == ["nis: statistic / threshold", "nis: per_dof"]
    cv_names = [tr["name"] for tr in by_title["encoded_ekf: coding_vector"] if tr["name"].startswith("x")]
    assert cv_names == [f"x{i}" for i in range(12)]  # labelled with the model's states
    spans = {tr["name"] for tr in by_title["encoded_ekf: e_x"] if tr.get("fill") == "toself"}
    assert spans == {"alarm"}  # the row's own alarms; the ground truth is shaded once across the figure
    shapes = specs[0]["figure"]["layout"]["shapes"]
    assert shapes and all(s["yref"] == "paper" and (s["y0"], s["y1"]) == (0, 1) for s in shapes)
    ratio = next(tr for tr in by_title["nis: statistic / threshold"] if tr["name"] == "nis.accel")
    assert np.nanmax(array(ratio["y"])) == pytest.approx(500.0 / 90.0, rel=1e-6)
    per_dof = [tr["name"] for tr in by_title["nis: per_dof"] if tr.get("fill") != "toself"]
    assert per_dof == ["nis.accel", f"nis.{HOSTILE_SHOWN}", "nis.gps", "nis.all"]


def test_a_section_is_one_figure_with_its_rows_on_one_time_axis(embedded):
    """Every row of a section's figure plots against the one x axis, which draws one spike line
    across the rows; the page hovers every row at once."""
    for spec in figures(embedded):
        layout, data = spec["figure"]["layout"], spec["figure"]["data"]
        assert {trace.get("xaxis", "x") for trace in data} == {"x"}
        assert not any(key.startswith("xaxis") and key != "xaxis" for key in layout)
        assert layout["xaxis"]["showspikes"] and layout["xaxis"]["spikemode"] == "across"
        assert layout["hovermode"] == "x unified" and layout["hoversubplots"] == "axis"
        rows = [key for key in layout if re.fullmatch(r"yaxis\d*", key) and "overlaying" not in layout[key]]
        domains = sorted(layout[key]["domain"] for key in rows)
        assert all(low[1] <= high[0] for low, high in zip(domains, domains[1:]))  # stacked, not overlapping
        assert len(rows) == len(layout["annotations"])  # a title above each row
        # each row's legend is one line in the band under its title, not beside the rows: long
        # channel names cannot squeeze the plots
        legends = [layout[key] for key in layout if re.fullmatch(r"legend\d*", key)]
        assert len(legends) == len(rows) and all(g["orientation"] == "h" and g["x"] == 0 for g in legends)
        assert layout["margin"]["r"] <= 20


def test_a_long_channel_name_is_shortened_in_its_legend_and_whole_in_its_hover():
    from logscan.report.stacked import LEGEND_NAME_CHARS, legend_name

    long = "sensor_combined/accelerometer_m_s2[0] &lt;x&gt; integrated"
    trace = {"name": long, "hovertemplate": "%{y:.4g}"}
    legend_name(trace)
    assert len(trace["name"].replace("&lt;", "<").replace("&gt;", ">")) <= LEGEND_NAME_CHARS
    assert trace["name"].startswith("sensor_combined/acc") and trace["name"].endswith("integrated")
    assert trace["hovertemplate"] == f"{long}: %{{y:.4g}}<extra></extra>"
    short = {"name": "nis.&lt;script&gt;alert(1)&lt;/script&gt;"}  # 29 characters shown
    legend_name(short)
    assert short["name"] == "nis.&lt;script&gt;alert(1)&lt;/script&gt;"


def test_a_sparse_statistic_is_drawn_as_a_line_not_as_gaps(embedded):
    """A 10 Hz group's statistic is NaN 9 steps in 10 on the grid: draw its defined samples joined."""
    ratio = next(
        tr for spec in figures(embedded) for title, traces in rows_of(spec).items() for tr in traces
        if title == "nis: statistic / threshold" and tr["name"] == "nis.gps"
    )  # fmt: skip
    y = array(ratio["y"])
    assert y.size > 1000 and np.isfinite(y).all()


def test_header_facts_profile_model_and_verdict(embedded):
    facts = dict(row for row in table(embedded, "log-facts") if len(row) == 2)
    assert facts["format"] == "mcap" and facts["duration"] == "3599.99 s"
    assert facts["span"].startswith("2023-11-14T22:13:20.000 UTC")
    assert facts["partial read"] == "no"
    assert '<details id="profile">' in embedded and 'model = "quadcopter"' in embedded.replace("&#34;", '"')
    assert 'class="verdict alarm"' in embedded and "Verdict: " in embedded
    assert 'content="logscan 0.1.0"' in embedded
    assert "<strong>What it can and cannot see:</strong> catches bit flips" in embedded


def test_partial_read_and_clean_run_show_in_the_verdict():
    report = make_report(5_000, truth=False, hostile=False)
    report.log_facts.update(partial=True, partial_reason="truncated chunk at byte 1234")
    report.verdict = "partial input"
    page = render_html(report, plotlyjs_src="p.js")
    assert 'class="verdict partial"' in page and "truncated chunk at byte 1234" in page
    clean = make_report(5_000, truth=False, hostile=False)
    clean.results = [DetectorResult("encoded_ekf")]
    clean.verdict = "no alarms"
    page = render_html(clean, plotlyjs_src="p.js")
    assert 'class="verdict ok"' in page and 'id="no-alarms"' in page


def test_a_series_off_the_grid_is_reported_not_fatal():
    report = make_report(5_000, truth=False, hostile=False)
    broken = DetectorResult("plugin")
    broken.series["bad"] = np.zeros(10)
    report.results.append(broken)
    page = render_html(report, plotlyjs_src="p.js")
    assert "statistic &#39;bad&#39; has shape (10,), the grid has 5000 steps: not drawn" in page


def test_rendering_is_deterministic():
    report = make_report(20_000)
    assert render_html(report, plotlyjs_src="p.js") == render_html(report, plotlyjs_src="p.js")


def test_module_is_importable_without_rendering():
    # the template ships inside the package (logscan.templates)
    import logscan.templates

    assert (Path(logscan.templates.__file__).parent / "report.html.j2").is_file()


def test_a_real_log_with_script_topic_names_shows_them_as_text(tmp_path):
    """End to end from an MCAP file: the reader's topic and channel names reach the page as text."""
    try:
        from logscan.readers import read_log
        from logscan.readers.mcap import TopicData, write_mcap
    except ImportError as exc:  # pragma: no cover - only while the MCAP stack is missing
        pytest.skip(f"MCAP reader/writer missing: {exc}")
    t_ns = np.arange(500, dtype=np.int64) * 10_000_000
    topic = f"/{HOSTILE}"
    path = tmp_path / "hostile.mcap"
    write_mcap(path, {topic: TopicData("x/msg/Y", t_ns, {"value": np.sin(t_ns / 1e9)})})
    log = read_log(str(path))
    channel = next(iter(log.channels))
    assert HOSTILE in channel
    grid = (t_ns - t_ns[0]) / 1e9
    result = DetectorResult("probe")
    values = log.channels[channel].values.copy()
    values[200:210] = 5.0
    result.add_statistic(grid, channel, values, upper=2.0, n_persist=3)
    page = render_html(
        ReportInput(log.summary(), "", "embedded", {}, "0.1.0", grid, [result], verdict="1 alarms"),
        plotlyjs_src="plotly.min.js",
    )
    assert HOSTILE not in page
    escaped = "&lt;script&gt;alert(1)&lt;/script&gt;"
    assert f"<li>/{escaped}</li>" in page  # topic list
    assert f"<td>/{escaped}/value</td>" in page  # alarm table: signal names the channel
    assert len(re.findall(r"<script\b", page, re.I)) == OWN_SCRIPTS


def test_warm_up_transient_does_not_squash_the_judged_view():
    n = 6_000
    t = np.arange(n) * 0.01
    e_v = np.random.default_rng(3).normal(0.0, 0.01, n)
    e_v[:50] = -100.0  # filter settling, before the band exists
    band = np.where(t >= 1.0, 0.05, np.nan)
    band[100:103] = 30.0  # the first adaptive windows are wide
    e_v[3000:3005] = 2.0  # a fault: its peak stays in view
    result = DetectorResult("encoded_ekf")
    result.add_statistic(t, "e_v", e_v, upper=band, lower=-band, valid=np.isfinite(band), n_persist=3)
    report = make_report(n, truth=False, hostile=False)
    report.results = [result]
    layout = figures(render_html(report, plotlyjs_src="p.js"))[0]["figure"]["layout"]
    low, high = layout["yaxis"]["range"]
    assert len(result.alarms) == 1
    assert -0.2 < low < -0.05 and 2.0 < high < 2.2  # band, judged values and the alarm peak, padded
    result.series["e_v"][:50] = 0.0  # no transient: plotly's autorange
    result.thresholds["e_v"].upper[100:103] = 0.05
    result.thresholds["e_v"].lower[100:103] = -0.05
    assert "range" not in figures(render_html(report, plotlyjs_src="p.js"))[0]["figure"]["layout"]["yaxis"]
