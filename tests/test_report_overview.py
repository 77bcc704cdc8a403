"""Report overview: margins per check, incident headlines in the verdict, alarmed detectors first,
captions on every figure, no SI prefixes, rejected samples in plain words, groups and topics read."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from test_report import figures, table

from logscan.report import ReportInput, render_html
from logscan.report.context import measurement_groups
from logscan.report.margins import margin_ratios, result_margins, statistic_margin
from logscan.results import DetectorResult, Incident

N = 1_000
T = np.arange(N) * 0.01


def result_with(name: str, statistic, upper=None, lower=None, **options) -> DetectorResult:
    result = DetectorResult("det")
    result.add_statistic(T, name, np.asarray(statistic, dtype=np.float64), upper=upper, lower=lower, **options)
    return result


# --- margins --------------------------------------------------------------------------------------


def test_two_sided_margin_is_the_distance_from_the_centre_over_the_half_width():
    # a mu +- rho s band around mu = 10 with half width 2: e = 11.5 is 0.75 of the way to a bound
    e = np.full(N, 10.0)
    e[400] = 11.5
    e[700] = 8.8  # 0.6 toward the lower bound
    margin = statistic_margin(result_with("e_x", e, upper=12.0, lower=8.0), "e_x", T)
    assert margin.kind == "two-sided"
    assert margin.ratio == pytest.approx(0.75) and margin.time == pytest.approx(4.0) and margin.value == 11.5
    assert margin.n_alarms == 0


def test_two_sided_margin_on_a_varying_float32_band_counts_the_lower_side_and_skips_nan():
    centre = np.linspace(-5.0, 5.0, N)
    half = 1.0 + 0.5 * np.sin(T)
    e = centre.copy()
    e[:100] = np.nan  # not evaluated there
    e[250] = centre[250] - 1.1 * half[250]  # beyond the lower bound: 1.1
    result = result_with("e", e, upper=centre + half, lower=centre - half, n_persist=5, valid=~np.isnan(e))
    assert result.thresholds["e"].upper.dtype == np.float32  # as kept for figures
    margin = statistic_margin(result, "e", T)
    assert margin.ratio == pytest.approx(1.1, rel=1e-5) and margin.time == pytest.approx(2.5)
    assert margin.n_alarms == 0  # one sample: too short for n_persist = 5


def test_one_sided_margins_constant_bands_and_bounds_of_either_sign():
    nis = np.where(np.arange(N) % 10 == 0, 40.0, np.nan)  # a 10 Hz statistic on a 100 Hz grid
    nis[500] = 180.0
    result = result_with("nis.gps", nis, upper=90.0, valid=~np.isnan(nis))
    assert not result.thresholds["nis.gps"].upper.flags.writeable  # a read-only broadcast constant
    margin = statistic_margin(result, "nis.gps", T)
    assert (margin.kind, margin.ratio, margin.n_alarms) == ("upper", pytest.approx(2.0), 1)
    ratios = margin_ratios(
        np.array([-3.0, -1.0, 1.0, -6.0, 4.0, 2.0, np.nan]),
        np.array([-2.0, -2.0, -2.0, np.nan, np.nan, np.nan, 1.0]),  # upper < 0: e must stay below
        np.array([np.nan, np.nan, np.nan, -3.0, 2.0, 0.0, np.nan]),  # lower < 0, lower > 0, lower = 0
    )
    expected = [2.0 / 3.0, 2.0, np.inf, 2.0, 0.5, np.nan, np.nan]
    np.testing.assert_allclose(ratios, expected)


def reference_ratios(e, hi, lo):
    """The module docstring's ratios, every case computed everywhere in float64 and picked per sample."""
    e, hi, lo = (np.asarray(a, dtype=np.float64) for a in (e, hi, lo))
    has_hi, has_lo = np.isfinite(hi), np.isfinite(lo)
    with np.errstate(divide="ignore", invalid="ignore"):
        centre, half = 0.5 * (hi + lo), 0.5 * (hi - lo)
        two_sided = np.where(half > 0, np.abs(e - centre) / half, np.where(e == centre, 0.0, np.inf))
        upper_only = np.where(hi > 0, e / hi, np.where(e < 0, hi / e, np.inf))
        lower_only = np.where(lo < 0, e / lo, np.where(e > 0, lo / e, np.inf))
    ratio = np.where(has_hi & has_lo, two_sided, np.where(has_hi, upper_only, np.where(has_lo, lower_only, np.nan)))
    ratio[(has_hi & ~has_lo & (hi == 0)) | (has_lo & ~has_hi & (lo == 0)) | np.isnan(e)] = np.nan
    return ratio


def test_margin_ratios_and_peak_are_the_float64_ratios_of_every_case_exactly():
    rng = np.random.default_rng(11)
    e = rng.normal(0.0, 3.0, N)
    e[rng.random(N) < 0.05] = np.nan
    e[::97] = 0.0
    hi = rng.choice([4.0, -1.0, 0.0, np.nan, np.inf], N)
    lo = np.where(rng.random(N) < 0.5, hi, rng.choice([-4.0, 1.0, 0.0, np.nan], N))  # lo == hi: zero width
    result = result_with("s", e, upper=hi, lower=lo, valid=rng.random(N) < 0.9)
    kept = result.series["s"], result.thresholds["s"].upper, result.thresholds["s"].lower  # float32
    expected = reference_ratios(*kept)
    np.testing.assert_array_equal(margin_ratios(*kept), expected)
    ranked = np.where(result.judged["s"] & ~np.isnan(expected), expected, -np.inf)
    margin = statistic_margin(result, "s", T)
    assert margin.ratio == ranked.max() and margin.time == T[int(np.argmax(ranked))]


def test_a_constant_band_is_one_value_for_every_sample():
    e = np.linspace(-2.0, 3.0, N)
    result = result_with("e", e, upper=2.0, lower=-2.0)
    assert result.thresholds["e"].upper.strides == (0,)  # a broadcast constant, never copied to N values
    np.testing.assert_array_equal(margin_ratios(e, np.broadcast_to(2.0, (N,)), None), reference_ratios(e, 2.0, np.nan))
    assert statistic_margin(result, "e", T).ratio == 1.5


def test_samples_that_cannot_alarm_do_not_count_toward_the_margin():
    e = np.zeros(N)
    e[:50] = 30.0  # a settling transient in the warm-up
    e[600] = 0.5
    e[700] = 40.0  # not a valid sample (e.g. no update of that sensor there)
    valid = np.ones(N, dtype=bool)
    valid[700] = False
    margin = statistic_margin(result_with("e_v", e, upper=1.0, lower=-1.0, warmup_s=1.0, valid=valid), "e_v", T)
    assert (margin.ratio, margin.time, margin.n_alarms) == (0.5, 6.0, 0)


def test_margins_taken_block_by_block_find_the_peak_in_any_block(monkeypatch):
    import logscan.report.margins as margins

    rng = np.random.default_rng(3)
    e = rng.normal(0.0, 1.0, N)
    e[::7] = np.nan
    e[901] = 3.9  # the peak, in the last block
    band = 4.0 + 0.01 * np.sin(T)
    result = result_with("e_x", e, upper=band, lower=-band, valid=~np.isnan(e))
    whole = statistic_margin(result, "e_x", T)
    monkeypatch.setattr(margins, "BLOCK", 64)
    blocks = statistic_margin(result, "e_x", T)
    assert (blocks.ratio, blocks.time) == (whole.ratio, whole.time) and whole.time == pytest.approx(9.01)


def test_a_statistic_never_evaluated_has_no_margin_and_says_why():
    result = result_with("nis.mag", np.full(N, np.nan), upper=90.0, valid=np.zeros(N, dtype=bool))
    margins = result_margins([result], T)
    assert margins[0].ratio is None and margins[0].note.startswith("never evaluated against its threshold")


# --- the page -------------------------------------------------------------------------------------


def report_of(results, incidents=(), unchecked=(), verdict="no alarms", groups=()) -> ReportInput:
    facts = {
        "file": "/logs/flight.mcap",
        "format": "mcap",
        "start_ns": 0,
        "end_ns": int(T[-1] * 1e9),
        "duration_s": float(T[-1]),
        "topics": {"/imu": {"fields": ["accel.x"]}, "/camera": {"fields": ["image"]}},
        "channels": {"/imu/accel.x": {"samples": N, "unit": None}},
    }
    return ReportInput(
        facts, "", "embedded", {"name": "quadcopter", "groups": {"accel": {}, "gyro": {}, "mag": {}}}, "0.1.0",
        T, list(results), verdict=verdict, incidents=list(incidents), unchecked=list(unchecked), groups=list(groups),
    )  # fmt: skip


def quiet_and_alarming() -> list[DetectorResult]:
    """A detector without alarms, one whose NIS-like statistic exceeds at 3.00-3.19 s, and one with
    three rejected gyro samples."""
    quiet = DetectorResult("quiet")
    quiet.add_statistic(T, "e_x", np.zeros(N), upper=1.0, lower=-1.0)
    loud = DetectorResult("loud")
    stat = np.ones(N)
    stat[300:320] = 11.0
    loud.add_statistic(T, "nis.accel", stat, upper=2.0, n_persist=3)
    flags = np.zeros(N)
    flags[[600, 601, 605]] = 1.0
    encoded = DetectorResult("encoded")
    encoded.add_statistic(T, "rejected.gyro", flags, upper=0.5, hold_off_s=1.0)
    encoded.add_statistic(T, "e_x", np.zeros(N), upper=1.0, lower=-1.0)
    return [quiet, loud, encoded]


def test_the_verdict_names_the_incidents_and_alarmed_detectors_come_first():
    results = quiet_and_alarming()
    alarm = results[1].alarms[0]
    incident = Incident(3.0, 3.19, "accel", "accelerometer inconsistent 3.00-3.19 s (nis.accel, peak 5.5x)", [alarm])
    page = render_html(report_of(results, [incident], verdict="2 alarms in 2 incidents"), plotlyjs_src="p.js")
    verdict = page[page.index('id="verdict"') : page.index("</div>", page.index('id="verdict"'))]
    assert "accelerometer inconsistent 3.00-3.19 s (nis.accel, peak 5.5x)" in verdict
    assert page.index("Detector: loud") < page.index("Detector: encoded") < page.index("Detector: quiet")
    # the quiet detector collapses to one line with its margin; figures are numbered in page order
    assert re.search(r'<details class="detector"[^>]*>\s*<summary><h2>Detector: quiet</h2>', page)
    assert "no alarms; closest to a threshold: e_x peaked at 0 of its threshold (0.00 s)" in page
    ids = re.findall(r'class="figure ls-timeseries[^"]*" id="(fig-\d+)"', page)
    assert ids == [f"fig-{i}" for i in range(len(ids))] and len(ids) == len(figures(page))
    assert [spec["id"] for spec in figures(page)] == ids
    assert figures(page)[0]["figure"]["layout"]["annotations"][0]["text"].startswith("<b>loud")


def test_margin_table_on_every_report_with_the_checks_that_could_not_run():
    results = quiet_and_alarming()
    page = render_html(report_of(results, unchecked=["group 'mag': no valid samples"]), plotlyjs_src="p.js")
    rows = {(row[0], row[1]): row for row in table(page, "margin-table")[1:]}
    assert rows["quiet", "e_x"][2:5] == ["two-sided", "0", "0.000"]
    assert rows["loud", "nis.accel"][3:5] == ["5.5", "3.000"] and rows["loud", "nis.accel"][6] == "1"
    assert rows["encoded", "rejected.gyro"][7] == "3 samples outside the physical range, the filter skipped them"
    assert "group &#39;mag&#39;: no valid samples" in page[page.index('id="margin-unchecked"') :]
    healthy = render_html(report_of(results[:1]), plotlyjs_src="p.js")
    assert "Closest to a threshold: e_x" in healthy and "Every check ran on the whole log." in healthy


def test_rejected_alarms_say_what_the_filter_did():
    page = render_html(report_of(quiet_and_alarming(), verdict="2 alarms"), plotlyjs_src="p.js")
    row = next(r for r in table(page, "alarm-table") if "rejected.gyro" in r)
    assert "3 samples outside the physical range, the filter skipped them" in row
    assert "2" not in row[row.index("rejected.gyro") + 4 :]  # no meaningless peak/threshold ratio of 2


def test_every_figure_has_a_caption_saying_what_normal_looks_like():
    report = report_of(quiet_and_alarming())
    report.results[1].extras["nis.accel.per_dof"] = np.ones(N)
    page = render_html(report, plotlyjs_src="p.js")
    n_rows = sum(len(spec["figure"]["layout"]["annotations"]) for spec in figures(page))
    captions = re.findall(r'<li class="caption">([^<]*)</li>', page)
    # the quiet detector's e_x, 0 all log long, is folded away and named; rows with one caption share it
    assert n_rows == 4 and "Not drawn, constant all log long and never alarmed: e_x." in captions
    captions.remove("Not drawn, constant all log long and never alarmed: e_x.")
    assert 3 <= len(captions) <= n_rows and len(set(captions)) == len(captions)
    assert all("Normal:" in c or "for context" in c for c in captions), captions
    assert any("refused a gyro sample as outside the physical range" in c for c in captions)


def test_statistics_have_no_si_prefixes():
    results = [result_with("ratio", np.full(N, 1e-4), upper=1e-3)]
    page = render_html(report_of(results), plotlyjs_src="p.js")
    for spec in figures(page):
        layout = spec["figure"]["layout"]
        axis_defaults = layout["template"]["layout"]["yaxis"]  # a section's y axes take theirs from its template
        assert layout["yaxis"].get("exponentformat", axis_defaults["exponentformat"]) == "e"
        assert layout["xaxis"]["exponentformat"] == "none"
    assert "0.1" in [row[3] for row in table(page, "margin-table")[1:]]  # 1e-4 / 1e-3 in plain digits
    assert not re.search(r"\d[µu]<", page)


def test_measurement_groups_as_used_and_topics_read_vs_in_the_log():
    class Spec:
        channels, rate_hz, noise_std, width, source = ["/imu/accel.x"], 100.0, [0.1], 1, None

    class Quaternion:  # four channels converted to three angles: the NIS expects 3
        channels, rate_hz, noise_std, width, source = [f"/att/q[{i}]" for i in range(4)], 50.0, None, 3, "quaternion"

    class Profile:
        measurements = {"accel": Spec(), "attitude": Quaternion()}

    counts = {"updates": {"accel": 999}, "rejected": {"accel": 2}, "mean_nis": {"attitude": 2.5}}
    groups = measurement_groups(Profile(), counts)
    page = render_html(report_of(quiet_and_alarming()[:1], groups=groups), plotlyjs_src="p.js")
    rows = table(page, "groups-table")
    assert rows[1] == ["accel", "/imu/accel.x", "100", "0.1", "999", "2", "— (1)"]
    assert rows[2][1].endswith("/att/q[3] (from quaternion)") and rows[2][-1] == "2.5 (3)"
    assert len(rows) == 3  # only the groups the profile used, not the model's gyro and mag
    assert "1 read of 2 in the log" in page
    topics = page[page.index('id="log-topics"') :]
    assert topics.index("/imu") < topics.index("in the log, not read") < topics.index("/camera")


def test_the_readme_and_the_report_page_show_the_screenshots_the_script_regenerates():
    """The README shows the faulty sample's report; docs/reading-the-report.md shows it and links
    the healthy one; docs/make_screenshots.py makes both."""
    root = Path(__file__).resolve().parent.parent
    readme = (root / "README.md").read_text(encoding="utf-8")
    page = (root / "docs" / "reading-the-report.md").read_text(encoding="utf-8")
    script = (root / "docs" / "make_screenshots.py").read_text(encoding="utf-8")
    assert re.search(r"!\[[^\]]*\]\(docs/images/report_quad_imu_bias\.png\)", readme)
    for log in ("quad_imu_bias", "quad_healthy"):
        image = root / "docs" / "images" / f"report_{log}.png"
        assert f"](images/report_{log}.png)" in page and f'"{log}"' in script
        assert image.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and image.stat().st_size < 400_000


def test_an_installed_logscan_ships_every_template_file():
    import tomllib

    root = Path(__file__).resolve().parent.parent
    shipped = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    patterns = shipped["package-data"]["logscan.templates"]
    files = [p for p in (root / "templates").iterdir() if p.is_file() and p.suffix != ".py"]
    assert any(p.name == "report.js" for p in files)
    assert all(any(p.match(pattern) for pattern in patterns) for p in files), (files, patterns)
