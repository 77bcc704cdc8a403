"""Roll-forward recovery on linear loops: input timing, agreement with the shared EKF, specific
re-filtering vs generic roll-forward, the paper's element replacement, keeping the alarm, T_max."""

from __future__ import annotations

import numpy as np
import pytest
from recovery_linear import PARAMS, make_loop

from logscan.errors import ProfileError
from logscan.filters import run_ekf
from logscan.recovery import UNTRUSTWORTHY, Anomaly, RecoverySettings, recover
from logscan.recovery.rerun import rerun

GPS = {"outer": ("gps",)}


def _rms(a):
    return float(np.sqrt(np.mean(np.square(a))))


# ---- input timing ----------------------------------------------------------------------------
def test_noise_free_rollforward_reproduces_the_true_states_exactly():
    """x_k = f(x_{k-1}, u[k]) as the kernel predicts: a noise-free loop's roll-forward from the true
    checkpoint is the truth to rounding; the same roll-forward with the input one step late is not."""
    loop, truth = make_loop(N=200, noise=0.0, x0=None)
    assert np.max(np.abs(loop.trace.x_post - truth)) < 1e-9  # noise-free: the filter sits on the truth
    rec = recover([loop], [Anomaly(8.0, 15.0, None)], RecoverySettings(method="rollforward", hold_s=0.0))
    lr = rec.loops["outer"]
    span = lr.recovered
    k1 = rec.anomalies[0].checkpoint_steps["outer"]
    assert span.sum() > 60 and np.flatnonzero(span)[0] == k1
    assert np.max(np.abs(lr.x_recovered[span] - truth[span])) < 1e-9
    # an off-by-one input (u[k-1] over the step to k) drifts away from the truth
    u = loop.run.u
    x = truth[k1].copy()
    late = [x]
    for k in range(k1 + 1, k1 + span.sum()):
        x = loop.model.f(x, u[k - 1], loop.run.dt)
        late.append(x)
    assert np.max(np.abs(np.array(late) - truth[span])) > 1e-3


def test_refiltering_with_nothing_excluded_reproduces_the_shared_ekf():
    loop, _ = make_loop(N=300, rates={"gps": 3, "odo": 1}, seed=4)
    part = rerun(loop, 57, 250, ())
    assert np.max(np.abs(part.x_post - loop.trace.x_post[57:251])) < 1e-12
    assert np.max(np.abs(part.P_post - loop.trace.P_post[57:251])) < 1e-12


def test_shared_run_noise_overrides_are_kept_by_the_rerun():
    loop, _ = make_loop(N=200, seed=2)
    loop.trace = run_ekf(
        loop.model, loop.run, x0=[0.0, 0.0], P0=np.eye(2), Q=np.eye(2) * 1e-2, R={"gps": [1.5]}, full_P=True
    )
    part = rerun(loop, 40, 199, ())
    assert np.max(np.abs(part.x_post - loop.trace.x_post[40:])) < 1e-12


# ---- specific vs generic, methods ---------------------------------------------------------------
def _before_last(recovered: np.ndarray) -> np.ndarray:
    """The recovered steps but the last of each span."""
    return recovered & np.append(recovered[1:], False)


def test_specific_refilter_beats_pure_rollforward_when_one_group_is_attacked():
    errors = {"refilter": [], "rollforward": [], "ekf": []}
    for seed in range(4):
        loop, truth = make_loop(N=300, seed=seed, attacks=[("gps", 10.0, 20.0, 3.0)])
        spans = {}
        for name, targets, method in (
            ("refilter", GPS, "refilter"),
            ("rollforward", GPS, "rollforward"),
            ("generic", None, "refilter"),
        ):
            settings = RecoverySettings(method=method, detection_time_s=0.3)
            spans[name] = recover([loop], [Anomaly(10.4, 20.0, targets)], settings).loops["outer"]
        # (the roll-forward's growing P_R weakens the agreement test: it may end before the attack)
        m = spans["refilter"].recovered & spans["rollforward"].recovered
        assert m.sum() > 60
        for name in ("refilter", "rollforward"):
            errors[name].append(spans[name].x_recovered[m, 0] - truth[m, 0])
        errors["ekf"].append(loop.trace.x_post[m, 0] - truth[m, 0])
        # a generic detector knows no sensor: re-filtering is the pure roll-forward (but at each span's
        # last step, which takes in the sample that ended it)
        both = _before_last(spans["generic"].recovered) & _before_last(spans["rollforward"].recovered)
        assert both.sum() > 60
        np.testing.assert_array_equal(spans["generic"].x_recovered[both], spans["rollforward"].x_recovered[both])
    rms = {k: _rms(np.concatenate(v)) for k, v in errors.items()}
    assert rms["refilter"] < 0.6 * rms["rollforward"], rms
    assert rms["rollforward"] < 0.5 * rms["ekf"], rms


PARAMS3 = {
    "A": [[0.0, 1.0, 0.0], [0.0, -0.2, 0.0], [0.0, 0.0, -0.5]],
    "B": [[0.0], [1.0], [1.0]],
    "C": {"gps": [[1.0, 0.0, 0.0]], "odo": [[0.0, 1.0, 0.0]], "wheel": [[0.0, 0.0, 1.0]]},
    "Q": [[1e-3, 0.0, 0.0], [0.0, 2e-2, 0.0], [0.0, 0.0, 1e-2]],
    "R": {"gps": [0.3], "odo": [0.05], "wheel": [0.1]},
}


def test_replace_swaps_only_the_states_a_flagged_group_has_gain_on():
    """The paper's element replacement: roll-forward values where K g != 0 (p, v for gps), the
    shared EKF's for a state the gps gain never reaches (w, decoupled)."""
    rates = {"gps": 1, "odo": 1, "wheel": 1}
    loop, _ = make_loop(N=200, seed=1, params=PARAMS3, rates=rates, attacks=[("gps", 8.0, 12.0, 2.0)], x0=np.zeros(3))
    anomaly = [Anomaly(8.3, 12.0, GPS)]
    rep = recover([loop], anomaly, RecoverySettings(method="replace")).loops["outer"]
    rf = recover([loop], anomaly, RecoverySettings(method="rollforward")).loops["outer"]
    m = rep.recovered
    assert m.sum() > 30
    np.testing.assert_array_equal(rep.x_recovered[m, :2], rf.x_recovered[m, :2])
    np.testing.assert_array_equal(rep.x_recovered[m, 2], loop.trace.x_post[m, 2])
    assert np.max(np.abs(rf.x_recovered[m, 2] - loop.trace.x_post[m, 2])) > 1e-3  # it would differ
    # a generic anomaly replaces the whole state (the paper's line 14)
    gen = recover([loop], [Anomaly(8.3, 12.0, None)], RecoverySettings(method="replace")).loops["outer"]
    both = gen.recovered & rf.recovered  # the specific roll-forward ends when gps agrees again
    assert both.sum() > 30
    np.testing.assert_array_equal(gen.x_recovered[both], rf.x_recovered[both])


# ---- keeping the alarm, end of an anomaly -------------------------------------------------------
def test_the_kept_alarm_ends_after_the_attack_stops_not_while_it_lasts():
    loop, _ = make_loop(N=400, seed=3, attacks=[("gps", 10.0, 25.0, 3.0)])
    # the shared EKF's detector lost the anomaly after 1 s; the flagged sensor keeps it
    rec = recover([loop], [Anomaly(10.3, 11.3, GPS)], RecoverySettings(detection_time_s=0.3, hold_s=1.0))
    r = rec.anomalies[0]
    assert r.alarm_kept and not r.capped
    assert 25.0 - 1e-9 <= r.t_agreed <= 26.0, r.t_agreed
    # the span ends at the agreeing sample (the hold only confirms it), and says why
    assert r.t_recovered_end == pytest.approx(r.t_agreed) and "agreed" in r.end_reason
    assert rec.loops["outer"].recovered[int(round(24.9 / 0.1))]


def test_an_anomaly_that_never_agrees_is_cut_at_max_duration():
    loop, _ = make_loop(N=400, seed=3, attacks=[("gps", 10.0, 40.0, 3.0)])
    r = recover([loop], [Anomaly(10.3, 11.0, GPS)], RecoverySettings(max_duration_s=8.0)).anomalies[0]
    assert r.capped and r.t_agreed is None
    assert r.t_recovered_end == pytest.approx(18.3)


def test_an_anomaly_that_lasts_to_the_end_of_the_log_is_not_capped():
    loop, _ = make_loop(N=200, seed=3, attacks=[("gps", 10.0, 40.0, 3.0)])
    r = recover([loop], [Anomaly(10.3, 11.0, GPS)], RecoverySettings(max_duration_s=60.0)).anomalies[0]
    assert not r.capped and r.t_agreed is None and "end of the log" in r.note
    assert r.t_recovered_end == pytest.approx(19.9)


def test_a_generic_anomaly_ends_when_every_sensor_agrees_after_the_detectors_alarm():
    loop, _ = make_loop(N=300, seed=0)
    r = recover([loop], [Anomaly(10.0, 14.0, None)], RecoverySettings(hold_s=0.5)).anomalies[0]
    # healthy sensors: the first samples after the alarm agree (the hold confirms it)
    assert r.t_recovered_end == pytest.approx(14.0) and r.t_agreed == pytest.approx(14.0)
    assert "agreed" in r.end_reason and not r.alarm_kept


def test_a_generic_anomaly_whose_sensor_still_shows_it_ends_hold_s_after_the_alarm():
    loop, _ = make_loop(N=300, seed=0, attacks=[("gps", 10.0, 20.0, 30.0)])
    r = recover([loop], [Anomaly(10.3, 14.0, None)], RecoverySettings(hold_s=0.5)).anomalies[0]
    assert r.t_recovered_end == pytest.approx(14.5) and r.t_agreed is None and r.alarm_kept
    assert r.end_reason == "0.5 s after the detector's alarm"


def test_an_anomaly_detected_inside_the_previous_recovery_merges_with_it():
    loop, _ = make_loop(N=300, seed=0, attacks=[("gps", 10.0, 15.0, 3.0)])
    anomalies = [Anomaly(10.3, 11.0, GPS), Anomaly(12.2, 13.0, GPS), Anomaly(20.0, 21.0, GPS)]
    rec = recover([loop], anomalies, RecoverySettings(hold_s=0.5))
    assert [r.merged for r in rec.anomalies] == [2, 1]
    assert 15.0 - 1e-9 <= rec.anomalies[0].t_recovered_end <= 15.5


def test_no_checkpoint_before_the_anomaly_recovers_nothing_and_says_so():
    loop, _ = make_loop(N=100, seed=0)
    rec = recover([loop], [Anomaly(0.15, 1.0, None)], RecoverySettings(detection_time_s=0.5))
    r = rec.anomalies[0]
    assert r.t_checkpoint is None and "no consistent checkpoint" in r.note
    assert not rec.loops["outer"].recovered.any()


# ---- T_max, outlasted -----------------------------------------------------------------------------
def test_t_max_is_the_first_time_the_bound_exceeds_the_allowed_error():
    loop, _ = make_loop(N=300, seed=0)
    settings = RecoverySettings(method="rollforward", allowed_error={"outer.p": 0.5, "outer.v": 1e6}, hold_s=0.0)
    rec = recover([loop], [Anomaly(10.0, 20.0, None)], settings)
    r, lr = rec.anomalies[0], rec.loops["outer"]
    T = r.t_max["outer.p"]
    assert T is not None and 0 < T < 10.0
    m = lr.recovered
    first = lr.t[m][np.flatnonzero(lr.bound[m, 0] > 0.5)[0]]
    assert first - 10.0 == pytest.approx(T)
    assert r.t_max["outer.v"] is None  # never within the horizon
    assert r.outlasted == ("outer.p",) and r.verdict == UNTRUSTWORTHY
    short = recover([loop], [Anomaly(10.0, 10.0 + T / 2, None)], settings).anomalies[0]
    assert short.outlasted == () and short.verdict == ""


def test_settings_are_validated_with_every_problem_listed():
    with pytest.raises(ProfileError) as err:
        RecoverySettings(method="magic", hold_s=-1.0, k_sigma=0.0, allowed_error={"p": 1.0})
    assert len(err.value.problems) == 4
    assert "magic" in str(err.value) and "refilter" in str(err.value)
    loop, _ = make_loop(N=50)
    with pytest.raises(ProfileError, match="outer.q") as err:
        recover([loop], [], RecoverySettings(allowed_error={"outer.q": 1.0}))
    assert "outer.p" in err.value.hint


def test_inputs_are_checked():
    loop, _ = make_loop(N=50)
    with pytest.raises(ValueError, match="unknown loop"):
        recover([loop], [Anomaly(2.0, 3.0, {"inner": ("gps",)})])
    with pytest.raises(ValueError, match="lacks"):
        recover([loop], [Anomaly(2.0, 3.0, {"outer": ("lidar",)})])
    loop.trace = run_ekf(loop.model, loop.run)
    with pytest.raises(ValueError, match="full_P"):
        recover([loop], [])


def test_params_are_the_two_group_loop():
    assert set(PARAMS["C"]) == {"gps", "odo"}


def test_the_agreement_test_uses_a_groups_per_sample_noise():
    from logscan.recovery.agreement import AGREE, DISAGREE, agreement_status

    loop, _ = make_loop(N=250, seed=3, attacks=[("gps", 10.0, 25.0, 3.0)])
    part = rerun(loop, 90, 200, ("gps",))
    status = agreement_status(loop, 90, part, ("gps",), 0.99)
    assert np.mean(status[20:] == DISAGREE) > 0.9  # the 10-sigma bias, against R = 0.3^2
    loop.run.groups["gps"].noise_std_series = np.full((250, 1), 100.0)  # the receiver says 100 m
    status = agreement_status(loop, 90, part, ("gps",), 0.99)
    assert np.all(status[1:] == AGREE)


def test_each_flagged_loop_ends_when_its_own_sensors_agree_again():
    a, _ = make_loop("a", N=400, seed=5, attacks=[("gps", 10.0, 15.0, 3.0)])
    b, _ = make_loop("b", N=400, seed=6, attacks=[("gps", 10.0, 25.0, 3.0)])
    r = recover([a, b], [Anomaly(10.3, 11.0, {"a": ("gps",), "b": ("gps",)})], RecoverySettings(hold_s=1.0)).anomalies[
        0
    ]
    assert 15.0 - 1e-9 <= r.loop_ends["a"] <= 16.0 and 25.0 - 1e-9 <= r.loop_ends["b"] <= 26.0, r.loop_ends
    assert r.t_recovered_end == r.loop_ends["b"] and r.t_agreed == pytest.approx(r.loop_ends["b"])


def test_a_merged_anomaly_keeps_a_loop_recovering_until_after_its_latest_detection():
    # b's sensor never agrees again, so the second attack on a falls inside the first anomaly's span
    # (no consistent checkpoint in between): a must be recovered through its second attack too
    a, _ = make_loop("a", N=300, seed=5, attacks=[("gps", 10.0, 15.0, 3.0), ("gps", 20.0, 25.0, 3.0)])
    b, _ = make_loop("b", N=300, seed=6, attacks=[("gps", 10.0, 40.0, 3.0)])
    anomalies = [Anomaly(10.3, 11.0, {"a": ("gps",), "b": ("gps",)}), Anomaly(20.3, 21.0, {"a": ("gps",)})]
    rec = recover([a, b], anomalies, RecoverySettings(hold_s=1.0))
    (r,) = rec.anomalies
    assert r.merged == 2 and 25.0 - 1e-9 <= r.loop_ends["a"] <= 26.0, r.loop_ends
    assert rec.loops["a"].recovered[int(round(22.0 / 0.1))]
