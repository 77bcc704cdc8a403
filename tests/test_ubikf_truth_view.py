"""The UBIKF's estimation error against its envelopes (logscan/report/ubikf_truth_view.py): on a
simulated hover_uav log, one row of the `chi2` section per state the truth gives, with the shares
of steps inside the hull and inside +-3 sqrt(P+) that a direct count on the trace and the logged
truth gives; a log without truth gets no such rows."""

from __future__ import annotations

import re

import numpy as np
import pytest

from logscan.detectors.ubikf_bound import EnvelopeView
from logscan.json_policy import jsonable
from logscan.pipeline import analyze_log
from logscan.readers import read_log
from logscan.readers.mcap.writer import TopicData, write_mcap
from logscan.report.figures import Figure, Trace
from logscan.report.page_parts import PageInput
from logscan.report.page_sections import detector_sections
from logscan.report.plotly_json import allocate_points
from logscan.report.ubikf_truth_view import SIGMAS, inside_shares, ubikf_truth_rows
from logscan.simulate.dispatch import simulate
from logscan.simulate.output import grid_ns, write_simulation

ROW_TITLE = re.compile(r"the UBIKF's error in (\w+) against its envelopes")
SHARE = re.compile(r"(\w+) (\d+\.\d)\s% / (\d+\.\d)\s%")


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """(a short simulated hover with its truth, the same log as a real one would be: no truth)."""
    folder = tmp_path_factory.mktemp("ubikf_truth")
    sim = simulate("hover_uav", duration=6.0, seed=5)
    with_truth = folder / "hover.mcap"
    write_simulation(sim, with_truth)
    t_ns = grid_ns(sim)
    topics = {s.topic: TopicData(s.schema, t_ns[s.steps], dict(s.fields)) for s in sim.series()}
    without = folder / "hover_no_truth.mcap"
    write_mcap(without, topics, encoding="json", metadata={"logscan.profile": {"toml": sim.profile_toml()}})
    return with_truth, without


@pytest.fixture(scope="module")
def analysed(logs):
    return analyze_log(logs[0], detector_names=["chi2"], free_series=True)


def chi2_result(analysis):
    (result,) = [r for r in analysis.results if r.detector == "chi2"]
    return result


def chi2_rows(analysis) -> list[Figure]:
    """The rows of the chi2 section's one figure, as the report page stacks them."""
    report = analysis.report_input()
    _, figures = detector_sections(PageInput(report, np.asarray(report.t, dtype=np.float64), []), [])
    (rows,) = [rows for _, rows in figures if any(fig.title.startswith("chi2") for fig in rows)]
    return rows


def logged_truth(path, analysis, states) -> np.ndarray:
    """(N, k) the true states as logged, the sample stamped at each grid step (the simulator logs
    the truth at every step), read from the file itself."""
    log = read_log(path, topics={"/truth/state"})
    grid = analysis.run.start_ns + np.round(analysis.run.t * 1e9).astype(np.int64)
    columns = []
    for name in states:
        channel = log.channels[f"/truth/state/{name}"]
        stamps = np.asarray(channel.t, dtype=np.int64)
        i = np.searchsorted(stamps, grid)
        assert np.array_equal(stamps[i], grid)
        columns.append(np.asarray(channel.values, dtype=np.float64)[i])
    return np.column_stack(columns)


def test_one_row_per_state_the_truth_gives(logs, analysed):
    ubikf = analysed.prepared.traces["ubikf"]
    truth_fields = analysed.prepared.log.truth["true_state_fields"]
    expected = [name for name in ubikf.state_names if name in truth_fields]
    assert len(expected) == 12  # hover_uav: every state is simulated
    titled = [ROW_TITLE.search(fig.title) for fig in chi2_rows(analysed)]
    assert [m.group(1) for m in titled if m] == expected
    for fig in ubikf_truth_rows(chi2_result(analysed), PageInput(analysed.report_input(), analysed.run.t, [])):
        assert [trace.name for trace in fig.traces][-1] == "x_mid − x_true"
        assert fig.traces[0].style["fill"] == fig.traces[1].style["fill"] == "toself"  # the two bands


def test_the_captions_inside_shares_are_a_direct_count(logs, analysed):
    ubikf = analysed.prepared.traces["ubikf"]
    rows = ubikf_truth_rows(chi2_result(analysed), PageInput(analysed.report_input(), analysed.run.t, []))
    said = {m.group(1): (float(m.group(2)), float(m.group(3))) for m in SHARE.finditer(rows[0].caption)}
    assert list(said) == list(ubikf.state_names)
    x_true = logged_truth(logs[0], analysed, ubikf.state_names)
    judged = np.isfinite(x_true) & np.isfinite(ubikf.x_mid) & ~ubikf.diverged[:, None]
    in_hull = ((ubikf.x_lo <= x_true) & (x_true <= ubikf.x_hi) & judged).sum(axis=0) / judged.sum(axis=0)
    sigma = SIGMAS * np.sqrt(ubikf.P_diag.astype(np.float64))
    in_sigma = ((np.abs(ubikf.x_mid - x_true) <= sigma) & judged).sum(axis=0) / judged.sum(axis=0)
    shares = inside_shares(chi2_result(analysed).info["envelope_view"], analysed.prepared.context.true_states)
    for k, name in enumerate(ubikf.state_names):
        assert 0.0 <= in_hull[k] <= 1.0 and 0.0 <= in_sigma[k] <= 1.0
        assert shares[name].hull == in_hull[k] and shares[name].sigma == in_sigma[k]
        assert said[name] == (np.floor(1000 * in_hull[k]) / 10, np.floor(1000 * in_sigma[k]) / 10)
    assert np.mean(in_sigma) > 0.9  # a healthy hover: the bound holds the error


def test_the_view_is_one_line_in_the_json_summary(analysed):
    view = chi2_result(analysed).info["envelope_view"]
    assert isinstance(view, EnvelopeView)
    assert isinstance(jsonable(chi2_result(analysed).info)["envelope_view"], str)


def test_a_log_without_truth_gets_no_figure(logs, analysed):
    analysis = analyze_log(logs[1], detector_names=["chi2"], free_series=True)
    assert analysis.prepared.log.truth is None
    assert analysis.prepared.context.true_states == {}
    assert "envelope_view" not in chi2_result(analysis).info
    assert not [fig for fig in chi2_rows(analysis) if ROW_TITLE.search(fig.title)]
    assert any(fig.title.startswith("chi2") for fig in chi2_rows(analysis))  # the section itself is there
    # the view without the truth (a report whose run context has none): no rows either
    report = analysis.report_input()
    report.context.true_states = {}
    assert ubikf_truth_rows(chi2_result(analysed), PageInput(report, report.t, [])) == []


def test_a_traces_own_cap_bounds_its_share_of_the_points():
    y = np.zeros(10)
    capped = Trace("band", y, np.zeros(0, dtype=np.int64), 1.0, {}, max_points=24)
    free = Trace("line", y, np.zeros(0, dtype=np.int64), 1.0, {})
    points = allocate_points([Figure("f", "y", [capped, free], {})], 18_000)
    assert points[id(capped)] == 24 and points[id(free)] > 24
