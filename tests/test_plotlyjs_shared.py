"""`--plotlyjs`: several logs' reports share one plotly.min.js beside them by default (said on stderr),
`--plotlyjs embed` puts it into each report, and `train` and `evaluate` take `--plotlyjs DIR` too."""

from __future__ import annotations

import pytest

BANNER = "plotly.js v"  # plotly.min.js's first comment: the library itself is in the page


@pytest.fixture(scope="module")
def two_logs(sample_paths):
    return sample_paths("quad_healthy.mcap", "quad_imu_bitflip.mcap")


@pytest.fixture(scope="module")
def sample_paths():
    from conftest import SAMPLES

    def paths(*names):
        found = [SAMPLES / name for name in names]
        if not all(path.exists() for path in found):
            pytest.skip("sample logs missing")
        return found

    return paths


def test_several_logs_share_one_plotly_js_beside_the_reports_and_say_so(cli, two_logs, tmp_path):
    out = tmp_path / "reports"
    result = cli("analyze", *two_logs, "-o", f"{out}/", "--exit-zero")
    assert result.exit_code == 0, result.stderr
    assert f"logscan: plotly.js: one copy for the 2 reports, {out}/plotly.min.js (--plotlyjs embed: one in each)" in (
        result.stderr
    )
    assert BANNER in (out / "plotly.min.js").read_text(encoding="utf-8")
    for name in ("quad_healthy.report.html", "quad_imu_bitflip.report.html"):
        page = (out / name).read_text(encoding="utf-8")
        assert '<script src="plotly.min.js"' in page and BANNER not in page
        assert (out / name).stat().st_size < 1_000_000  # not ~5 MB each


def test_embed_keeps_each_report_self_contained_and_quiet_says_nothing(cli, two_logs, tmp_path):
    out = tmp_path / "reports"
    result = cli("analyze", *two_logs, "-o", f"{out}/", "--plotlyjs", "embed", "--exit-zero")
    assert not (out / "plotly.min.js").exists() and not (tmp_path / "embed").exists()
    assert all(BANNER in (out / name).read_text(encoding="utf-8") for name in ("quad_healthy.report.html",))
    assert "plotly.js: one copy" not in result.stderr
    quiet = cli("analyze", *two_logs, "-o", f"{tmp_path / 'q'}/", "--exit-zero", "-q")
    assert (tmp_path / "q" / "plotly.min.js").is_file() and "plotly.js" not in quiet.stderr


def test_one_log_still_embeds_by_default(cli, sample_paths, tmp_path):
    (log,) = sample_paths("quad_healthy.mcap")
    result = cli("analyze", log, "-o", tmp_path / "r.html", "-q")
    assert result.exit_code == 0
    assert BANNER in (tmp_path / "r.html").read_text(encoding="utf-8")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.html"]


def test_evaluate_links_a_shared_plotly_js(cli, sample_paths, tmp_path):
    (log,) = sample_paths("quad_imu_bitflip.mcap")
    result = cli("evaluate", log, "-o", tmp_path / "e.html", "--plotlyjs", tmp_path / "js", "-q")
    assert result.exit_code == 0, result.stderr
    page = (tmp_path / "e.html").read_text(encoding="utf-8")
    assert '<script src="js/plotly.min.js"' in page and BANNER not in page
    assert BANNER in (tmp_path / "js" / "plotly.min.js").read_text(encoding="utf-8")
    cli("evaluate", log, "-o", tmp_path / "embedded.html", "-q")
    assert BANNER in (tmp_path / "embedded.html").read_text(encoding="utf-8")


def test_train_links_a_shared_plotly_js(cli, sample_paths, tmp_path):
    (log,) = sample_paths("jackal_train_1.mcap")
    result = cli("train", log, "-o", tmp_path / "t.tables.json", "--plotlyjs", tmp_path, "-q")
    assert result.exit_code == 0, result.stderr
    page = (tmp_path / "t.tables.html").read_text(encoding="utf-8")
    assert '<script src="plotly.min.js"' in page and BANNER not in page
    assert BANNER in (tmp_path / "plotly.min.js").read_text(encoding="utf-8")
