"""Settings that would hide faults are refused with the reason: a false-alarm design rate under
1e-12 per hour, or a multiplier over the bound its parameter declares (issue 31)."""

from __future__ import annotations

import math

import pytest

from logscan.detectors.params import MIN_ALPHA, MIN_DESIGN_RATE_PER_HOUR, SLOWEST_TESTS_PER_HOUR, Interval
from logscan.detectors.registry import BUILTIN, Registry
from logscan.errors import ProfileError

SAMPLE = "quad_imu_bias.mcap"

# (detector, setting, words of the reason)
HIDING = [
    ("encoded_ekf", "rho = 1e308", ["rho must be a number in (0, 50]", "it would hide faults", "got 1e+308"]),
    ("nis", "alpha = 1e-300", ["alpha must be", "under 1e-12 false alarms per hour", "got 1e-300"]),
    ("cusum", "alpha = 1e-300", ["unknown parameter(s) alpha"]),  # cusum has no alpha: h and the budget
    ("cusum", "h = 1e300", ["h must be a number in (0, 1000]", "it would hide faults"]),
    ("cusum", "h = 500.0", ["h = 500 at kappa = 0.25", "under 1e-12 false alarms per hour", "use h <="]),
    ("cusum", "budget_per_hour = 1e-300", ["budget_per_hour must be", "designs a test that never alarms"]),
    ("cusum", "clip = 0.1", ["clip = 0.1 is not above kappa = 0.25"]),
    ("nis", "budget_per_hour = 1e-13", ["under 1e-12 false alarms per hour"]),
]


def _profile_with(tmp_path, embedded: str, detector: str, setting: str):
    text = embedded + f"\n[detectors.{detector}]\n{setting}\n"
    path = tmp_path / "hiding.toml"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize("detector, setting, words", HIDING, ids=[f"{d} {s}" for d, s, _ in HIDING])
def test_a_fault_hiding_setting_is_exit_2_with_its_reason(cli, sample, tmp_path, detector, setting, words):
    from logscan.readers import read_embedded_profile

    log = sample(SAMPLE)
    text = read_embedded_profile(log)
    assert f"[detectors.{detector}]" not in text
    result = cli("analyze", log, "--profile", _profile_with(tmp_path, text, detector, setting), "--no-report")
    assert result.exit_code == 2, result.stdout + result.stderr
    assert "no alarms" not in result.stdout
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    for word in words:
        assert word in lines[0], lines[0]


def _entries():
    return [e for e in Registry(plugins=[]).entries() if e.origin == BUILTIN and e.ok]


def _bounded(constraints: list) -> list[Interval]:
    return [c for c in constraints if isinstance(c, Interval) and c.why]


def _threshold_like(name: str) -> bool:
    """Parameters that set how far a statistic may go before an alarm, or how rare a false alarm is."""
    words = ("rho", "alpha", "budget", "threshold", "margin", "ratio", "limit", "persist", "jump", "periods")
    return name in ("h", "n_samples", "min_duration_s") or any(w in name for w in words)


PARAMS = [
    (entry.cls, key)
    for entry in _entries()
    for key in entry.cls.defaults
    if _threshold_like(key) and key in entry.cls.parameter_constraints
]
# no multiplier to bound: thresholds in the statistic's own unit, and a share already bounded by 1
UNBOUNDED = {
    ("encoded_ekf", "threshold"): "an absolute threshold in the statistic's unit (the user's)",
    ("atfm", "margin"): "a selection margin in the sensor's unit, not a threshold",
    ("frozen", "still_ratio"): "a share of the noise in [0, 1): a larger one flags more, never less",
    (
        "kgn",
        "envelope_margin",
    ): "widens the trained envelope; windows outside it are reported not checked, never passed",
}


@pytest.mark.parametrize("cls, key", PARAMS, ids=[f"{c.name}.{k}" for c, k in PARAMS])
def test_every_threshold_like_parameter_declares_its_fault_hiding_bound(cls, key):
    bounds = _bounded(cls.parameter_constraints[key])
    if (cls.name, key) in UNBOUNDED:
        pytest.skip(UNBOUNDED[cls.name, key])
    assert bounds, f"{cls.name}.{key}: no bound with its reason (Interval(..., why=...))"
    default = cls.defaults[key]
    if default is not None:
        assert any(b.accepts(default) for b in bounds), f"{cls.name}.{key}: default {default} outside its bound"
    for bound in bounds:
        beyond = []
        if bound.high is not None:
            beyond.append(bound.high * 2 + 1 if bound.kind is int else 1e308)
        if bound.low is not None and bound.low > 0 and bound.kind is float:
            beyond.append(1e-300)
        assert beyond, f"{cls.name}.{key}: its bound states no limit"
        for value in beyond:
            value = int(value) if bound.kind is int else value
            with pytest.raises(ProfileError) as caught:
                cls(**{key: value}).check_params()
            line = caught.value.one_line()
            assert bound.why in line and "\n" not in line


@pytest.mark.parametrize("entry", _entries(), ids=lambda e: e.name)
def test_every_default_configuration_is_accepted(entry):
    entry.cls().check_params()


def test_the_smallest_alpha_keeps_the_design_rate_at_the_floor():
    assert MIN_ALPHA * SLOWEST_TESTS_PER_HOUR >= MIN_DESIGN_RATE_PER_HOUR
    assert math.isclose(MIN_ALPHA * SLOWEST_TESTS_PER_HOUR, MIN_DESIGN_RATE_PER_HOUR, rel_tol=0.1)


def test_the_listing_shows_the_bounds_and_reasons(cli):
    result = cli("detectors")
    assert result.exit_code == 0
    assert "a number in (0, 50] (over 50 spreads" in result.stdout
    assert "designs a test that never alarms" in result.stdout
