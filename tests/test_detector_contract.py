"""The detector contract, checked on every registered detector (scikit-learn's parametrize_with_checks idea).

Parametrised over a registry built here: the built-ins, the installed plugins, the example plugin
of examples/ and a tiny test-only detector (so the contract test itself is exercised even while no
built-in exists). Checks: config round-trips through JSON, parameters are validated in run and not
in __init__, output shapes match the grid, output is deterministic, trained state round-trips as
strict JSON, NotTrainedError without training, and on simulated sample logs: no alarms on the
healthy fixture, alarms on the faulty fixture.
"""

from __future__ import annotations

import json
import sys
from importlib.metadata import EntryPoint, entry_points
from pathlib import Path

import numpy as np
import pytest

from logscan.align import AlignedGroup, AlignedRun
from logscan.detectors.base import Detector, describe
from logscan.detectors.registry import BUILTIN_DETECTORS, ENTRY_POINT_GROUP, Registry
from logscan.errors import LogscanError, NotTrainedError
from logscan.results import DetectorResult

REPO = Path(__file__).resolve().parents[1]
EXAMPLE_PLUGIN = REPO / "examples" / "logscan-example-plugin"
EXAMPLE_ENTRY_POINT = "logscan_example_plugin:RangeCheckDetector"


class ContractProbeDetector(Detector):
    """Test-only: each channel's |value| over its trained healthy scale, against a fixed factor."""

    name = "contract_probe"
    defaults = {"factor": 3.0, "n_persist": 2}
    requires_fit = True
    trained_attributes = ("scale_",)

    def _fit(self, runs, traces, **context):
        scale: dict[str, float] = {}
        for run in runs:
            for group in run.groups.values():
                peak = np.nanmax(np.abs(group.z[group.fresh]), axis=0)
                for channel, value in zip(group.channels, peak):
                    scale[channel] = max(scale.get(channel, 0.0), float(value))
        self.scale_ = scale

    def _run(self, run, trace, **context):
        result = self.new_result()
        for group in run.groups.values():
            for j, channel in enumerate(group.channels):
                ratio = np.abs(group.z[:, j]) / self.scale_[channel]
                result.add_statistic(
                    run.t, channel, ratio, upper=self.factor, valid=group.fresh, n_persist=self.n_persist
                )
        return result


# --- the registry under test --------------------------------------------------------------------


def example_plugin_entry_point() -> EntryPoint:
    """The example plugin's entry point, loadable from the checkout without installing it."""
    if str(EXAMPLE_PLUGIN) not in sys.path:
        sys.path.insert(0, str(EXAMPLE_PLUGIN))
    return EntryPoint(name="range_check", value=EXAMPLE_ENTRY_POINT, group=ENTRY_POINT_GROUP)


def contract_registry() -> Registry:
    installed = list(entry_points(group=ENTRY_POINT_GROUP))
    plugins = installed
    if not any(ep.value == EXAMPLE_ENTRY_POINT for ep in installed):
        plugins = installed + [example_plugin_entry_point()]
    return Registry(builtins=[*BUILTIN_DETECTORS, f"{__name__}:ContractProbeDetector"], plugins=plugins)


REGISTRY = contract_registry()
NAMES = REGISTRY.names()


# --- a synthetic run (no simulator needed) ------------------------------------------------------


def synthetic_run(seed: int = 0, n: int = 400, burst: bool = False) -> AlignedRun:
    """A 100 Hz run with an accelerometer group (every step) and a 10 Hz position group.

    burst=True puts a 0.12 s burst of 1e20 values (a flipped exponent bit) into accel x at 2.5 s.
    """
    rng = np.random.default_rng(seed)
    dt = 0.01
    t = np.arange(n) * dt
    accel = rng.normal(0.0, 0.05, (n, 3)) + np.array([0.0, 0.0, 9.81])
    if burst:
        accel[250:262, 0] = 1e20
    fresh_pos = np.arange(n) % 10 == 0
    pos_samples = np.column_stack([np.sin(0.5 * t), np.cos(0.5 * t), 1.0 + 0.0 * t])
    pos_samples += rng.normal(0.0, 0.2, (n, 3))
    position = pos_samples[np.maximum.accumulate(np.where(fresh_pos, np.arange(n), 0))]
    groups = {
        "accel": AlignedGroup("accel", ["/imu/acc.x", "/imu/acc.y", "/imu/acc.z"], accel, np.ones(n, bool)),
        "position": AlignedGroup("position", ["/gps/x", "/gps/y", "/gps/z"], position, fresh_pos),
    }
    return AlignedRun(
        t=t,
        dt=dt,
        start_ns=0,
        u=np.zeros((n, 4)),
        u_fresh=np.ones(n, bool),
        input_channels=["/cmd/thrust", "/cmd/tau.x", "/cmd/tau.y", "/cmd/tau.z"],
        groups=groups,
    )


def synthetic_case(name: str) -> tuple[Detector, AlignedRun]:
    """A detector trained on synthetic healthy runs and a faulty synthetic run; skips detectors
    that need inputs the synthetic case lacks (the shared filter trace, mode channels...)."""
    cls = REGISTRY.get(name)
    if cls.requires_trace:
        pytest.skip(f"{name} needs the filter trace: checked on the simulated fixtures")
    try:
        detector = cls().fit([synthetic_run(1), synthetic_run(2)])
        run = synthetic_run(3, burst=True)
        detector.run(run)
    except LogscanError as exc:
        pytest.skip(f"{name} cannot run on the synthetic case: {exc.one_line()}")
    return detector, run


def assert_same_result(a: DetectorResult, b: DetectorResult) -> None:
    assert a.series.keys() == b.series.keys()
    for key in a.series:
        np.testing.assert_array_equal(a.series[key], b.series[key])
    for key in a.thresholds:
        for x, y in (
            (a.thresholds[key].upper, b.thresholds[key].upper),
            (a.thresholds[key].lower, b.thresholds[key].lower),
        ):
            assert (x is None) == (y is None)
            if x is not None:
                np.testing.assert_array_equal(x, y)
    assert [al.to_dict() for al in a.alarms] == [al.to_dict() for al in b.alarms]


# --- checks on every detector -------------------------------------------------------------------


def test_registry_under_test_loads_without_problems():
    assert REGISTRY.warnings() == []
    assert {"contract_probe", "range_check"} <= set(NAMES)


@pytest.mark.parametrize("name", NAMES)
def test_describes_itself(name):
    cls = REGISTRY.get(name)
    assert name.isidentifier() and name == name.lower()
    assert describe(cls), f"{cls.__name__} needs a docstring whose first line says what it detects"


@pytest.mark.parametrize("name", NAMES)
def test_config_round_trips_through_json(name):
    cls = REGISTRY.get(name)
    detector = cls()
    detector.check_params()  # the defaults are valid
    config = json.loads(json.dumps(detector.get_params(), allow_nan=False))
    assert config == detector.get_params()
    again = cls.from_config(config)
    assert again.get_params() == detector.get_params()
    assert set(config) == set(cls.defaults)


@pytest.mark.parametrize("name", NAMES)
def test_init_only_stores_parameters(name):
    cls = REGISTRY.get(name)
    detector = cls(not_a_parameter=1)  # no validation in __init__ ...
    assert detector.get_params()["not_a_parameter"] == 1
    with pytest.raises(LogscanError, match="not_a_parameter"):  # ... but in run
        detector.run(synthetic_run())


@pytest.mark.parametrize("name", NAMES)
def test_output_shapes_match_the_grid(name):
    detector, run = synthetic_case(name)
    result = detector.run(run)
    assert result.detector == name
    assert result.series, "a detector returns at least one statistic series"
    for key, values in result.series.items():
        assert values.shape == (run.n_steps,), key
    assert set(result.thresholds) <= set(result.series)
    for alarm in result.alarms:
        assert run.t[0] <= alarm.start <= alarm.end <= run.t[-1]
        assert alarm.detector == name
    json.dumps(result.to_dict(), allow_nan=False)
    json.dumps(result.to_dict(summary_only=False), allow_nan=False)


@pytest.mark.parametrize("name", NAMES)
def test_output_is_deterministic(name):
    detector, run = synthetic_case(name)
    assert_same_result(detector.run(run), detector.run(run))
    retrained, _ = synthetic_case(name)
    assert_same_result(detector.run(run), retrained.run(run))


@pytest.mark.parametrize("name", NAMES)
def test_trained_state_round_trips_as_strict_json(name):
    detector, run = synthetic_case(name)
    text = json.dumps(detector.to_state(), allow_nan=False)
    state = json.loads(text)
    assert state["schema_version"] == type(detector).state_version and state["detector"] == name
    restored = type(detector).from_state(state)
    assert_same_result(detector.run(run), restored.run(run))


@pytest.mark.parametrize("name", [n for n in NAMES if REGISTRY.get(n).requires_fit])
def test_untrained_detector_raises_not_trained(name):
    with pytest.raises(NotTrainedError):
        REGISTRY.get(name)().run(synthetic_run())


# --- healthy / faulty fixtures (simulated sample logs) -------------------------------------------

SAMPLE_LOGS = REPO / "sample_logs"
# The healthy quadcopter log and its high-order bit-flip burst variant (a fault every detector
# should see: docs/algorithms.md section 1.5). Rename here if sample_logs/ differs.
FIXTURES = {"healthy": "quad_healthy.mcap", "faulty": "quad_imu_bitflip.mcap"}
# Detectors of sensors a quadcopter log lacks get fixtures that have them: A-TFM needs redundant
# speed sensors and a mode channel (the Jackal logs; its faulty one attacks the GPS speed).
JACKAL = {"healthy": "jackal_train_1.mcap", "faulty": "jackal_gps_bias.mcap"}
HOVER = {"healthy": "hover_healthy.mcap", "faulty": "hover_rotor_offset.mcap"}
# the UBIKF's chi-square test needs a model with interval parameters (hover_uav)
OWN_FIXTURES = {"atfm": JACKAL, "atfm_residual": JACKAL, "chi2": HOVER}
# detectors of a fault the faulty fixture (a bit flip) does not have, checked on their own faults
OWN_FAULT_TESTS = {"frozen": "the fixture's bit flips never freeze a channel (tests/test_frozen.py: stuck sensors)"}
_PIPELINE_CACHE: dict[str, tuple] = {}


def pipeline_case(kind: str, name: str | None = None):
    """(aligned run, EKF trace, model, profile, every filter trace) of a sample log through
    `logscan.pipeline.preparation` with what every detector under test needs, computed once per
    session; ``name``: the detector whose fixtures (`OWN_FIXTURES`) to use."""
    fixture = OWN_FIXTURES.get(name, FIXTURES)[kind]
    if fixture in _PIPELINE_CACHE:
        return _PIPELINE_CACHE[fixture]
    path = SAMPLE_LOGS / fixture
    if not path.exists():
        pytest.skip(f"{path.relative_to(REPO)} does not exist (made by sample_logs/make_samples.py)")
    from logscan.pipeline import load_profile_for, needs_of, prepare

    loaded = load_profile_for(path, None)
    # the detectors of this fixture set (a quadcopter log cannot run the UBIKF, for one)
    mine = [n for n in PIPELINE_NAMES if OWN_FIXTURES.get(n, FIXTURES)[kind] == fixture]
    detectors = [REGISTRY.get(n)() for n in mine]
    prepared = prepare(path, loaded, needs_of(detectors))
    _PIPELINE_CACHE[fixture] = (prepared.run, prepared.trace, prepared.model, prepared.profile, prepared.traces)
    return _PIPELINE_CACHE[fixture]


def pipeline_detector(name: str) -> Detector:
    """Detector ``name`` configured by the healthy log's profile and trained on that log."""
    healthy_run, healthy_trace, model, profile, _ = pipeline_case("healthy", name)
    spec = profile.detectors.get(name)
    detector = REGISTRY.get(name).from_config(spec.settings if spec else {})
    if detector.trained_attributes:  # as training fits it: with the filters it probes with (kgn)
        from logscan.pipeline.stages import fit_context

        detector.fit([healthy_run], [healthy_trace], **fit_context(detector, model, healthy_run))
    return detector


PIPELINE_NAMES = [n for n in NAMES if n != "contract_probe"]


@pytest.mark.parametrize("name", PIPELINE_NAMES)
def test_no_alarms_on_the_healthy_fixture(name):
    run, trace, model, _, traces = pipeline_case("healthy", name)
    result = pipeline_detector(name).run(run, trace, model=model, traces=traces)
    assert result.alarms == []


@pytest.mark.parametrize("name", PIPELINE_NAMES)
def test_alarms_on_the_faulty_fixture(name):
    if REGISTRY.get(name).raw_topics:
        pytest.skip(
            f"{name} reads the autopilot's own topics, which the simulated fixtures lack (tests/test_{name}.py)"
        )
    if name in OWN_FAULT_TESTS:
        pytest.skip(f"{name}: {OWN_FAULT_TESTS[name]}")
    run, trace, model, _, traces = pipeline_case("faulty", name)
    detector = pipeline_detector(name)
    assert detector.run(run, trace, model=model, traces=traces).alarms


# --- the base class itself ----------------------------------------------------------------------


class ArrayStateDetector(Detector):
    """Test-only: stores arrays with non-finite values as trained state."""

    name = "array_state"
    defaults = {"k": 2}
    requires_fit = True
    requires_trace = True
    trained_attributes = ("table_", "limit_")


def test_state_encoding_is_lossless_strict_json_for_arrays_and_nonfinite_floats():
    detector = ArrayStateDetector(k=5)
    detector.table_ = np.array([[1.5, np.nan], [np.inf, -np.inf]], dtype=np.float32)
    detector.limit_ = {"a": float("nan"), "b": [1, 2], "c": np.int64(3)}
    text = json.dumps(detector.to_state(), allow_nan=False)
    restored = ArrayStateDetector.from_state(json.loads(text))
    assert restored.k == 5
    assert restored.table_.dtype == np.float32 and restored.table_.shape == (2, 2)
    np.testing.assert_array_equal(restored.table_, detector.table_)
    assert np.isnan(restored.limit_["a"]) and restored.limit_["b"] == [1, 2] and restored.limit_["c"] == 3


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda s: s.update(format="other"), "not a logscan detector state"),
        (lambda s: s.update(detector="contract_probe"), "is for detector 'contract_probe'"),
        (lambda s: s.update(schema_version=99), "schema version 99"),
        (lambda s: s["state"].pop("limit_"), "lacks limit_"),
    ],
)
def test_from_state_rejects_foreign_or_incomplete_state(edit, message):
    from logscan.errors import InputError

    detector = ArrayStateDetector()
    detector.table_, detector.limit_ = np.zeros(2), 1.0
    state = detector.to_state()
    edit(state)
    with pytest.raises(InputError, match=message):
        ArrayStateDetector.from_state(state, path="tables.json")


def test_to_state_and_run_need_training_and_run_needs_the_trace():
    from logscan.errors import UsageError

    with pytest.raises(NotTrainedError, match="not trained"):
        ArrayStateDetector().to_state()
    detector = ArrayStateDetector()
    detector.table_, detector.limit_ = np.zeros(2), 1.0
    with pytest.raises(UsageError, match="needs the filter trace"):
        detector.run(synthetic_run())


def test_parameters_never_shadow_methods():
    detector = ContractProbeDetector(run=1)
    assert callable(detector.run) and detector.params["run"] == 1
    with pytest.raises(AttributeError):
        detector.no_such_thing


def test_result_with_wrong_shape_is_an_internal_error():
    from logscan.errors import InternalError

    class Broken(ContractProbeDetector):
        def _run(self, run, trace, **context):
            result = self.new_result()
            result.series["x"] = np.zeros(3)
            return result

    detector = Broken().fit([synthetic_run()])
    with pytest.raises(InternalError, match="grid has 400 steps"):
        detector.run(synthetic_run())


def test_result_to_dict_summarises_and_full_mode_has_values():
    run = synthetic_run(3, burst=True)
    result = ContractProbeDetector().fit([synthetic_run(1)]).run(run)
    summary = result.to_dict()
    assert summary["n_alarms"] == 1 and summary["alarms"][0]["signal"] == "/imu/acc.x"
    assert summary["series"]["/imu/acc.x"]["n"] == 400 and "series_values" not in summary
    full = result.to_dict(summary_only=False)
    assert len(full["series_values"]["/imu/acc.x"]) == 400
    assert full["thresholds"]["/imu/acc.x"]["upper"][0] == 3.0
