"""The end of an anomaly from a windowed detector's alarm: its alarm outlasts the anomaly by up to
its window (`Detector.end_delays`), so recovery looks for the end from the alarm's end minus it
(docs/algorithms.md 5.4); the sample that ended the anomaly is taken in by the recovered estimate."""

from __future__ import annotations

import numpy as np
import pytest
from recovery_linear import make_loop

from logscan.alarms import AlarmInterval
from logscan.detectors.base import END_DELAY_KEY
from logscan.detectors.cusum import CusumDetector
from logscan.detectors.nis import NisDetector
from logscan.recovery import Anomaly, RecoverySettings, anomalies_from_alarms, recover
from logscan.recovery.rerun import rerun

GPS = {"outer": ("gps",)}


def _alarm(start: float, end: float, signal: str = "nis.gps", detector: str = "nis") -> AlarmInterval:
    return AlarmInterval(start, end, start, start, 1.0, 1.0, 1.0, "upper", 1, signal, detector)


def test_nis_declares_its_window_of_each_groups_updates():
    loop, _ = make_loop(N=200, seed=1, rates={"gps": 2, "odo": 1})  # gps every 0.2 s, odo every 0.1 s
    result = NisDetector(window=10).run(loop.run, loop.trace)
    delays = result.info[END_DELAY_KEY]
    assert delays["nis.gps"] == pytest.approx(2.0) and delays["nis.odo"] == pytest.approx(1.0)
    assert delays["nis.all"] == pytest.approx(1.0)  # 10 updates of any group
    assert NisDetector(window=3).run(loop.run, loop.trace).info[END_DELAY_KEY]["nis.gps"] == pytest.approx(0.6)


def test_cusum_declares_the_capped_statistics_fall_back_to_its_threshold():
    loop, _ = make_loop(N=200, seed=1)
    det = CusumDetector()
    result = det.run(loop.run, loop.trace)
    h = result.info["h"]["cusum.gps"]
    assert result.info[END_DELAY_KEY]["cusum.gps"] == pytest.approx((1.5 - 1.0) * h / 0.25 * 0.1)
    slower = CusumDetector(kappa=0.5).run(loop.run, loop.trace).info
    assert slower[END_DELAY_KEY]["cusum.gps"] == pytest.approx((1.5 - 1.0) * slower["h"]["cusum.gps"] / 0.5 * 0.1)


def test_an_alarm_shows_its_anomaly_until_its_end_minus_its_statistics_window():
    loop, _ = make_loop(N=300, seed=0)
    other, _ = make_loop("inner", N=300, seed=1)
    delays = {"outer": {("nis", "nis.gps"): 1.0}, "inner": {("nis", "nis.gps"): 0.1}}
    alarms = {"outer": [_alarm(10.3, 16.0)], "inner": [_alarm(10.2, 15.6), _alarm(20.0, 20.2)]}
    one, two = anomalies_from_alarms(alarms, [loop, other], end_delays=delays)
    assert (one.t_detect, one.t_end) == (10.2, 16.0)
    # each loop keeps its own alarms' time: the inner loop's shorter window does not lend the outer its end
    assert one.last_seen("outer") == pytest.approx(15.0) and one.last_seen("inner") == pytest.approx(15.5)
    assert two.last_seen("inner") == pytest.approx(20.1)
    # a loop with no alarm of its own in the anomaly: the alarms showed it there only at the detection
    assert two.last_seen("outer") == 20.0 and two.last_seen_anywhere() == pytest.approx(20.1)
    # a window longer than the alarm: the alarm shows the anomaly at its start at least
    (short,) = anomalies_from_alarms({"outer": [_alarm(10.3, 10.8)]}, [loop], end_delays=delays)
    assert short.last_seen("outer") == pytest.approx(10.3)
    # no declared delay: the alarm's end
    (plain,) = anomalies_from_alarms({"outer": [_alarm(10.3, 16.0)]}, [loop])
    assert plain.seen_until == {"outer": 16.0} and plain.last_seen("outer") == 16.0


def test_an_attack_that_ends_ends_the_recovery_within_the_detectors_window_not_at_its_alarm():
    """gps attacked over [10, 15) and flagged; odo off by 0.1 over the same window and not flagged, so
    the re-filter drifts and never re-agrees: with the alarm's end alone the recovery runs to it."""
    loop, _ = make_loop(N=400, seed=0, attacks=[("gps", 10.0, 15.0, 3.0), ("odo", 10.0, 15.0, 0.1)])
    late = recover([loop], [Anomaly(10.3, 16.0, GPS)], RecoverySettings(hold_s=1.0)).anomalies[0]
    assert late.t_recovered_end >= 16.0
    seen = Anomaly(10.3, 16.0, GPS, seen_until={"outer": 15.0})
    rec = recover([loop], [seen], RecoverySettings(hold_s=1.0))
    r = rec.anomalies[0]
    assert 15.0 <= r.t_recovered_end <= 15.2 and r.end_reason.startswith("did not re-agree")
    assert "after the detector's alarm last showed the anomaly" in r.end_reason


def test_a_real_nis_alarm_outlasts_the_attack_and_recovery_ends_with_the_attack():
    loop, truth = make_loop(N=400, seed=3, attacks=[("gps", 10.0, 15.0, 3.0)])
    result = NisDetector(window=10).run(loop.run, loop.trace)
    alarms = [a for a in result.alarms if a.signal == "nis.gps"]
    assert alarms and max(a.end for a in alarms) > 15.3  # the window sum holds the attack's last samples
    delays = {"outer": {("nis", s): d for s, d in result.info[END_DELAY_KEY].items()}}
    anomalies = anomalies_from_alarms({"outer": alarms}, [loop], end_delays=delays)
    rec = recover([loop], anomalies, RecoverySettings(hold_s=1.0))
    attack = next(r for r in rec.anomalies if r.t_detect < 15.0)
    assert attack.t_end > 15.3  # the alarm outlasts the attack...
    assert 14.95 <= attack.t_recovered_end <= 15.2  # ...the recovery does not
    assert not rec.loops["outer"].recovered[int(round(15.5 / 0.1))]


def test_the_sample_that_ended_the_anomaly_is_taken_in_by_the_recovered_estimate():
    loop, truth = make_loop(N=400, seed=0, attacks=[("gps", 10.0, 15.0, 3.0), ("odo", 10.0, 15.0, 0.1)])
    rec = recover([loop], [Anomaly(10.3, 15.0, GPS)], RecoverySettings(hold_s=1.0))
    r, outer = rec.anomalies[0], rec.loops["outer"]
    k1, k = r.checkpoint_steps["outer"], int(round(r.t_recovered_end / 0.1))
    rolled = rerun(loop, k1, k, ("gps",))  # the re-filter without gps up to the end
    z = loop.run.groups["gps"].z[k, 0]
    assert abs(outer.x_recovered[k, 0] - z) < abs(rolled.x_post[-1, 0] - z)
    assert outer.bound[k, 0] < 3.0 * np.sqrt(rolled.P_post[-1, 0, 0])
    np.testing.assert_allclose(outer.x_recovered[k - 1], rolled.x_post[-2])  # only the last step changes


def test_a_generic_anomalys_loop_without_alarms_keeps_its_recovery_only_while_its_sensors_show_it():
    """A generic anomaly raised on the inner loop only: the outer loop, attacked too, is recovered
    while its own gps shows the attack and released at the attack's end, though the inner loop's
    alarm lasts 3 s longer (its recovery capped hold_s after that alarm last showed the anomaly)."""
    # (a bias that a 5 s roll-forward's growing covariance still shows: 10 = 33 sigma of the gps)
    outer, _ = make_loop(N=400, seed=0, attacks=[("gps", 10.0, 15.0, 10.0)])
    inner, _ = make_loop("inner", N=400, seed=1)
    (anomaly,) = anomalies_from_alarms(
        {"inner": [_alarm(10.3, 18.0, "nis.all")]}, [outer, inner], end_delays={"inner": {("nis", "nis.all"): 0.5}}
    )
    assert anomaly.targets is None and anomaly.last_seen("outer") == pytest.approx(10.3)
    r = recover([outer, inner], [anomaly], RecoverySettings(hold_s=1.0)).anomalies[0]
    assert 15.0 <= r.loop_ends["outer"] <= 15.2
    assert r.loop_ends["inner"] <= 17.5 + 1.0 + 1e-9
