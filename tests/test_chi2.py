"""The UBIKF chi-square test end to end (detectors/ubikf_chi2.py on logscan/filters/ubikf.py): the
paper's rotor loss caught within 10 samples, no robust alarm on a healthy hover, possible-fault
warnings apart from alarms (exit 1 only with --fail-on warning), and the report's envelopes."""

from __future__ import annotations

import numpy as np
import pytest

from logscan.pipeline import analyze_log


@pytest.fixture(scope="module")
def rotor_loss(tmp_path_factory):
    from logscan.cli.main import main

    path = tmp_path_factory.mktemp("chi2") / "loss.mcap"
    try:
        main(
            [
                "simulate",
                "hover_uav",
                "--fault",
                "rotor-loss",
                "--duration",
                "12",
                "--seed",
                "31",
                "-q",
                "-o",
                str(path),
            ]
        )
    except SystemExit as exc:
        assert exc.code in (0, None)
    return path


def chi2_result(analysis):
    (result,) = [r for r in analysis.results if r.detector == "chi2"]
    return result


def test_the_rotor_loss_is_a_robust_alarm_within_10_samples(rotor_loss):
    analysis = analyze_log(rotor_loss, detector_names=["chi2"], free_series=True)
    (event,) = analysis.events
    result = chi2_result(analysis)
    robust = [a for a in result.alarms if a.signal == "chi2.lower"]
    assert robust, result.info
    first = min(a.start for a in robust)
    assert event.t_start <= first <= event.t_start + 10 * analysis.run.dt + 1e-9


def test_no_robust_alarm_on_the_healthy_hover_and_the_bound_settles(sample):
    analysis = analyze_log(sample("hover_healthy.mcap"), detector_names=["chi2"], free_series=True)
    result = chi2_result(analysis)
    assert result.alarms == []
    trace = result.extras["trace(P+)"]
    t = analysis.run.t
    assert np.isfinite(trace).all() and trace[t > 2.0].max() < trace[0]
    late = trace[t > t[-1] - 5.0]
    assert late.max() <= 1.1 * late.min()  # it settles (the paper's Fig. 4)
    for state in ("roll", "pitch", "yaw"):
        lo, mid, hi = (result.extras[f"{part}.{state}"] for part in ("lower", "estimate", "upper"))
        assert np.all(lo <= mid + 1e-6) and np.all(mid <= hi + 1e-6)


def test_the_upper_sum_is_a_band_not_a_count_of_warnings(sample, cli):
    path = sample("hover_healthy.mcap")
    analysis = analyze_log(path, detector_names=["chi2"], free_series=True)
    result = chi2_result(analysis)
    assert result.possible == [] and result.alarms == []
    share = result.info["band_straddles_delta"]
    assert 0.0 <= share < 1.0
    upper, lower = (
        result.extras["chi2.upper / delta"],
        result.series["chi2.lower"] / result.thresholds["chi2.lower"].upper,
    )
    judged = np.isfinite(lower)
    assert np.all(upper[judged] >= lower[judged] * (1 - 1e-5))  # a band over the lower sum (float32 series)
    assert "chi2.upper" not in result.series  # not a statistic: no margin, no alarm
    strict = cli("analyze", path, "-d", "chi2", "--no-report", "--fail-on", "warning")
    assert strict.exit_code == 0, strict.stdout + strict.stderr


def test_the_bound_lies_above_the_point_filters_covariance(sample):
    from logscan.detectors.ubikf_bound import BoundView
    from logscan.report.ubikf_view import ubikf_rows

    analysis = analyze_log(sample("hover_healthy.mcap"), detector_names=["chi2"], free_series=True)
    result = chi2_result(analysis)
    view = result.info["bound_view"]
    assert isinstance(view, BoundView)
    ratio = view.ratio()
    late = ratio[analysis.run.t > 2.0]
    assert np.nanmin(late) > 1.0  # the intervals in A and C cost covariance: strictly above
    assert view.settled_ratio() < 2.0  # and the weighted bound stays close
    (row,) = ubikf_rows(result, type("Page", (), {"truth_spans": []})())
    assert row.log_y and "ratio" in row.caption and len(row.traces) == 2


def test_the_report_draws_the_sums_the_envelopes_and_the_bound(sample, tmp_path):
    from logscan.report import render_html

    analysis = analyze_log(sample("hover_rotor_offset.mcap"), detector_names=["chi2"], free_series=True)
    analysis.prepared.release_series()
    page = render_html(analysis.report_input())
    for title in ("chi2: statistic / threshold", "chi2: roll", "chi2: trace(P+)", "chi2.upper / delta"):
        assert title in page, title
