"""Interval matrices of the `linear` model from its profile (`radius`, logscan/models/linear_intervals.py):
checked shapes and signs with one-line errors, the discrete model's intervals as given, a continuous
model's derived at the vertices and enclosing random draws, and the UBIKF running on them."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from logscan.errors import ModelError
from logscan.models import get_model

DT = 0.01
CONTINUOUS = {
    "A": [[0.0, 1.0], [-2.0, -0.5]],
    "B": [[0.0], [1.0]],
    "C": {"pos": [[1.0, 0.0]]},
    "R": {"pos": [0.05]},
}


def test_a_discrete_models_intervals_are_the_matrices_plus_minus_the_radius():
    params = {
        "A": [[0.99, 0.01], [-0.02, 0.995]], "B": [[0.0], [0.01]], "C": {"pos": [[1.0, 0.0]]},
        "continuous": False, "dt": DT,
        "radius": {"A": [[0.0, 0.001], [0.002, 0.0]], "C": {"pos": [[0.05, 0.0]]}, "R": {"pos": [[1e-4]]}},
    }  # fmt: skip
    im = get_model("linear", params).interval_model(DT)
    np.testing.assert_array_equal(im.A_m, params["A"])
    np.testing.assert_array_equal(im.A_r, params["radius"]["A"])
    np.testing.assert_array_equal(im.C_r, [[0.05, 0.0]])
    assert im.R_r[0, 0] == 1e-4 and im.B_r.max() == 0.0 and im.Q_r.max() == 0.0


def test_a_continuous_models_intervals_enclose_every_draw_of_its_uncertain_entries():
    params = {**CONTINUOUS, "radius": {"A": [[0.0, 0.0], [0.2, 0.05]], "B": [[0.0], [0.1]]}}
    model = get_model("linear", params)
    im = model.interval_model(DT)
    assert im.A_r.max() > 0 and im.B_r.max() > 0
    rng = np.random.default_rng(0)
    A0, B0 = np.array(params["A"]), np.array(params["B"])
    for _ in range(200):
        A = A0 + rng.uniform(-1, 1, A0.shape) * np.array(params["radius"]["A"])
        B = B0 + rng.uniform(-1, 1, B0.shape) * np.array(params["radius"]["B"])
        E = scipy.linalg.expm(np.block([[A, B], [np.zeros((1, 3))]]) * DT)
        tol = 1e-12
        assert np.all(np.abs(E[:2, :2] - im.A_m) <= im.A_r + tol) and np.all(np.abs(E[:2, 2:] - im.B_m) <= im.B_r + tol)


@pytest.mark.parametrize(
    ("radius", "message"),
    [
        ({"A": [[0.0, -0.1], [0.0, 0.0]]}, "radius A[0][1] = -0.1 is negative"),
        ({"A": [[0.1, 0.1]]}, "radius A has shape 1 x 2, expected 2 x 2"),
        ({"C": {"vel": [[0.1, 0.0]]}}, "radius C given for group 'vel' but C has no such group"),
        ({"Q": [[0.0, 0.1], [0.0, 0.0]]}, "radius Q must be symmetric"),
        ({"X": 1}, "radius has unknown key(s) X"),
        ({"A": [[0.1] * 2] * 2, "B": [[0.1], [0.1]], "R": {"pos": [[float("nan")]]}}, "radius R[pos] has non-finite"),
    ],
)
def test_a_bad_radius_is_one_clear_model_error(radius, message):
    with pytest.raises(ModelError) as info:
        get_model("linear", {**CONTINUOUS, "radius": radius})
    assert message in str(info.value) and "\n" not in info.value.message


def test_too_many_uncertain_entries_of_a_continuous_model_are_refused():
    params = {"A": np.eye(4).tolist(), "B": np.ones((4, 3)).tolist(), "C": {"y": np.eye(4).tolist()}}
    with pytest.raises(ModelError, match="vertex evaluation takes at most 10"):
        get_model("linear", {**params, "radius": {"A": np.full((4, 4), 0.01).tolist()}})


def test_the_ubikf_runs_on_a_profiles_intervals_and_its_bound_is_above_the_point_filter():
    from logscan.align import AlignedGroup, AlignedRun
    from logscan.filters.ubikf import run_ubikf

    params = {**CONTINUOUS, "radius": {"A": [[0.0, 0.0], [0.2, 0.05]], "C": {"pos": [[0.02, 0.0]]}}}
    im = get_model("linear", params).interval_model(DT)
    point = get_model("linear", CONTINUOUS).interval_model(DT)
    N = 500
    rng = np.random.default_rng(1)
    z = np.sin(np.arange(N) * DT)[:, None] + 0.05 * rng.normal(size=(N, 1))
    group = AlignedGroup("pos", ["pos0"], z, np.ones(N, bool))
    run = AlignedRun(t=np.arange(N) * DT, dt=DT, start_ns=0, u=np.zeros((N, 1)), u_fresh=np.ones(N, bool),
                     input_channels=[], groups={"pos": group})  # fmt: skip
    bound, exact = run_ubikf(im, run), run_ubikf(point, run)
    assert np.all(bound.P_trace[100:] > exact.P_trace[100:])
    assert np.all(bound.x_hi - bound.x_lo >= 0) and (bound.x_hi - bound.x_lo)[100:].min() > 0
