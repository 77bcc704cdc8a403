"""Interval matrices of the `linear` model from its profile (`radius` and `interval`,
logscan/models/linear_intervals.py): checked shapes, signs, ends and the point model inside, with
one-line errors naming the entry; the discrete model's intervals as given (an `interval` as its exact
box, equal to the `radius` form when symmetric), a continuous model's derived at the vertices and
enclosing random draws, and the UBIKF and `logscan analyze` running on them."""

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


# ------------------------------------------------------------------------------------------------
# `interval`: [lo, hi] per entry
# ------------------------------------------------------------------------------------------------
# dyadic numbers throughout, so that M +- r and (lo + hi) / 2 are exact and the two forms of one
# interval give equal arrays, not merely close ones
DISCRETE = {
    "A": [[0.75, 0.125], [-0.25, 0.5]], "B": [[0.0], [0.125]], "C": {"pos": [[1.0, 0.0]]},
    "R": {"pos": [0.5]}, "Q": [[0.25, 0.0], [0.0, 0.25]], "continuous": False, "dt": DT,
}  # fmt: skip
FIELDS = ("A_m", "A_r", "B_m", "B_r", "C_m", "C_r", "Q_m", "Q_r", "R_m", "R_r")


def as_interval(point, radius) -> list:
    """The [lo, hi] per entry of point +- radius."""
    M, r = np.asarray(point, dtype=float), np.asarray(radius, dtype=float)
    return np.stack([M - r, M + r], axis=-1).tolist()


def assert_same_model(a, b):
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_a_symmetric_interval_is_the_same_model_as_its_radius_discrete():
    radius = {
        "A": [[0.0, 0.0625], [0.125, 0.0]], "B": [[0.0], [0.03125]], "C": {"pos": [[0.0625, 0.0]]},
        "Q": [[0.0, 0.0625], [0.0625, 0.125]], "R": {"pos": [[0.0625]]},
    }  # fmt: skip
    interval = {
        "A": as_interval(DISCRETE["A"], radius["A"]), "B": as_interval(DISCRETE["B"], radius["B"]),
        "C": {"pos": as_interval(DISCRETE["C"]["pos"], radius["C"]["pos"])},
        "Q": as_interval(DISCRETE["Q"], radius["Q"]), "R": {"pos": as_interval([[0.25]], radius["R"]["pos"])},
    }  # fmt: skip
    by_radius = get_model("linear", {**DISCRETE, "radius": radius}).interval_model(DT)
    by_interval = get_model("linear", {**DISCRETE, "interval": interval}).interval_model(DT)
    assert_same_model(by_radius, by_interval)
    assert by_interval.A_r[1, 0] == 0.125 and by_interval.R_r[0, 0] == 0.0625


def test_a_symmetric_interval_is_the_same_model_as_its_radius_continuous():
    radius = {"A": [[0.0, 0.0], [0.25, 0.0625]], "B": [[0.0], [0.125]]}
    interval = {"A": as_interval(CONTINUOUS["A"], radius["A"]), "B": as_interval(CONTINUOUS["B"], radius["B"])}
    by_radius = get_model("linear", {**CONTINUOUS, "radius": radius}).interval_model(DT)
    by_interval = get_model("linear", {**CONTINUOUS, "interval": interval}).interval_model(DT)
    assert_same_model(by_radius, by_interval)
    assert by_interval.A_r.max() > 0


def test_an_asymmetric_interval_is_its_exact_box():
    # A[0][0] = 0.75 in [0.5, 0.875]: midpoint 0.6875, radius 0.1875 (not the point +- anything)
    A_box = [[[0.5, 0.875], [0.125, 0.125]], [[-0.25, -0.25], [0.5, 0.5]]]
    R_box = {"pos": [[[0.125, 0.5]]]}  # the point covariance 0.5^2 = 0.25: midpoint 0.3125
    im = get_model("linear", {**DISCRETE, "interval": {"A": A_box, "R": R_box}}).interval_model(DT)
    np.testing.assert_array_equal(im.A_m, [[0.6875, 0.125], [-0.25, 0.5]])
    np.testing.assert_array_equal(im.A_r, [[0.1875, 0.0], [0.0, 0.0]])
    assert im.R_m[0, 0] == 0.3125 and im.R_r[0, 0] == 0.1875
    np.testing.assert_array_equal(im.B_m, DISCRETE["B"])
    assert im.B_r.max() == 0.0 and im.C_r.max() == 0.0 and im.Q_r.max() == 0.0


def test_a_continuous_models_asymmetric_interval_is_the_hull_of_its_ends_discretised():
    # A[1][0] = -2 in [-2.5, -1.875]: one uncertain entry, two vertices
    A_box = [[[0.0, 0.0], [1.0, 1.0]], [[-2.5, -1.875], [-0.5, -0.5]]]
    model = get_model("linear", {**CONTINUOUS, "interval": {"A": A_box}})
    im = model.interval_model(DT)
    ends = []
    for a10 in (-2.5, -1.875):
        A = np.array([[0.0, 1.0], [a10, -0.5]])
        ends.append(scipy.linalg.expm(np.block([[A, np.array(CONTINUOUS["B"])], [np.zeros((1, 3))]]) * DT))
    lo, hi = np.minimum(*ends), np.maximum(*ends)
    assert not model.interval_widened
    np.testing.assert_allclose(im.A_m - im.A_r, lo[:2, :2], rtol=0, atol=1e-15)
    np.testing.assert_allclose(im.A_m + im.A_r, hi[:2, :2], rtol=0, atol=1e-15)
    point = get_model("linear", CONTINUOUS).interval_model(DT)
    assert not np.array_equal(im.A_m, point.A_m)  # the box's midpoint, not the point model's


PAIRS_2x2 = [[[0.0, 0.0], [1.0, 1.0]], [[-2.0, -2.0], [-0.5, -0.5]]]


@pytest.mark.parametrize(
    ("params", "message"),
    [
        (
            {"interval": {"A": [[[0.0, 0.0], [1.0, 1.0]], [[-1.8, -2.2], [-0.5, -0.5]]]}},
            "interval A[1][0] = [-1.8, -2.2]: lower end above the upper",
        ),
        (
            {"interval": {"A": [[[0.0, 0.0], [1.1, 1.2]], [[-2.0, -2.0], [-0.5, -0.5]]]}},
            "interval A[0][1] = [1.1, 1.2] does not hold the point matrix's entry 1",
        ),
        ({"interval": {"A": CONTINUOUS["A"]}}, "interval A has shape 2 x 2, expected 2 x 2 x 2"),
        ({"interval": {"B": [[[0.0, 0.0]]]}}, "interval B has shape 1 x 1 x 2, expected 2 x 1 x 2"),
        ({"interval": {"A": PAIRS_2x2}, "radius": {"A": [[0.0] * 2] * 2}}, "A is given both as radius and as interval"),
        (
            {"interval": {"C": {"pos": [[[0.9, 1.1], [0.0, 0.0]]]}}, "radius": {"C": {"pos": [[0.1, 0.0]]}}},
            "C[pos] is given both as radius and as interval",
        ),
        (
            {"interval": {"R": {"pos": [[[float("nan"), 1.0]]]}}},
            "interval R[pos][0][0] = [nan, 1] is not finite",
        ),
        (
            {"interval": {"R": {"pos": [[[0.0, 0.001]]]}}},
            "interval R[pos][0][0] = [0, 0.001] does not hold the point matrix's entry 0.0025",
        ),
        (
            {"interval": {"Q": [[[0.0, 1.0], [0.0, 0.0]], [[0.0, 1.0], [0.0, 1.0]]]}},
            "interval Q must be symmetric (lo and hi both): Q[0][1] = [0, 0] but Q[1][0] = [0, 1]",
        ),
        ({"interval": {"C": {"vel": [[[0.0, 1.0], [0.0, 0.0]]]}}}, "interval C given for group 'vel'"),
        ({"interval": {"X": 1}}, "interval has unknown key(s) X"),
    ],
)
def test_a_bad_interval_is_one_clear_model_error(params, message):
    with pytest.raises(ModelError) as info:
        get_model("linear", {**CONTINUOUS, **params})
    assert message in str(info.value) and "\n" not in info.value.message


def test_every_interval_problem_is_listed_at_once():
    interval = {
        "A": [[[0.0, 0.0], [1.0, 1.0]], [[-1.8, -2.2], [-0.5, -0.5]]],
        "B": [[[0.0, 0.0]], [[2.0, 3.0]]],
        "R": {"pos": [[[float("inf"), 1.0]]]},
    }
    with pytest.raises(ModelError) as info:
        get_model("linear", {**CONTINUOUS, "interval": interval})
    found = " | ".join(info.value.problems)
    assert len(info.value.problems) == 3, found
    for entry in ("A[1][0] = [-1.8, -2.2]", "B[1][0] = [2, 3]", "R[pos][0][0] = [inf, 1]"):
        assert entry in found


def test_qs_interval_must_hold_the_discrete_covariance_on_the_grid():
    # a continuous model's discrete Q is known with the grid period: the profile check names it
    Qd = get_model("linear", CONTINUOUS).default_Q(DT)
    below = {"Q": as_interval(0.5 * Qd, 0.25 * np.abs(Qd))}  # |Qd| beyond 0.75 |Qd|: every entry outside
    model = get_model("linear", {**CONTINUOUS, "interval": below})
    (problem,) = model.covariance_problems(DT)
    assert "interval Q[" in problem and "does not hold the point matrix's entry" in problem and "dt = 0.01 s" in problem
    with pytest.raises(ModelError, match="does not hold the point matrix's entry"):
        model.interval_model(DT)
    holding = get_model("linear", {**CONTINUOUS, "interval": {"Q": as_interval(Qd, 0.5 * np.abs(Qd))}})
    assert holding.covariance_problems(DT) == []
    np.testing.assert_allclose(holding.interval_model(DT).Q_r, 0.5 * np.abs(Qd), rtol=1e-15)


def test_a_discrete_models_q_interval_is_checked_when_built():
    with pytest.raises(
        ModelError, match=r"interval Q\[0\]\[0\] = \[0.5, 1\] does not hold the point matrix's entry 0.25"
    ):
        get_model("linear", {**DISCRETE, "interval": {"Q": [[[0.5, 1.0], [0.0, 0.0]], [[0.0, 0.0], [0.25, 0.25]]]}})


def test_a_profile_with_intervals_runs_the_chi2_detector(tmp_path, cli, sample):
    log = sample("jackal_healthy.mcap")
    profile = tmp_path / "jackal-interval.toml"
    profile.write_text(JACKAL_INTERVAL, encoding="utf-8")
    done = cli("analyze", "--profile", profile, "--detector", "chi2", "--output", tmp_path / "report.html", log)
    assert done.exit_code in (0, 1), done.stderr
    assert "Traceback" not in done.stdout + done.stderr and "detectors chi2" in done.stdout


JACKAL_INTERVAL = """
[vehicle]
model = "linear"
rate_hz = 20

[vehicle.params]
A = [[-5.07]]
B = [[0.435]]
C = { encoder = [[1.0], [1.0]], gps_speed = [[1.0]] }
Q = [[0.0095]]
R = { encoder = [0.02, 0.02], gps_speed = [0.05] }
states = ["v"]
inputs = ["Va"]
interval = { A = [[[-5.5, -4.9]]], B = [[[0.42, 0.45]]], C = { gps_speed = [[[0.98, 1.03]]] } }

[inputs]
Va = "/cmd/Va"

[measurements.encoder]
channels = ["/enc/left.v", "/enc/right.v"]
rate_hz = 20

[measurements.gps_speed]
channels = ["/gps/speed"]
rate_hz = 10
"""
