"""The recovery evaluation (bench/rfr_scenarios.py) on one unseen seed of the paper's ground robot:
recovery beats the shared EKF during the anomalies, and the k-sigma bound covers the truth."""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "bench"))
import rfr_scenarios as rfr  # noqa: E402

SEED = 101  # the bench's first unseen seed


@pytest.fixture(scope="module")
def robot_log(tmp_path_factory):
    root = tmp_path_factory.mktemp("rfr")
    return str(rfr.simulate(str(root / f"robot-{SEED}.mcap"), SEED)), root


def measure(robot_log, variant: rfr.Variant) -> dict:
    path, root = robot_log
    profile = root / f"{variant.detector}-{variant.method}-{variant.shifted}.toml"
    profile.write_text(rfr.profile_text(path, variant, 1.0), encoding="utf-8")
    return rfr.pooled(
        [{variant.label: rfr.measure_variant(path, str(profile), shifted=variant.shifted)}], variant.label
    )


def test_truth_is_read_on_the_loops_grids_and_the_anomaly_windows_are_the_papers(robot_log):
    from logscan.pipeline import analyze_log

    path, root = robot_log
    profile = root / "oracle.toml"
    profile.write_text(rfr.profile_text(path, rfr.Variant("oracle", "rollforward"), 1.0), encoding="utf-8")
    analysis = analyze_log(path, str(profile))
    outer = analysis.recovery.loops["outer"]
    truth = rfr.true_states(path, analysis.prepared.log.truth, "outer", analysis.prepared.run.start_ns, outer.t)
    # outside the attacks the shared EKF tracks the truth within a few of its sigmas
    mask = rfr.anomaly_mask(analysis.events, outer.t)
    healthy = ~mask & (outer.t < 3.0)
    assert np.max(np.abs(analysis.prepared.trace.x_post[healthy, 0] - truth[healthy, 0])) < 0.5
    # 3.25-5 s and 8.25-10 s on the 10 Hz grid: 3.3 .. 4.9 and 8.3 .. 9.9
    assert mask.sum() == 2 * 17 and outer.t[mask][0] == pytest.approx(3.3)
    # after the attacks: [5, 8.25) and from 10 s to the end of the log, every step after the first attack in no attack
    post = rfr.post_attack_mask(analysis.events, outer.t, mask)
    expected = ((outer.t >= 5.0 - 1e-9) & (outer.t < 8.25)) | (outer.t >= 10.0 - 1e-9)
    np.testing.assert_array_equal(post, expected)


def test_after_the_attacks_the_oracles_recovery_is_no_worse_than_the_ekf(robot_log):
    """A recovery ends when its sensors agree again or do not re-agree (docs/algorithms.md 5.4), so
    it does not dead-reckon past the attacks: what a user reads there (recovered inside the spans,
    the EKF's elsewhere) is no worse than the EKF alone."""
    for method in rfr.METHODS:
        figures = measure(robot_log, rfr.Variant("oracle", method))
        assert figures["post_rec"] <= figures["post_ekf"], (method, figures["post_rec"], figures["post_ekf"])
        assert figures["post_recovered_s"][1] < 1.0  # seconds recovered past the attacks on this seed


def test_oracle_recovery_beats_the_ekf_during_the_anomalies(robot_log):
    for method in rfr.METHODS:
        figures = measure(robot_log, rfr.Variant("oracle", method))
        assert figures["covered"] == 1.0
        assert figures["rec"] < 0.8 * figures["ekf"], (method, figures["rec"], figures["ekf"])
        # the worst case (Proposition 5.1) is far looser than the k-sigma bound
        assert figures["worst_x"] > 10 * figures["bound_x"]


def test_the_pipelines_bound_covers_the_truth_and_refiltering_matches_the_prototype(robot_log):
    """With the simulator's input timing declared ([inputs] stamp = "start"): the 3-sigma bound
    covers >= 90 % of the recovered samples, and re-filtering without the attacked position (the
    heading still used) stays near the prototype's 0.36 m (this seed is the 20-seed bench's worst
    re-filtered one, 0.52 m; pooled 0.33 m)."""
    rolled = measure(robot_log, rfr.Variant("oracle", "rollforward"))
    refiltered = measure(robot_log, rfr.Variant("oracle", "refilter"))
    assert rolled["coverage"] >= 0.9 and refiltered["coverage"] >= 0.9
    assert refiltered["rec"] < 0.6
    assert refiltered["rec"] < 0.2 * refiltered["ekf"]


def test_inputs_one_step_early_break_the_bound(robot_log):
    """The contrast: the same inputs one step early (a profile without stamp = "start") and the
    roll-forward drifts outside its own bound, worse than with the right timing. (It no longer runs
    on into the next attack: a recovery that does not re-agree after an attack ends there, so each
    attack is recovered from its own checkpoint, and the contrast is smaller than when one drifting
    roll-forward ran through both attacks.)"""
    early = measure(robot_log, rfr.Variant("oracle", "rollforward", shifted=True))
    rolled = measure(robot_log, rfr.Variant("oracle", "rollforward"))
    assert early["coverage"] < 0.5 and early["rec"] > 1.5 * rolled["rec"]
