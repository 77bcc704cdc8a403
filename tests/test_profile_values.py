"""Profile values that would hide a fault are refused (exit 2, one line), and a profile's physical
range of a measurement group reaches the filter."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import SAMPLES

from logscan.align import align
from logscan.filters import run_ekf
from logscan.log import Channel, Log, SourceInfo
from logscan.models import get_model
from logscan.profiles import parse_profile

# ------------------------------------------------------------------------------------------------
# range_lo / range_hi of the profile are the filter's physical range
# ------------------------------------------------------------------------------------------------

RANGE_PROFILE = """
[vehicle]
model = "linear"
rate_hz = 100

[vehicle.params]
A = [[0.0, 0.0], [0.0, 0.0]]
B = [[0.0], [0.0]]
C = { a = [[1.0, 0.0]], b = [[1.0, 0.0], [0.0, 1.0]] }
R = { a = [0.1], b = [0.1, 0.1] }
range = { a = [-2.0, 2.0] }

[inputs]
u0 = "/u"

[measurements.a]
channels = ["/a"]
rate_hz = 100

[measurements.b]
channels = ["/b0", "/b1"]
rate_hz = 100
"""
PROFILE_RANGE = "range_lo = [-1.0, -3.0]\nrange_hi = [1.0, 3.0]\n"


def range_log() -> Log:
    """100 Hz channels, zero except a few samples near the ranges' edges (step -> value)."""
    t = np.arange(50, dtype=np.int64) * 10_000_000
    values = {"/u": {}, "/a": {5: 1.5, 6: 2.5}, "/b0": {10: 1.001, 11: 0.999}, "/b1": {12: 2.9, 14: 3.1}}
    channels = {}
    for name, spikes in values.items():
        v = np.zeros(t.size)
        for step, value in spikes.items():
            v[step] = value
        channels[name] = Channel(name, t, v)
    return Log(channels, SourceInfo("range.mcap", "mcap"))


def rejected_steps(profile_text: str) -> dict[str, list[int]]:
    profile = parse_profile(profile_text)
    trace = run_ekf(get_model("linear", profile.vehicle.params), align(range_log(), profile))
    return {g: np.flatnonzero(trace.rejected[:, trace.group_index(g)]).tolist() for g in ("a", "b")}


def test_a_profile_range_rejects_what_the_model_range_accepts_and_keeps_what_is_inside():
    # the model's range for b is +-1e12: nothing of b is rejected without the profile's range
    assert rejected_steps(RANGE_PROFILE) == {"a": [6], "b": []}
    # with it: 1.001 > 1 (channel b0) and 3.1 > 3 (channel b1) are rejected; 0.999 and 2.9 are not;
    # group a has no profile range and keeps the model's (+-2: 2.5 rejected, 1.5 kept)
    assert rejected_steps(RANGE_PROFILE + PROFILE_RANGE) == {"a": [6], "b": [10, 14]}


def test_a_profile_range_may_also_widen_the_models():
    wide = RANGE_PROFILE.replace("[measurements.b]", "range_lo = -3.0\nrange_hi = 3.0\n\n[measurements.b]", 1)
    assert rejected_steps(wide) == {"a": [], "b": []}


# ------------------------------------------------------------------------------------------------
# Crippling values on a log with a real fault: exit 2 with one clear line, never "no alarms"
# ------------------------------------------------------------------------------------------------

LINEAR_ACCEL = """
[vehicle]
model = "linear"
rate_hz = 100.0

[vehicle.params]
A = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
B = [[0.0], [0.0], [0.0]]
C = { accel = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] }
Q = [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]]
R = { accel = [0.1, 0.1, 0.1] }
states = ["ax", "ay", "az"]
inputs = ["thrust"]

[inputs]
thrust = "/cmd/thrust"

[measurements.accel]
channels = ["/imu/accel.x", "/imu/accel.y", "/imu/accel.z"]
rate_hz = 100.0
stale_s = 0.025
"""
EMBEDDED_NOISE = "noise_std = [0.1, 0.1, 0.1]"  # the accelerometer's line in the embedded profile

# (name, base profile: "embedded" or "linear", line replaced, replacement, words the message holds)
CRIPPLED = [
    (
        "noise_std 1e300",
        "embedded",
        EMBEDDED_NOISE,
        "noise_std = 1e300",
        ["noise_std: 1e+300 would hide every fault of the group"],
    ),
    (
        "noise_std 1e6",
        "embedded",
        EMBEDDED_NOISE,
        "noise_std = 1e6",
        ["noise_std: 1e+06", "exceeds the group's range span 320"],
    ),
    ("noise_std nan", "embedded", EMBEDDED_NOISE, "noise_std = nan", ["noise_std: must be > 0 and finite"]),
    ("range inf", "embedded", EMBEDDED_NOISE, "range_hi = inf", ["range_hi: must be finite, got inf"]),
    ("stale_s 0", "embedded", "stale_s = 0.025", "stale_s = 0", ["stale_s: must be > 0, got 0"]),
    (
        "q_accel 1e200",
        "embedded",
        'model = "quadcopter"',
        'model = "quadcopter"\nparams = { q_accel = 1e200 }',
        ["process noise Q at dt = 0.01 s has non-finite entries"],
    ),
    ("R nan", "linear", "R = { accel = [0.1, 0.1, 0.1] }", "R = { accel = nan }", ["R[accel] standard deviations"]),
    ("R [[-1]]", "linear", "R = { accel = [0.1, 0.1, 0.1] }", "R = [[-1.0]]", ["R must be a table"]),
    (
        "R not PD",
        "linear",
        "R = { accel = [0.1, 0.1, 0.1] }",
        "R = { accel = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]] }",
        ["R[accel] is not positive definite"],
    ),
    (
        "Q not PSD",
        "linear",
        "Q = [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]]",
        "Q = [[0.01, 0.0, 0.0], [0.0, -0.01, 0.0], [0.0, 0.0, 0.01]]",
        ["Q is not positive semi-definite"],
    ),
    (
        "R for a missing group",
        "linear",
        "R = { accel = [0.1, 0.1, 0.1] }",
        "R = { accel = [0.1, 0.1, 0.1], gps = [0.5] }",
        ["R given for group 'gps' but C has no such group"],
    ),
    ("duplicate states", "linear", 'states = ["ax", "ay", "az"]', 'states = ["ax", "ax", "az"]', ["'ax' twice"]),
]


@pytest.fixture(scope="module")
def embedded_text():
    """The profile quad_imu_bias.mcap embeds, as TOML text."""
    from logscan.pipeline import load_profile_for

    path = SAMPLES / "quad_imu_bias.mcap"
    if not path.exists():
        pytest.skip(f"{path} missing (run sample_logs/make_samples.py)")
    return load_profile_for(path, None).text


def write_profile(tmp_path, text: str, old: str, new: str):
    assert text.count(old) >= 1, old
    path = tmp_path / "crippled.toml"
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    return path


def test_the_sane_profiles_find_the_fault(cli, sample, tmp_path, embedded_text):
    """Both base profiles raise alarms on the biased accelerometer: a crippled value hides a real
    fault, so exit 0 there would be a wrong verdict."""
    log = sample("quad_imu_bias.mcap")
    for text in (embedded_text, LINEAR_ACCEL):
        result = cli("analyze", log, "--profile", write_profile(tmp_path, text, "\n", "\n"), "--no-report")
        assert result.exit_code == 1, result.stdout + result.stderr
        assert "accel" in result.stdout


@pytest.mark.parametrize("name, base, old, new, words", CRIPPLED, ids=[c[0] for c in CRIPPLED])
def test_a_crippling_profile_value_stops_analyze_with_one_clear_line(
    cli, sample, tmp_path, embedded_text, name, base, old, new, words
):
    log = sample("quad_imu_bias.mcap")
    path = write_profile(tmp_path, embedded_text if base == "embedded" else LINEAR_ACCEL, old, new)
    result = cli("analyze", log, "--profile", path, "--no-report")
    assert result.exit_code == 2, result.stdout + result.stderr
    assert "no alarms" not in result.stdout
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(f"logscan: error: {path}: invalid profile: ")
    for word in words:
        assert word in lines[0]
