"""The recovery's error bounds: the k-sigma bound against a Monte Carlo of the roll-forward error,
and the paper's Proposition 5.1 worst case (above the actual error, and as its formula says)."""

from __future__ import annotations

import numpy as np
from recovery_linear import make_loop

from logscan.models.dispatch import call_literal
from logscan.models.linear import discretise
from logscan.recovery import Anomaly, RecoverySettings, recover
from logscan.recovery.bounds import proposition_51
from logscan.recovery.kernels import jacobian_bound

RUNS = 500


def _monte_carlo():
    """Per run: (roll-forward error, k-sigma bound, worst case) over the recovered span."""
    settings = RecoverySettings(method="rollforward", detection_time_s=0.1, hold_s=0.0)
    errors, bounds, worst = [], [], []
    for seed in range(RUNS):
        loop, truth = make_loop(N=100, seed=1000 + seed)
        lr = recover([loop], [Anomaly(6.0, 9.0, None)], settings).loops["outer"]
        m = lr.recovered
        errors.append(lr.x_recovered[m] - truth[m])
        bounds.append(lr.bound[m])
        worst.append(lr.worst_case[m])
    return np.concatenate(errors), np.concatenate(bounds), np.concatenate(worst)


def test_the_k_sigma_bound_covers_the_rollforward_error_and_is_not_loose():
    err, bound, worst = _monte_carlo()
    assert err.shape[0] == RUNS * 34  # k1 = 5.7 .. 9.0
    inside = np.mean(np.abs(err) <= bound, axis=0)
    assert np.all(inside >= 0.99), inside  # 3 sigma: 0.9973 for a consistent filter
    one_sigma = np.mean(np.abs(err) <= bound / 3.0, axis=0)
    assert np.all((one_sigma > 0.6) & (one_sigma < 0.76)), one_sigma  # 0.683: neither loose nor tight
    # the paper's worst case holds everywhere, and is far looser
    assert np.all(np.abs(err) <= worst)
    assert np.median(worst / bound) > 1.5


def test_proposition_51_follows_its_formula():
    Abar = np.array([[1.0, 0.1], [0.05, 0.9]])
    eps_d, eps_w = np.array([0.2, 0.1]), np.array([0.01, 0.03])
    B = proposition_51(Abar, eps_d, eps_w, 6)
    np.testing.assert_array_equal(B[0], eps_d)
    for j in range(1, 6):
        powers = [np.linalg.matrix_power(Abar, i) for i in range(j + 1)]
        expected = powers[j] @ eps_d + sum(P @ eps_w for P in powers)
        np.testing.assert_allclose(B[j], expected, rtol=1e-12)
    # an overflowing power is an unbounded (inf) bound, never NaN
    huge = proposition_51(np.array([[1e200, 0.0], [0.0, 0.0]]), eps_d, eps_w, 4)
    assert np.isinf(huge[3, 0]) and not np.isnan(huge).any()


def test_the_jacobian_bound_of_a_linear_model_is_abs_ad():
    loop, _ = make_loop(N=20)
    m = loop.model
    p = m.param_vector(0.1)
    Abar = call_literal(jacobian_bound, m.model_id, p, loop.trace.x_post, loop.run.u, 0.1)
    Ad = discretise(np.array(m._A), np.array(m._B), np.array(m._Q), 0.1)[0]
    np.testing.assert_allclose(Abar, np.abs(Ad), rtol=1e-12)
