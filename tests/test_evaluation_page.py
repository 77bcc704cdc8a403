"""`logscan evaluate LOGS -o eval.html`: the evaluation as a page, agreeing with `--json`."""

from __future__ import annotations

import html
import json
import re


def test_the_page_shows_the_scores_and_the_detection_matrix_of_the_json(cli, sample, tmp_path):
    logs = [sample(n) for n in ("quad_imu_bias.mcap", "quad_imu_bitflip.mcap", "quad_healthy.mcap")]
    page, out = tmp_path / "eval.html", tmp_path / "eval.json"
    result = cli("evaluate", *logs, "-o", page, "--json", out, "-q")
    assert result.exit_code == 0, result.stderr
    document = json.loads(out.read_text())
    text = page.read_text(encoding="utf-8")
    rows = {
        html.unescape(m.group(1)): [int(x) for x in m.groups()[1:]]
        for m in re.finditer(
            r"<tr[^>]*><td>([^<]+)</td><td class=\"num\">(\d+)</td><td class=\"num\">(\d+)</td>"
            r"<td class=\"num\">(\d+)</td><td class=\"num\">(\d+)</td>", text,
        )
    }  # fmt: skip
    for key, score in document["scores"].items():
        assert rows[key] == [score["n_events"], score["tp"], score["fn"], score["fp"]], key
    for kind in ("quadcopter/bias", "quadcopter/bitflip"):
        assert f"<td>{kind}</td>" in text
    assert 'id="latency"' in text and text.count("Plotly.newPlot") == 1


def test_an_output_named_like_a_log_is_refused(cli, sample, tmp_path):
    result = cli("evaluate", sample("quad_healthy.mcap"), "-o", tmp_path / "x.mcap")
    assert result.exit_code == 2
