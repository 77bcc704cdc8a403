"""The pipeline of one log: declared needs run each filter once, detector settings are checked before
any log is read, and no module outside detectors/ names a detector."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

from logscan.detectors.registry import default_registry
from logscan.errors import ProfileError
from logscan.needs import CodedVariance, Needs
from logscan.pipeline import analyze_log, create_detectors, load_profile_for, needs_of, prepare, stages

REPO = Path(__file__).resolve().parents[1]
SAMPLES = REPO / "sample_logs"
HEALTHY = SAMPLES / "quad_healthy.mcap"


def test_needs_merge_filters_and_their_parts():
    merged = Needs.of(ekf=("K",)) | Needs.of(ekf=("S",)) | Needs()
    assert merged.parts("ekf") == {"K", "S"} and merged.wants("ekf") and not merged.wants("ubikf")


def test_the_encoded_checks_ask_for_the_predicted_variance_only_when_normalising_or_without_onboard_variances():
    loaded = load_profile_for(HEALTHY, None)
    (encoded,) = create_detectors(loaded, ["encoded_ekf"])
    raw = encoded.with_params(ex_statistic="raw")
    prepared = prepare(HEALTHY, loaded, Needs.of(ekf=()))
    assert prepared.run.onboard_variance is not None
    # the default e_x statistic (window_sum) is normalised by CV K S K^T CV^T, which the filter
    # computes with the detector's coding vector: never K and S
    coded = CodedVariance(encoded.sigma_floor, encoded.r_max)
    assert encoded.needs(prepared.run).parts("ekf") == {coded}
    assert raw.needs(prepared.run) == Needs.of(ekf=())
    prepared.run.onboard_variance = None
    assert raw.needs(prepared.run).parts("ekf") == {coded}
    assert raw.with_params(r_max=10.0).needs(prepared.run).parts("ekf") == {CodedVariance(encoded.sigma_floor, 10.0)}


def test_each_needed_filter_runs_exactly_once(monkeypatch):
    calls = []
    real = stages.FILTERS["ekf"]
    monkeypatch.setitem(
        stages.FILTERS, "ekf", lambda model, run, parts, **kw: calls.append(parts) or real(model, run, parts, **kw)
    )
    analysis = analyze_log(HEALTHY, detector_names=["encoded_ekf", "nis"])
    assert len(calls) == 1 and [r.detector for r in analysis.results] == ["encoded_ekf", "nis"]


def test_prepare_without_detectors_runs_no_filter():
    prepared = prepare(HEALTHY, load_profile_for(HEALTHY, None), Needs())
    assert prepared.traces == {} and prepared.trace is None and prepared.run.n_steps > 1


def _bad_profile(tmp_path, settings: str) -> Path:
    text = load_profile_for(HEALTHY, None).text + f"\n[detectors.nis]\n{settings}\n"
    path = tmp_path / "bad.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    "settings, message",
    [
        ("windw = 3", "unknown parameter(s) windw"),
        ("window = 0", "window must be an integer in [1, inf), got 0"),
        ("budget_per_hour = -1.0", "budget_per_hour must be a number in [1e-12, inf)"),
        ("alpha = 1.5", "alpha must be a number in [3e-14, 1)"),
        ('overall = "yes"', "overall must be true or false"),
    ],
)
def test_a_bad_detector_setting_is_refused_before_any_log_is_read(tmp_path, monkeypatch, cli, settings, message):
    def no_reading(*args, **kwargs):
        raise AssertionError("the log was read before the profile's detector settings were checked")

    # the module that reads (the package's `prepare` is a function of that name)
    monkeypatch.setattr(importlib.import_module("logscan.pipeline.preparation"), "read_log", no_reading)
    profile = _bad_profile(tmp_path, settings)
    with pytest.raises(ProfileError, match=message.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[")):
        analyze_log(HEALTHY, profile)
    result = cli("analyze", HEALTHY, "--profile", profile, "--no-report")
    assert result.exit_code == 2
    assert message in result.stderr and str(profile) in result.stderr


def test_detectors_command_shows_each_parameter_with_its_constraint(cli):
    result = cli("detectors")
    assert result.exit_code == 0
    assert "nis parameters" in result.output
    line = next(line for line in result.output.splitlines() if line.strip().startswith("rho_v "))
    assert "default 8.0" in line and "a number in (0, 50]" in line and "it would hide faults" in line


def test_every_builtin_parameter_has_a_declared_constraint():
    registry = default_registry()
    for entry in registry.entries():
        if entry.origin == "built-in":
            assert set(entry.cls.parameter_constraints) == set(entry.cls.defaults), entry.name
            entry.cls().check_params()  # the defaults satisfy their own constraints


def _string_constants(tree: ast.AST) -> set[str]:
    """String literals of a module, except docstrings and the keys of dicts and subscripts (a
    filter's own quantity, e.g. its "nis" array, is not a reference to a detector)."""
    skipped = {
        id(node.body[0].value)
        for node in ast.walk(tree)
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
        and node.body
        and isinstance(node.body[0], ast.Expr)
        and isinstance(node.body[0].value, ast.Constant)
    }
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            skipped.update(id(key) for key in node.keys if key is not None)
        elif isinstance(node, ast.Subscript):
            skipped.add(id(node.slice))
    return {
        node.value
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skipped
    }


def test_no_module_outside_detectors_names_a_detector():
    names = set(default_registry().names())
    offenders = []
    for path in sorted((REPO / "logscan").rglob("*.py")):
        named = names & _string_constants(ast.parse(path.read_text()))
        offenders += [f"{path.relative_to(REPO)}: {name}" for name in sorted(named)]
    assert offenders == []


def test_needs_of_is_the_union_over_detectors():
    loaded = load_profile_for(HEALTHY, None)
    detectors = create_detectors(loaded, ["encoded_ekf", "nis"])
    prepared = prepare(HEALTHY, loaded, needs_of(detectors))
    assert set(prepared.traces) == {"ekf"}
