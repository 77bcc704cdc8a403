"""A `linear` profile's prior (`params.x0`, `params.P0`): where the system may be when the log begins.
The ground robot's motors start turning (35 and 45 rad/s) while the default prior (x0 = 0, P0 = I)
put their unmeasured current 35-45 standard deviations off: the motor loops' checks read the first
second as a fault (cusum and e_x alarms at 0.5-1.5 s on 5 of 19 healthy 30-min drives)."""

from __future__ import annotations

import numpy as np
import pytest

from logscan.errors import ModelError
from logscan.models import get_model
from logscan.simulate.ground_robot_sim import initial_state, motor_params

BASE = {"A": [[0.9, 0.0], [0.1, 0.8]], "B": [[1.0], [0.0]], "C": {"y": [[0.0, 1.0]]}, "continuous": False, "dt": 0.1}


def test_the_profiles_prior_is_the_filters_and_the_default_stays():
    model = get_model("linear", {**BASE, "x0": [1.0, -2.0], "P0": [[4.0, 0.5], [0.5, 9.0]]})
    np.testing.assert_array_equal(model.default_x0(), [1.0, -2.0])
    np.testing.assert_array_equal(model.default_P0(), [[4.0, 0.5], [0.5, 9.0]])
    plain = get_model("linear", BASE)
    np.testing.assert_array_equal(plain.default_x0(), [0.0, 0.0])
    np.testing.assert_array_equal(plain.default_P0(), np.eye(2))


@pytest.mark.parametrize(
    ("prior", "message"),
    [
        ({"x0": [1.0]}, "x0 has 1 columns, expected 2"),
        ({"x0": [1.0, float("nan")]}, "x0 has non-finite entries"),
        ({"P0": [[1.0, 0.0]]}, "P0 has 1 rows, expected 2"),
        ({"P0": [[1.0, 2.0], [0.0, 1.0]]}, "P0 is not symmetric"),
        ({"P0": [[1.0, 0.0], [0.0, -1.0]]}, "P0"),
    ],
)
def test_a_bad_prior_is_one_clear_model_error(prior, message):
    with pytest.raises(ModelError, match=message):
        get_model("linear", {**BASE, **prior})


def test_the_ground_robots_motor_prior_covers_where_its_motors_start():
    params = motor_params()
    model = get_model("linear", params)
    x0, P0 = model.default_x0(), model.default_P0()
    _, motors, _ = initial_state()
    for start in motors:  # each motor's true [i, w] at the log's first step
        error = start - x0
        mahalanobis2 = float(error @ np.linalg.solve(P0, error))
        assert mahalanobis2 <= 2.0, (start, mahalanobis2)  # within the prior: each state at most 1 sigma
    # the default prior it replaced did not: the current alone 35-45 standard deviations off
    assert all(abs(i) > 30.0 for i, _ in motors)
