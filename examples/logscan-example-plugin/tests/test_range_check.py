"""The example plugin's own tests: the range_check detector on small hand-made runs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from logscan.align import AlignedGroup, AlignedRun
from logscan.errors import NotTrainedError, ProfileError
from logscan_example_plugin import RangeCheckDetector


def speed_run(values, rate_hz=10.0):
    """A run with one measurement group "speed" of one channel, fresh at every step."""
    values = np.asarray(values, dtype=float)
    n = values.size
    group = AlignedGroup("speed", ["/odom/speed"], values.reshape(n, 1), np.ones(n, bool))
    return AlignedRun(
        t=np.arange(n) / rate_hz,
        dt=1 / rate_hz,
        start_ns=0,
        u=np.zeros((n, 0)),
        u_fresh=np.ones(n, bool),
        input_channels=[],
        groups={"speed": group},
    )


def test_configured_limits_raise_an_alarm_on_the_out_of_range_samples():
    run = speed_run([1, 2, 3, 50, 51, 2, 1, -9, 1, 1])
    result = RangeCheckDetector(limits={"/odom/speed": [-5, 20]}).run(run)
    assert [(a.start, a.end, a.bound) for a in result.alarms] == [(0.3, 0.4, "upper"), (0.7, 0.7, "lower")]
    assert result.series["/odom/speed"].shape == (10,)


def test_training_learns_healthy_range_with_margin_and_round_trips_as_json():
    detector = RangeCheckDetector(margin=0.5).fit([speed_run([0, 1, 2]), speed_run([4, 3])])
    assert detector.limits_ == {"/odom/speed": [-2.0, 6.0]}
    state = json.loads(json.dumps(detector.to_state()))
    again = RangeCheckDetector.from_state(state)
    assert again.limits_ == detector.limits_
    assert [a.start for a in again.run(speed_run([1, 7, 1])).alarms] == [0.1]


def test_without_any_range_it_asks_for_training():
    with pytest.raises(NotTrainedError, match="no range"):
        RangeCheckDetector().run(speed_run([1, 2]))


def test_bad_limits_are_reported_at_run_time():
    detector = RangeCheckDetector(limits={"/odom/speed": [5, 1]})  # __init__ never validates
    with pytest.raises(ProfileError, match="low <= high"):
        detector.run(speed_run([1, 2]))
