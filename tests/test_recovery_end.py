"""The end of a recovery: after the alarms last showed the anomaly, the first flagged sample that no
longer shows it ends the recovery (re-agreed, or the recovered estimate did not re-agree), with the
reason (docs/algorithms.md 5.4)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from recovery_linear import make_loop
from scipy.stats import chi2

from logscan.detectors.budget import design_rate
from logscan.errors import ProfileError
from logscan.recovery import Anomaly, RecoverySettings, recover
from logscan.recovery.agreement import (
    AGREE,
    DISAGREE,
    NO_SAMPLE,
    SHOWN,
    agreed_at,
    agreement_status,
    keep_bound,
    released_at,
)
from logscan.recovery.rerun import rerun

GPS = {"outer": ("gps",)}
BUDGET = (0.1, 100.0)


def _astray(seed: int = 0):
    """gps attacked (+3 = 10 sigma) over [10, 15) and flagged; odo off by 0.1 over the same window
    and not flagged, so the re-filter that keeps odo drifts: after the attack its estimate does
    not agree with the honest gps, nor does gps show an anomaly against it."""
    return make_loop(N=400, seed=seed, attacks=[("gps", 10.0, 15.0, 3.0), ("odo", 10.0, 15.0, 0.1)])


def test_a_recovery_that_does_not_re_agree_after_the_attack_ends_there_and_says_why():
    loop, truth = _astray()
    rec = recover([loop], [Anomaly(10.3, 15.0, GPS)], RecoverySettings(hold_s=1.0))
    r = rec.anomalies[0]
    # what agreement alone would have done: dead-reckon on for more than 5 s past the attack, or to the cap
    k1 = r.checkpoint_steps["outer"]
    part = rerun(loop, k1, loop.run.n_steps - 1, ("gps",))
    t = loop.run.t[k1:]
    old = agreed_at(t, agreement_status(loop, k1, part, ("gps",), 0.99), 10.3, 1.0)
    assert old is None or old > 20.0, old
    # the attack's samples show the anomaly (the alarm is kept through it); the first sample after
    # the detector's alarm that does not show it, and disagrees within hold_s, ends the recovery
    status = agreement_status(loop, k1, part, ("gps",), 0.99, BUDGET)
    assert np.mean(status[(t > 11.0) & (t < 15.0)] == SHOWN) > 0.9
    first, agreed = released_at(t, status, 15.0, 1.0)
    assert not agreed
    assert r.t_recovered_end == pytest.approx(first) and 15.0 <= first <= 15.5
    assert r.t_agreed is None and not r.capped and r.end_reason.startswith("did not re-agree")
    assert "gps" in r.end_reason and f"{keep_bound(loop, 'gps', BUDGET):.1f}" in r.end_reason
    assert r.to_dict()["end_reason"] == r.end_reason
    # nothing recovered after the end: the shared filter's estimate stands there
    outer = rec.loops["outer"]
    assert outer.recovered[int(round(14.9 / 0.1))] and not outer.recovered[int(round(15.6 / 0.1))]


def test_the_kept_alarms_bound_is_the_false_alarm_budgets_chi_square_quantile():
    loop, _ = make_loop(N=400, seed=0, rates={"gps": 2, "odo": 1})  # gps at 5 Hz
    per_sample = design_rate(*BUDGET) / (3600.0 * 5.0)
    rate = np.count_nonzero(loop.run.groups["gps"].fresh) / (loop.run.t[-1] - loop.run.t[0])
    assert rate == pytest.approx(5.0, rel=0.01)
    expected = chi2.ppf(1.0 - design_rate(*BUDGET) / (3600.0 * rate), 1)
    assert keep_bound(loop, "gps", BUDGET) == pytest.approx(expected, rel=1e-9)
    assert chi2.sf(keep_bound(loop, "gps", BUDGET), 1) == pytest.approx(per_sample, rel=0.02)
    # a stricter budget asks for more evidence
    assert keep_bound(loop, "gps", (0.01, 1000.0)) > keep_bound(loop, "gps", BUDGET) > chi2.ppf(0.99, 1)


def test_a_budget_too_short_to_show_is_refused():
    with pytest.raises(ProfileError, match="proof_hours"):
        RecoverySettings(budget_per_hour=0.1, proof_hours=10.0)
    with pytest.raises(ProfileError, match="budget_per_hour"):
        RecoverySettings(budget_per_hour=0.0)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(st.sampled_from([AGREE, DISAGREE, NO_SAMPLE, SHOWN]), min_size=1, max_size=60),
    st.floats(0.0, 6.0),
    st.floats(0.0, 2.0),
)
def test_released_at_is_the_first_disagreement_or_held_agreement_after_the_alarm(status, t_from, hold):
    status = np.array(status, dtype=np.int8)
    t = np.arange(status.size) * 0.1
    found = released_at(t, status, t_from, hold)
    later = t >= t_from

    def shown_within(k: int) -> bool:
        return bool(np.any((status == SHOWN) & (t > t[k]) & (t <= t[k] + hold)))

    held = [int(k) for k in np.flatnonzero((status == AGREE) & later) if not shown_within(int(k))]
    if found is None:
        assert not np.any((status == DISAGREE) & later) and not held
        return
    t_end, agreed = found
    k = int(np.argmin(np.abs(t - t_end)))
    assert later[k] and not np.any((status == DISAGREE) & later & (t < t[k]))
    assert not any(j < k for j in held)
    if status[k] == DISAGREE:
        assert not agreed
    else:
        assert status[k] == AGREE and k in held
        assert agreed == (not np.any((status == DISAGREE) & (t > t[k]) & (t <= t[k] + hold)))
