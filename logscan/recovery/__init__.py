"""Checkpointing and roll-forward recovery (RFR) of state estimates during anomalies, per control loop.

Offline, recovery answers: "during each alarm, what should the estimator have believed?" (the
checkpointing paper; docs/algorithms.md section 5 gives the equations and the departures from the
paper). A pure library: `analyze` calls it, the report draws its result.

API
 - ``LoopRun(name, model, run, trace)``: one control loop (its own model, grid rate and sensor
   groups) with the shared EKF's trace of its run, which must hold the full ``P_post``
   (``run_ekf(model, run, full_P=True)``).
 - ``Anomaly(t_detect, t_end, targets, seen_until=None)``: the first alarmed time, the time the
   detector's alarm ended, ``targets``: loop name -> flagged group names (specific detector) or None
   (generic: every loop affected, nothing known about which sensors), and ``seen_until``: loop ->
   the latest time its alarms still showed the anomaly (an alarm's end minus its statistic's
   declared end delay, `Detector.end_delays`; None: the alarm's end).
 - ``anomalies_from_alarms({loop: [AlarmInterval, ...]}, loops, specific=True, merge_gap_s=0,
   end_delays={loop: {(detector, statistic): s}})``: one detector's alarms as anomalies (an
   alarm's statistic names its group, e.g. ``nis.gps``).
 - ``anomalies_from_truth(events, detection_time_s, loops)``: the ground-truth ORACLE, for
   evaluation only (t_detect = fault start + detection_time_s; targets from the fault's target
   ``[loop.]group[.output]`` or its channels).
 - ``RecoverySettings(method="refilter"|"rollforward"|"replace", checkpoint_period_s=0,
   detection_time_s=0, k_sigma=3, allowed_error={"loop.state": E}, hold_s=1, max_duration_s=60,
   agreement_quantile=0.99, consistency_tol_s=None, budget_per_hour=0.1, proof_hours=100)``:
   validated at creation (ProfileError listing every problem).
 - ``recover(loops, anomalies, settings) -> Recovery``: ``Recovery.loops[name]`` is a
   `LoopRecovery` with, on that loop's grid, ``x_recovered`` (N, n) (NaN outside recovered spans),
   ``bound`` (N, n) k-sigma of the covariance propagated through the recovery and ``worst_case``
   (N, n) (the paper's Proposition 5.1, labelled worst case); ``Recovery.anomalies`` one
   `AnomalyRecord` per (merged) anomaly: checkpoint time and steps, roll-forward length, recovered
   span end, whether the alarm was kept, when the flagged sensors agreed again, why each loop's
   span ended (``end_reasons``, ``end_reason``: e.g. "did not re-agree" when, after the alarms last
   showed the anomaly, a flagged sensor disagreed with the recovered estimate without showing the
   anomaly at the false-alarm budget's bound), T_max per state with an allowed error, ``outlasted``
   (``verdict`` = "recovery no longer trustworthy"), method, targets, a note when nothing could be
   recovered. At a span's last step, ended by a sample that no longer shows the anomaly, the
   recovered estimate has taken that sample in.
Times are seconds since the first loop's ``run.start_ns`` (the log's grid seconds).
Input convention: step k of a run predicts x_k = f(x_{k-1}, u[k]) as the shared EKF does; u[k] is
the input applied over the interval that ends at t_k.
"""

from logscan.recovery.anomalies import anomalies_from_alarms, anomalies_from_truth
from logscan.recovery.engine import recover
from logscan.recovery.records import (
    METHODS,
    UNTRUSTWORTHY,
    Anomaly,
    AnomalyRecord,
    LoopRecovery,
    LoopRun,
    Recovery,
    RecoverySettings,
)

__all__ = [
    "METHODS",
    "UNTRUSTWORTHY",
    "Anomaly",
    "AnomalyRecord",
    "LoopRecovery",
    "LoopRun",
    "Recovery",
    "RecoverySettings",
    "anomalies_from_alarms",
    "anomalies_from_truth",
    "recover",
]
