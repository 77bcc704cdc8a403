"""The detectors run in the order that frees each large series early (`run_order`), with the same
results, in the given order, and the failures listed as before; the run context's true states are
made only for a page that draws them."""

from __future__ import annotations

import numpy as np

from logscan.pipeline import create_detectors, detect, load_profile_for, needs_of, prepare
from logscan.pipeline.release import run_order
from logscan.results import DetectorResult

NAMES = ["nis", "encoded_ekf", "cusum", "frozen"]


def prepared_with(sample, names, log="quad_imu_bias.mcap"):
    path = sample(log)
    loaded = load_profile_for(path, None)
    detectors = create_detectors(loaded, names)
    return prepare(path, loaded, needs_of(detectors)), detectors


def test_the_samples_readers_run_first_the_lighter_next_and_those_reading_nothing_last(sample):
    prepared, detectors = prepared_with(sample, NAMES)
    # frozen reads the samples; cusum the innovations (y, S_diag), less than encoded_ekf's states
    # and covariances; nis none of the large series
    assert [detectors[i].name for i in run_order(prepared, detectors)] == ["frozen", "cusum", "encoded_ekf", "nis"]


def test_the_results_are_those_of_each_detector_alone_in_the_given_order(sample):
    alone = {}
    for name in NAMES:
        prepared, detectors = prepared_with(sample, [name])
        (alone[name],) = detect(prepared, detectors).results
    prepared, detectors = prepared_with(sample, NAMES)
    announced: list[str] = []
    analysis = detect(prepared, detectors, free_series=True, sensor_views=True, progress=announced.append)
    assert announced == ["detector frozen", "detector cusum", "detector encoded_ekf", "detector nis"]
    assert [r.detector for r in analysis.results] == NAMES
    for result in analysis.results:
        before = alone[result.detector]
        assert [a.to_dict() for a in result.alarms] == [a.to_dict() for a in before.alarms]
        assert result.series.keys() == before.series.keys()
        for key, series in result.series.items():
            np.testing.assert_array_equal(series, before.series[key], err_msg=key)


class _Failing:
    """A detector that raises; ``reads``: what it declares it reads."""

    raw_topics: frozenset[str] = frozenset()

    def __init__(self, name: str, reads: frozenset[str]):
        self.name, self.reads = name, reads

    def run(self, run, trace, **context) -> DetectorResult:
        raise RuntimeError(f"{self.name} broke")


def test_failures_are_listed_the_samples_readers_first_then_as_given(sample):
    prepared, (nis, _) = prepared_with(sample, ["nis", "cusum"])  # cusum: the filter keeps y
    light, heavy, samples = (
        _Failing("light", frozenset({"y"})),
        _Failing("heavy", frozenset({"x_prior", "x_post"})),
        _Failing("samples", frozenset({"z"})),
    )
    detectors = [heavy, nis, light, samples]
    assert [detectors[i].name for i in run_order(prepared, detectors)] == ["samples", "light", "heavy", "nis"]
    analysis = detect(prepared, detectors, free_series=True)
    assert [f.detector for f in analysis.failures] == ["samples", "heavy", "light"]
    assert [r.detector for r in analysis.results] == ["nis"]


def test_the_true_states_are_made_only_for_a_page_that_draws_them(sample):
    prepared, _ = prepared_with(sample, ["nis"])  # a simulated log: its truth gives the model's states
    assert prepared.context.true_states == {}  # only the UBIKF's envelopes are drawn against them
    drawn, _ = prepared_with(sample, ["chi2"], "hover_healthy.mcap")  # tests/test_ubikf_truth_view.py
    assert set(drawn.context.true_states) == set(drawn.model.state_names)
