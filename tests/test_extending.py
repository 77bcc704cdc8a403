"""docs/extending.md followed step by step: its example detector (one file plus one registry line),
its example linear model (one class module plus one registry line), its nonlinear model (kernels,
class, registry lines) and its reader (one function plus one registration) work end to end."""

from __future__ import annotations

import importlib.util
import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from logscan.detectors.registry import BUILTIN_DETECTORS, Registry

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "extending.md"
SAMPLES = REPO / "sample_logs"


def code_after(heading: str, language: str = "python", index: int = 0) -> str:
    """The ``index``-th fenced code block of ``language`` after ``heading`` in docs/extending.md."""
    text = DOC.read_text()
    rest = text[text.index(heading) :]
    blocks = re.findall(rf"```{language}\n(.*?)```", rest, flags=re.S)
    return blocks[index]


def registry_line(block: str) -> str:
    """The line the doc adds to a registry table (marked as the new one or the only entry)."""
    lines = [ln for ln in block.splitlines() if "# the new line" in ln] or [
        ln for ln in block.splitlines() if ln.strip().startswith('"')
    ]
    return lines[-1]


@pytest.fixture
def new_detector(tmp_path, monkeypatch):
    """The doc's detector file written as a module, and the registry with the doc's new line."""
    source = code_after("### 1. The file: `detectors/innovation_mean.py`")
    (tmp_path / "innovation_mean.py").write_text(source)
    monkeypatch.syspath_prepend(str(tmp_path))
    line = registry_line(code_after("### 2. The registry line"))
    spec = re.search(r'"logscan\.detectors\.(\w+):(\w+)"', line)
    assert spec, line
    registry = Registry(builtins=BUILTIN_DETECTORS + [f"{spec.group(1)}:{spec.group(2)}"], plugins=[])
    monkeypatch.setattr("logscan.detectors.registry._DEFAULT", registry)
    return registry


def test_the_new_detector_loads_with_its_declared_parameters(new_detector, cli):
    assert new_detector.warnings() == []
    assert "innovation_mean" in new_detector.names()
    result = cli("detectors", "--json", "-")
    entry = next(d for d in json.loads(result.output)["detectors"] if d["name"] == "innovation_mean")
    assert [p["name"] for p in entry["parameters"]] == ["window", "alpha", "n_persist"]
    with pytest.raises(Exception, match="window must be an integer"):
        new_detector.create("innovation_mean", {"window": 1})


def test_the_new_detector_runs_through_the_pipeline_and_is_scored(new_detector):
    from logscan.pipeline import analyze_log
    from logscan.verdict.evaluation import evaluate_analysis

    analysis = analyze_log(SAMPLES / "quad_imu_bias.mcap", detector_names=["innovation_mean"])
    (result,) = analysis.results
    assert set(result.series) == {f"innovation_mean.{g}" for g in analysis.trace.group_names}
    accel = [a for a in result.alarms if a.signal == "innovation_mean.accel"]
    assert accel and 30.0 <= accel[0].start < 31.0  # the +1 m/s^2 bias on accel.x starts at 30 s
    scores = evaluate_analysis(analysis).scores
    assert scores["innovation_mean:accel"].tp == 1


def test_the_new_detector_runs_in_logscan_analyze_with_its_words(new_detector, cli, tmp_path):
    out = tmp_path / "summary.json"
    log = SAMPLES / "quad_imu_bias.mcap"
    result = cli("analyze", log, "-d", "innovation_mean", "--no-report", "--json", out)
    assert result.exit_code == 1, result.stderr  # alarms raised
    (entry,) = json.loads(out.read_text())["logs"][0]["detectors"]
    assert entry["detector"] == "innovation_mean"
    assert "innovation_mean.accel" in entry["series"]
    assert "innovation_mean.accel" in {a["signal"] for a in entry["alarms"]}
    for signal in entry["series"]:  # tests/test_words.py's rule: plain words for every statistic
        assert entry["labels"][signal] and len(entry["labels"][signal]) > 15, entry["labels"]
    assert "accelerometer" in entry["labels"]["innovation_mean.accel"]


def test_the_new_detector_raises_nothing_on_the_healthy_sample(new_detector):
    from logscan.pipeline import analyze_log

    analysis = analyze_log(SAMPLES / "quad_healthy.mcap", detector_names=["innovation_mean"])
    assert analysis.alarms == []


@pytest.fixture
def new_model(tmp_path, monkeypatch):
    """The doc's linear model written as a module, and the model registry with the doc's line."""
    from logscan import models

    (tmp_path / "spring_cart.py").write_text(code_after("### A linear (or linearised) model"))
    monkeypatch.syspath_prepend(str(tmp_path))
    line = registry_line(code_after("### A linear (or linearised) model", index=1))
    name, spec = re.match(r'\s*"(\w+)": "logscan\.models\.(\w+:\w+)"', line).groups()
    monkeypatch.setitem(models._REGISTRY, name, spec)
    return models.get_model(name)


def _contract_module():
    spec = importlib.util.spec_from_file_location("model_contract", REPO / "tests" / "test_model_contract.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(
    "check",
    [
        "test_states_inputs_groups_and_defaults_have_consistent_shapes",
        "test_measurement_jacobian_H_matches_central_differences_of_h_per_group",
        "test_in_place_kernels_equal_the_allocating_ones",
        "test_direct_groups_really_observe_their_states",
        "test_parameters_round_trip_through_describe_and_json",
        "test_unknown_model_id_is_a_clear_model_error_before_any_kernel_runs",
    ],
)
def test_the_new_model_passes_the_model_contract(new_model, check):
    getattr(_contract_module(), check)(new_model.name, None)


def test_the_new_model_discrete_jacobian_matches_differences(new_model):
    _contract_module().test_discrete_jacobian_F_matches_central_differences_of_f(new_model.name, None, 0.01)


def test_the_new_model_is_filtered_by_the_shared_ekf(new_model):
    from logscan.align import AlignedGroup, AlignedRun
    from logscan.filters import run_ekf
    from logscan.models import dispatch

    n, dt = 500, 0.01
    rng = np.random.default_rng(3)
    t = np.arange(n) * dt
    force = np.sin(t)[:, None]
    x = np.zeros(2)
    truth = np.empty((n, 2))
    for k in range(n):
        truth[k] = x
        x = new_model.f(x, force[k], dt)
    z = truth[:, :1] + rng.normal(0.0, 0.01, (n, 1))
    group = AlignedGroup("position", ["/cart/x"], z, np.ones(n, bool))
    run = AlignedRun(
        t=t,
        dt=dt,
        start_ns=0,
        u=force,
        u_fresh=np.ones(n, bool),
        input_channels=["/cart/force"],
        groups={"position": group},
    )
    trace = run_ekf(new_model, run)
    assert dispatch.MODEL_IDS[new_model.model_id] == "linear"  # the shared linear kernels
    assert np.abs(trace.x_post[-100:, 0] - truth[-100:, 0]).max() < 0.05
    assert 0.5 < np.nanmean(trace.nis) < 2.0  # consistent: mean NIS per measurement about 1


@pytest.fixture
def nonlinear_model(tmp_path, monkeypatch):
    """The doc's pendulum: its kernels and class modules written into a folder searched as part of
    `logscan.models`, its dispatch registry line run (the import that registers the kernels), its
    model registry line added. The EKF compiled for its id is kept out of the disk cache (the id
    is the doc's, not the repository's)."""
    from numba.core.caching import NullCache

    from logscan import models
    from logscan.filters import ekf

    heading = "### A nonlinear model"
    (tmp_path / "pendulum_kernels.py").write_text(code_after(heading, index=0))
    (tmp_path / "pendulum.py").write_text(code_after(heading, index=1))
    monkeypatch.setattr(models, "__path__", [*models.__path__, str(tmp_path)])
    monkeypatch.setattr(ekf.ekf_run, "_cache", NullCache())
    dispatch_line = code_after(heading, index=2).strip()
    assert dispatch_line.startswith("from logscan.models.pendulum_kernels import") and "\n" not in dispatch_line
    namespace: dict = {}
    exec(dispatch_line, namespace)
    line = registry_line(code_after(heading, index=3))
    name, spec = re.match(r'\s*"(\w+)": "(logscan\.models\.\w+:\w+)"', line).groups()
    monkeypatch.setitem(models._REGISTRY, name, spec)
    yield models.get_model(name)
    from logscan.models import model_kernels

    for table in (model_kernels.REGISTRY, model_kernels.MODEL_IDS):
        table.pop(namespace["PENDULUM_ID"], None)
    for module in ("logscan.models.pendulum", "logscan.models.pendulum_kernels"):
        sys.modules.pop(module, None)


@pytest.mark.parametrize(
    "check",
    [
        "test_model_id_is_dispatched_under_the_registered_name",
        "test_states_inputs_groups_and_defaults_have_consistent_shapes",
        "test_measurement_jacobian_H_matches_central_differences_of_h_per_group",
        "test_direct_groups_really_observe_their_states",
        "test_parameters_round_trip_through_describe_and_json",
        "test_unknown_model_id_is_a_clear_model_error_before_any_kernel_runs",
    ],
)
def test_the_nonlinear_model_passes_the_model_contract(nonlinear_model, check):
    getattr(_contract_module(), check)(nonlinear_model.name, None)


def test_the_nonlinear_model_discrete_jacobian_matches_differences(nonlinear_model):
    _contract_module().test_discrete_jacobian_F_matches_central_differences_of_f(nonlinear_model.name, None, 0.01)


def test_the_nonlinear_model_is_filtered_by_the_shared_ekf(nonlinear_model):
    from logscan.align import AlignedGroup, AlignedRun
    from logscan.filters import run_ekf

    n, dt = 1000, 0.01
    rng = np.random.default_rng(5)
    t = np.arange(n) * dt
    torque = 0.5 * np.sin(2.0 * t)[:, None]
    x = np.array([0.8, 0.0])
    truth = np.empty((n, 2))
    for k in range(n):
        x = nonlinear_model.f(x, torque[k], dt)
        truth[k] = x
    z = truth[:, :1] + rng.normal(0.0, 0.01, (n, 1))
    run = AlignedRun(
        t=t,
        dt=dt,
        start_ns=0,
        u=torque,
        u_fresh=np.ones(n, bool),
        input_channels=["/pendulum/torque"],
        groups={"angle": AlignedGroup("angle", ["/pendulum/theta"], z, np.ones(n, bool))},
    )
    trace = run_ekf(nonlinear_model, run, x0=np.array([0.8, 0.0]))
    assert np.abs(trace.x_post[-200:, 0] - truth[-200:, 0]).max() < 0.05
    assert np.abs(trace.x_post[-200:, 1] - truth[-200:, 1]).max() < 0.3  # the unmeasured rate


@pytest.fixture
def new_reader(tmp_path, monkeypatch):
    """The doc's reader module written into a folder searched as part of `logscan.readers`, its
    registration line run; the registered reader removed afterwards."""
    from logscan import readers

    heading = "## Adding a reader"
    (tmp_path / "kv_reader.py").write_text(code_after(heading, index=0))
    monkeypatch.setattr(readers, "__path__", [*readers.__path__, str(tmp_path)])
    monkeypatch.setattr(readers, "READERS", dict(readers.READERS))
    line = code_after(heading, index=1).strip()
    assert line.startswith("from logscan.readers import kv_reader") and "\n" not in line
    exec(line, {})
    yield readers.READERS["kv"]
    sys.modules.pop("logscan.readers.kv_reader", None)
    del readers.kv_reader  # the next import runs the module (and its registration) again


def write_tank_log(path: Path, bias_from_s: float | None = None) -> Path:
    """60 s of the doc's tank (x' = -2 x + 2 u) at 100 Hz in the doc's text format, level noise
    0.01; a +0.1 offset on the level sensor from ``bias_from_s`` on."""
    dt, n = 0.01, 6000
    rng = np.random.default_rng(11)
    a = np.exp(-2.0 * dt)
    x, lines = 0.0, []
    for k in range(n):
        t = k * dt
        valve = 0.5 + 0.3 * np.sin(0.5 * t)
        level = x + rng.normal(0.0, 0.01) + (0.1 if bias_from_s is not None and t >= bias_from_s else 0.0)
        lines.append(f"t={t:.2f} valve={valve:.5f} level={level:.5f}")
        x = a * x + (1.0 - a) * valve + rng.normal(0.0, np.sqrt(0.01 * dt))
    path.write_text("\n".join(lines) + "\n")
    return path


def test_the_doc_example_lines_are_read_by_the_new_reader(new_reader, tmp_path, cli):
    from logscan.readers import detect_format, read_log

    example = tmp_path / "example.kv"
    example.write_text(code_after("## Adding a reader", language="text"))
    assert detect_format(example) == "kv"
    log = read_log(example)
    assert sorted(log.channels) == ["level", "valve"]
    assert log.channels["level"].t.tolist() == [0, 10_000_000, 20_000_000]
    assert read_log(example, topics=["level"]).channels.keys() == {"level"}
    result = cli("inspect", example, "--json", "-")
    assert result.exit_code == 0, result.stderr
    facts = json.loads(result.output)
    assert facts["format"] == "kv" and set(facts["channels"]) == {"level", "valve"}


def test_builtin_formats_are_still_detected_first(new_reader):
    from logscan.readers import detect_format

    assert detect_format(SAMPLES / "quad_imu_bias.mcap") == "mcap"
    assert detect_format(SAMPLES / "quad_healthy.csv") == "csv"
    with pytest.raises(ValueError, match="built-in"):
        from logscan.readers import register_reader

        register_reader("csv", new_reader.sniff, new_reader.read)


def test_a_log_of_the_new_format_is_analysed_with_the_doc_profile(new_reader, tmp_path, cli):
    profile = tmp_path / "tank.toml"
    profile.write_text(code_after("## Adding a reader", language="text", index=1))
    healthy = write_tank_log(tmp_path / "tank.kv")
    out = tmp_path / "summary.json"
    result = cli("analyze", healthy, "--profile", profile, "--no-report", "--json", out)
    assert result.exit_code == 0, result.stdout + result.stderr
    entry = json.loads(out.read_text())["logs"][0]
    assert entry["detectors"] and all(d["alarms"] == [] for d in entry["detectors"])
    biased = write_tank_log(tmp_path / "tank_bias.kv", bias_from_s=30.0)
    result = cli("analyze", biased, "--profile", profile, "--no-report", "--json", out)
    assert result.exit_code == 1, result.stdout + result.stderr
    alarms = [a for d in json.loads(out.read_text())["logs"][0]["detectors"] for a in d["alarms"]]
    assert alarms and 30.0 <= min(a["start"] for a in alarms) < 32.0


_PENDULUM_CLI = """\
import sys

from logscan import models

models.__path__.append(sys.argv[1])
exec(sys.argv[2])  # the doc's registry line of logscan/models/dispatch.py
name, spec = sys.argv[3].split("=", 1)  # the doc's line of the _REGISTRY table
models._REGISTRY[name] = spec
models.MODEL_NAMES = tuple(models._REGISTRY)  # as when the line is in the table's source

from logscan.cli.main import main  # after the registration, as in the installed package

main(sys.argv[4:])
"""


def test_the_nonlinear_model_runs_in_logscan_analyze(nonlinear_model, tmp_path):
    """`logscan analyze` on a CSV log of the pendulum, in a fresh process with a fresh cache
    directory: the doc's id is not one of the repository's, so no compiled kernel may be reused or
    left behind for it. An angle sensor offset of 0.1 rad from 10 s on is seen by `nis`."""
    import os
    import subprocess

    heading = "### A nonlinear model"
    package = tmp_path / "models"
    package.mkdir()
    (package / "pendulum_kernels.py").write_text(code_after(heading, index=0))
    (package / "pendulum.py").write_text(code_after(heading, index=1))
    name, spec = re.match(
        r'\s*"(\w+)": "(logscan\.models\.\w+:\w+)"', registry_line(code_after(heading, index=3))
    ).groups()
    n, dt = 2000, 0.01
    rng = np.random.default_rng(7)
    t = np.arange(n) * dt
    torque = 0.5 * np.sin(2.0 * t)
    x, theta = np.array([0.8, 0.0]), np.empty(n)
    for k in range(n):
        theta[k] = x[0]
        x = nonlinear_model.f(x, torque[k : k + 1], dt)
    theta += rng.normal(0.0, 0.01, n) + np.where(t >= 10.0, 0.1, 0.0)
    log = tmp_path / "pendulum.csv"
    rows = [f"{round(tk * 1e9)},{uk:.6f},{zk:.6f}" for tk, uk, zk in zip(t, torque, theta)]
    log.write_text("time_ns,/pendulum/torque,/pendulum/theta\n" + "\n".join(rows) + "\n")
    profile = tmp_path / "pendulum.toml"
    profile.write_text(
        f'[vehicle]\nmodel = "{name}"\nrate_hz = 100\n[inputs]\ntorque = "/pendulum/torque"\n'
        '[measurements.angle]\nchannels = ["/pendulum/theta"]\nrate_hz = 100\n'
    )
    out = tmp_path / "summary.json"
    args = ["analyze", log, "--profile", profile, "-d", "nis", "--no-report", "--json", out]
    env = {**os.environ, "LOGSCAN_CACHE_DIR": str(tmp_path / "cache")}
    env.pop("NUMBA_CACHE_DIR", None)
    proc = subprocess.run(
        [sys.executable, "-c", _PENDULUM_CLI, str(package), code_after(heading, index=2).strip(), f"{name}={spec}"]
        + [str(a) for a in args],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert proc.returncode == 1, proc.stdout + proc.stderr  # alarms raised
    (entry,) = json.loads(out.read_text())["logs"][0]["detectors"]
    assert "nis.angle" in entry["series"]
    starts = [a["start"] for a in entry["alarms"] if a["signal"] == "nis.angle"]
    assert starts and 10.0 <= min(starts) < 11.0
