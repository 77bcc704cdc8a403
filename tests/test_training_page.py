"""The training report of `logscan train` (logscan/report/training_page.py): from a real training on
the jackal sample, its lookup table, curves and knees match the tables document, hostile names stay
text, plotly.js is embedded once, the page stays small; in headless Chromium every figure renders
with no JavaScript error.
"""

from __future__ import annotations

import copy
import re

import numpy as np
import pytest
from conftest import SAMPLES
from test_report import HOSTILE, HOSTILE_SHOWN, array, figures, table
from test_report_browser import CHROMIUM, console_errors, dump_dom, js_errors

from logscan.detectors.base import decode_state_value, encode_state_value
from logscan.report.training_page import render_training_html, shared_parts

SAMPLE = SAMPLES / "jackal_healthy.mcap"
PAGE_SCRIPTS = 4  # error recorder, plotly.js, figure JSON, drawing
MAX_PAGE_BYTES = 1_500_000  # without plotly.js
CELL = re.compile(r"^(\S+) \((\d+)\)(?: · knee (\S+))?$")


@pytest.fixture(scope="module")
def document() -> dict:
    if not SAMPLE.exists():
        pytest.skip(f"{SAMPLE} missing (run sample_logs/make_samples.py)")
    from logscan.training.train import train_logs

    return train_logs([str(SAMPLE)], None)


@pytest.fixture(scope="module")
def page(document) -> str:
    return render_training_html(document)


def atfm_tables(document: dict) -> dict:
    state = next(s for s in document["detectors"] if s["detector"] == "atfm")
    return decode_state_value(state["state"]["tables_"])


def one_group(document: dict) -> tuple[str, dict]:
    tables = atfm_tables(document)
    assert tables, "the jackal profile trains at least one A-TFM group"
    return next(iter(tables.items()))


def hostile_document(document: dict) -> dict:
    """The document with a sensor, the group, the profile, a log and another detector named HOSTILE."""
    doc = copy.deepcopy(document)
    state = next(s for s in doc["detectors"] if s["detector"] == "atfm")
    tables = decode_state_value(state["state"]["tables_"])
    name, group = next(iter(tables.items()))
    group["sensors"][0] = HOSTILE
    state["state"]["tables_"] = encode_state_value({HOSTILE: group, **{k: v for k, v in tables.items() if k != name}})
    doc["profile_name"] = HOSTILE
    doc["training_logs"][0]["name"] = HOSTILE + ".mcap"
    doc["detectors"].append({
        "format": state.get("format"), "detector": "encoded_ekf", "schema_version": 1,
        "params": {"margin": 0.05, "note": HOSTILE},
        "state": {"threshold_": encode_state_value(np.array([3.5, 4.25])), HOSTILE: 1.0},
    })  # fmt: skip
    return doc


def curve_specs(page: str) -> list[dict]:
    return [spec for spec in figures(page) if any(tr.get("name") == "knees" for tr in spec["figure"]["data"])]


def test_the_analysis_reports_style_recorder_and_drawing_script_are_reused(page):
    parts = shared_parts()
    assert parts["style"].startswith("<style>") and "font-family" in parts["style"]
    assert "logscanError" in parts["recorder"]
    assert "logscan-figures" in parts["drawing"] and "data-plots-rendered" in parts["drawing"]
    for part in parts.values():
        assert part in page
    assert 'id="js-errors"' in page


def test_header_summarises_the_tables_file(document, page):
    assert "<h1>logscan training report</h1>" in page
    assert document["logscan_version"] in page
    assert document["profile_fingerprint"][:12] in page
    rows = table(page, "training-logs")
    assert rows[0] == ["log", "size", "SHA-256"]
    log = document["training_logs"][0]
    assert rows[1][0] == log["name"]
    assert f"{log['bytes']:,} bytes" in rows[1][1]
    assert rows[1][2] == log["sha256"][:12] + "…"


def test_lookup_table_cells_match_the_document(document, page):
    _, group = one_group(document)
    rows = table(page, "lookup-0")
    assert rows[0] == ["mode value", *group["sensors"]]
    assert len(rows) == 1 + len(group["modes"])
    raised = 0
    for r, row in enumerate(rows[1:]):
        assert float(row[0]) == pytest.approx(group["modes"][r], rel=1e-3)
        for i, cell in enumerate(row[1:]):
            match = CELL.match(cell)
            assert match, cell
            assert float(match.group(1)) == pytest.approx(group["eps"][r, i], rel=1e-3)
            assert int(match.group(2)) == group["e"][r, i]
            if group["eps"][r, i] > group["eps_knee"][r, i]:  # the envelope raised it: the knee shown
                raised += 1
                assert float(match.group(3)) == pytest.approx(group["eps_knee"][r, i], rel=1e-3)
            else:
                assert match.group(3) is None
    assert raised, "the jackal table has rows the envelope raised"


def test_eps_against_mode_value_figure(document, page):
    _, group = one_group(document)
    spec = figures(page)[0]["figure"]
    lines = [tr for tr in spec["data"] if tr["mode"] == "lines+markers"]
    knees = [tr for tr in spec["data"] if tr["marker"].get("symbol") == "circle-open"]
    assert [tr["name"] for tr in lines] == group["sensors"]
    for i, (line, knee) in enumerate(zip(lines, knees, strict=True)):
        np.testing.assert_allclose(array(line["x"]), group["modes"])
        np.testing.assert_allclose(array(line["y"]), group["eps"][:, i])
        np.testing.assert_allclose(array(knee["y"]), group["eps_knee"][:, i])


def test_one_curve_figure_per_sensor_and_mode(document, page):
    _, group = one_group(document)
    specs = curve_specs(page)
    assert len(specs) == len(group["modes"]) * len(group["sensors"])
    assert len(figures(page)) == 1 + len(specs)
    titles = [spec["figure"]["layout"]["title"]["text"] for spec in specs]
    expected = [f"{s} · mode {m:.4g}" for m in group["modes"] for s in group["sensors"]]
    assert titles == expected
    for spec in specs:
        assert f'id="{spec["id"]}"' in page
        assert spec["figure"]["layout"]["height"] <= 300
    assert page.count('class="muted caption"') >= len(specs)


def test_curves_and_knee_markers_match_the_training(document, page):
    _, group = one_group(document)
    specs = iter(curve_specs(page))
    w, windows = group["w"], group["windows"]
    for row in group["curves"]:
        for curve in row:
            fig = next(specs)["figure"]
            lines = [tr for tr in fig["data"] if tr["name"].startswith("w=")]
            assert [tr["name"] for tr in lines] == [f"w={x}" for x in windows]
            for k, (line, window) in enumerate(zip(lines, windows)):
                np.testing.assert_allclose(array(line["x"]), curve["eps"], rtol=1e-6)
                np.testing.assert_allclose(array(line["y"]), curve["counts"][:, k] / window, rtol=1e-6)
            knees = next(tr for tr in fig["data"] if tr["name"] == "knees")
            assert array(knees["x"]).tolist() == [k[1] for k in curve["knees"]]  # at the knee's eps
            np.testing.assert_allclose(array(knees["y"]), [k[2] / k[0] for k in curve["knees"]])
            at = windows.index(w)  # the detection window's knee emphasised
            assert knees["marker"]["symbol"][at] == "diamond"
            assert knees["marker"]["size"][at] > max(s for j, s in enumerate(knees["marker"]["size"]) if j != at)
            labels = [a["text"] for a in fig["layout"]["annotations"]]
            assert labels == [f"<b>w={x} knee</b>" if x == w else f"w={x} knee" for x in windows]
            eps_max = float(curve["eps"][-1])
            diagonal, half = fig["layout"]["shapes"]
            assert (diagonal["x0"], diagonal["y0"], diagonal["y1"], diagonal["line"]["dash"]) == (0, 1, 0, "dash")
            assert diagonal["x1"] == pytest.approx(eps_max)
            assert (half["y0"], half["y1"], half["line"]["dash"]) == (0.5, 0.5, "dot")


def test_hostile_names_stay_text(document):
    page = render_training_html(hostile_document(document))
    assert HOSTILE not in page
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in page  # in the tables and headings, as text
    assert len(re.findall(r"<script\b", page, re.I)) == PAGE_SCRIPTS
    assert table(page, "lookup-0")[0][1] == HOSTILE  # the parser unescapes: the name itself, as text
    specs = figures(page)
    assert specs[0]["figure"]["data"][0]["name"] == HOSTILE_SHOWN  # plotly shows it literally
    assert specs[1]["figure"]["layout"]["title"]["text"].startswith(HOSTILE_SHOWN)
    assert "encoded_ekf" in page and "3.5, 4.25" in page  # the other detector's trained values


def test_other_trained_detectors_are_listed(document):
    doc = copy.deepcopy(document)
    doc["detectors"] = [{
        "detector": "encoded_ekf", "schema_version": 1, "params": {"margin": 0.05, "variant": "baseline"},
        "state": {"threshold_": encode_state_value(np.float64(7.8125))},
    }]  # fmt: skip
    page = render_training_html(doc)
    assert table(page, "trained-0") == [["threshold_", "7.8125"]]
    params = table(page, "trained-params-0")
    assert ["variant", "baseline"] in params and ["margin", "0.05"] in params
    assert figures(page) == []


def test_plotlyjs_embedded_once_and_page_small(page):
    from plotly.offline import get_plotlyjs

    assert page.count("plotly.js v") == 1  # plotly.min.js's banner
    assert "<script src=" not in page  # self-contained: works offline
    size = len(page.encode("utf-8")) - len(get_plotlyjs().encode("utf-8"))
    assert size < MAX_PAGE_BYTES, size


def test_train_writes_the_report_beside_the_tables(cli, tmp_path):
    if not SAMPLE.exists():
        pytest.skip(f"{SAMPLE} missing")
    result = cli("train", SAMPLE, "-o", tmp_path / "jt.json", "-q")
    assert result.exit_code == 0, result.stderr
    page = (tmp_path / "jt.html").read_text(encoding="utf-8")
    assert "logscan training report" in page and len(curve_specs(page)) >= 1


@pytest.mark.slow
@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (Debian: apt-get install -y chromium)")
def test_every_figure_renders_in_chromium_without_javascript_errors(document, tmp_path):
    path = tmp_path / "tables.html"
    source = render_training_html(hostile_document(document))
    path.write_text(source, encoding="utf-8")
    dom, stderr = dump_dom(path, tmp_path / "profile")
    specs = figures(source)
    assert (js_errors(dom), console_errors(stderr)) == ("", [])
    assert re.search(r'data-plots-rendered="(\d+)"', dom).group(1) == str(len(specs))  # every newPlot resolved
    drawn = re.findall(r'id="(tf-\d+)"[^>]*><div class="plot-container plotly"', dom)
    assert drawn == [spec["id"] for spec in specs] and len(drawn) >= 2
    assert dom.count('class="main-svg"') >= len(specs)
    assert len(re.findall(r'<path class="js-line"', dom)) >= len(specs)
    assert HOSTILE not in dom
    assert len(re.findall(r"<script\b", dom, re.I)) == PAGE_SCRIPTS


def test_a_table_without_curves_shows_its_lookup_table(document):
    doc = copy.deepcopy(document)
    state = next(s for s in doc["detectors"] if s["detector"] == "atfm")
    tables = decode_state_value(state["state"]["tables_"])
    for group in tables.values():
        del group["curves"], group["eps_knee"]
    state["state"]["tables_"] = encode_state_value(tables)
    page = render_training_html(doc)
    _, group = one_group(document)
    rows = table(page, "lookup-0")
    assert len(rows) == 1 + len(group["modes"]) and "knee" not in " ".join(map(" ".join, rows))
    assert len(figures(page)) == len(tables) and curve_specs(page) == []
