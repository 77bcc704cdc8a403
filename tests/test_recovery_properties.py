"""Properties of recovery's building blocks (hypothesis): a re-run from any checkpoint with nothing
excluded is the shared EKF; an agreement end never has a disagreeing sample within its hold."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from recovery_linear import make_loop

from logscan.recovery.agreement import AGREE, DISAGREE, NO_SAMPLE, agreed_at
from logscan.recovery.rerun import rerun

LOOPS = {period: make_loop(N=200, seed=period, rates={"gps": period, "odo": 1})[0] for period in (1, 3, 7)}


@settings(max_examples=25, deadline=None)
@given(st.sampled_from(sorted(LOOPS)), st.integers(0, 190), st.integers(1, 120))
def test_a_rerun_with_nothing_excluded_is_the_shared_ekf(period, k1, length):
    loop = LOOPS[period]
    k_stop = min(k1 + length, 199)
    part = rerun(loop, k1, k_stop, ())
    np.testing.assert_allclose(part.x_post, loop.trace.x_post[k1 : k_stop + 1], rtol=0, atol=1e-12)
    # with every group excluded the covariance only grows between steps (F P F^T + Q, Q > 0)
    rf = rerun(loop, k1, k_stop, ("gps", "odo"))
    assert np.all(np.diff(np.einsum("kii->ki", rf.P_post)[:, 0]) > 0)


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.sampled_from([AGREE, DISAGREE, NO_SAMPLE]), min_size=1, max_size=60),
    st.floats(0.0, 3.0),
    st.floats(0.0, 2.0),
)
def test_an_agreement_end_holds_without_a_disagreement(status, t_from, hold):
    status = np.array(status, dtype=np.int8)
    t = np.arange(status.size) * 0.1
    found = agreed_at(t, status, t_from, hold)
    if found is None:
        # no agreeing sample >= t_from is followed by hold_s free of disagreement (within t)
        for i in np.flatnonzero((status == AGREE) & (t >= t_from)):
            window = (t > t[i]) & (t <= t[i] + hold)
            assert np.any(status[window] == DISAGREE) or t[i] + hold > t[-1] + 1e-9
        return
    i = int(np.argmin(np.abs(t - found)))
    assert status[i] == AGREE and found >= t_from
    assert not np.any(status[(t > found) & (t <= found + hold)] == DISAGREE)
    assert found + hold <= t[-1] + 1e-9
