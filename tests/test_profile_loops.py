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


def test_recovery_takes_the_false_alarm_budget_of_its_kept_alarm():
    profile = parse_profile(BASE + "[recovery]\nbudget_per_hour = 0.05\nproof_hours = 200.0\n")
    assert profile.recovery.settings == {"budget_per_hour": 0.05, "proof_hours": 200.0}
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
        ("budget_per_hour = 0", "budget_per_hour: must be > 0"),
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


def test_input_stamp_start_holds_a_command_from_the_next_step(tmp_path):
    """u_k applied over [t_k, t_k+1) (a command stamped when issued) must drive x_k -> x_k+1: the
    EKF's step k+1, so alignment holds it from the next grid step; the default ("end") holds it at
    its own step (an IMU's increments over the step ending at their stamp)."""
    import numpy as np

    from logscan.align import align
    from logscan.log import Channel, Log, SourceInfo

    t_ns = (np.arange(20) * 1e8).astype(np.int64)  # 10 Hz, on the grid
    log = Log(
        channels={
            "/u": Channel("/u", t_ns, np.arange(20.0)),
            "/y": Channel("/y", t_ns, np.zeros(20)),
        },
        source=SourceInfo(path="mem", format="test"),
    )
    profile = parse_profile(BASE.split("[loops.left_motor]")[0])
    at_end = align(log, profile).u[:, 0]
    assert profile.inputs.stamp == "end" and at_end[5] == 5.0
    started = parse_profile(BASE.split("[loops.left_motor]")[0].replace('u0 = "/u"', 'u0 = "/u"\nstamp = "start"'))
    assert started.inputs.stamp == "start" and parse_profile(started.to_toml()) == started
    at_start = align(log, started).u[:, 0]
    np.testing.assert_array_equal(at_start[1:], at_end[:-1])  # one step later, exactly
    with pytest.raises(ProfileError, match="stamp"):
        parse_profile(BASE.replace('u0 = "/u"', 'u0 = "/u"\nstamp = "middle"'))
