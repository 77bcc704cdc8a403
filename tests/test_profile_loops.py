"""Hierarchical profiles: [loops.<name>] tables parsed as profiles of their own, and [recovery]."""

from __future__ import annotations

import pytest

from logscan.errors import ProfileError
from logscan.profiles import parse_profile

MOTOR = (
    'vehicle = { model = "linear", rate_hz = 100.0, params = { A = [[1.0, 0.01], [0.0, 1.0]], '
    "B = [[0.0], [0.01]], C = { encoder = [[0.0, 1.0]] }, continuous = false, dt = 0.01 } }\n"
    'inputs = { u0 = "/volt" }\n'
)
BASE = f"""
[vehicle]
model = "linear"
rate_hz = 10.0
loop = "outer"
params = {{ A = [[0.0]], B = [[1.0]], C = [[1.0]] }}
[inputs]
u0 = "/u"
[measurements.y]
channels = ["/y"]
rate_hz = 10.0
[loops.left_motor]
{MOTOR}
[loops.left_motor.measurements.encoder]
channels = ["/enc"]
rate_hz = 100.0
noise_std = [1.0]
"""


def test_loops_parse_and_round_trip():
    profile = parse_profile(BASE + '[recovery]\ndetector = "oracle"\nallowed_error = { "outer.x0" = 1.5 }\n')
    assert profile.loop_name == "outer"
    assert list(profile.loops) == ["left_motor"]
    motor = profile.loops["left_motor"]
    assert motor.vehicle.rate_hz == 100.0 and motor.loop_name == "left_motor"
    assert motor.measurements["encoder"].channels == ["/enc"]
    assert profile.topics() == {"/u", "/y", "/volt", "/enc"}
    assert profile.recovery.detector == "oracle" and profile.recovery.settings == {"allowed_error": {"outer.x0": 1.5}}
    assert parse_profile(profile.to_toml()) == profile


def test_a_profile_without_loops_is_one_loop_called_main():
    profile = parse_profile(BASE.split("[loops.left_motor]")[0].replace('loop = "outer"\n', ""))
    assert profile.loop_name == "main" and profile.loops == {} and profile.recovery is None


def test_a_loop_is_checked_against_its_own_model_and_named_in_the_problem():
    bad = BASE.replace('inputs = { u0 = "/volt" }', 'inputs = { volts = "/volt" }')
    with pytest.raises(ProfileError) as info:
        parse_profile(bad)
    assert "[loops.left_motor] [inputs]" in str(info.value) and "volts" in str(info.value)


@pytest.mark.parametrize(
    ("recovery", "expected"),
    [
        ('method = "rewind"', "method: must be one of refilter, rollforward, replace"),
        ("k_sigma = 0", "k_sigma: must be > 0"),
        ('allowed_error = { "inner.x" = 1.0 }', "'inner.x': expected 'loop.state'"),
        ("checkpoint_every = 1.0", "unknown key 'checkpoint_every'"),
    ],
)
def test_recovery_table_problems(recovery, expected):
    with pytest.raises(ProfileError) as info:
        parse_profile(BASE + "[recovery]\n" + recovery + "\n")
    assert expected in " ".join(info.value.problems)


def test_a_loop_may_not_take_the_primary_loops_name():
    with pytest.raises(ProfileError) as info:
        parse_profile(BASE.replace("[loops.left_motor", "[loops.outer"))
    assert "the top level is already the loop 'outer'" in " ".join(info.value.problems)
