"""The outlier gate of a group whose error is a slow wander (docs/algorithms.md 8.4): a GNSS fix
tens of metres off for a few samples is kept out of the filter's update, and still judged.

Without the gate the wheeled model took such an outlier into its GNSS wander state (tau 300 s),
and the real Husky drive's alarms ran on for one to two minutes after a 2-s, 50-m outlier while
the filter worked it out again."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from conftest import need_testdata
from ros_edit import METRES_PER_DEG_LAT, edit_messages, shift_fix

from logscan.align import AlignedGroup, AlignedRun
from logscan.filters.ekf import pack_run, run_ekf
from logscan.filters.reference import reference_ekf
from logscan.models import get_model

ROS1_BAG = "ros-robots/robot_localization_test1_husky.bag"


def _summary(cli, path: Path, tmp_path: Path) -> tuple[int, dict, str]:
    out = tmp_path / f"{path.name}.json"
    result = cli("analyze", path, "--no-report", "--json", out)
    return result.exit_code, json.loads(out.read_text())["logs"][0], result.output


def _driving_run(outliers: dict[int, float], N: int = 4000, dt: float = 0.01) -> AlignedRun:
    """A wheeled robot driving a slow arc, its GNSS fix at 2.5 Hz (1 m noise) and heading at 10 Hz;
    ``outliers``: step -> metres added north to that fix."""
    rng = np.random.default_rng(7)
    t = np.arange(N) * dt
    u = np.column_stack([np.full(N, 1.0), np.full(N, 0.05)])
    psi = 0.05 * t
    x = np.cumsum(np.cos(psi)) * dt
    y = np.cumsum(np.sin(psi)) * dt
    fix = np.full((N, 2), np.nan)
    fresh = np.arange(N) % 40 == 0
    fix[fresh] = np.column_stack([x, y])[fresh] + rng.normal(0.0, 1.0, (int(fresh.sum()), 2))
    for step, north in outliers.items():
        fix[step, 1] += north
    heading_fresh = np.arange(N) % 10 == 0
    heading = np.where(heading_fresh, psi + rng.normal(0.0, 0.02, N), np.nan)[:, None]
    groups = {
        "position": AlignedGroup("position", ["x", "y"], fix, fresh),
        "heading": AlignedGroup("heading", ["psi"], heading, heading_fresh),
    }
    return AlignedRun(t=t, dt=dt, start_ns=0, u=u, u_fresh=np.ones(N, bool), input_channels=["v", "w"], groups=groups)


def test_a_gated_outlier_is_kept_for_the_detectors_and_out_of_the_update():
    model = get_model("wheeled", {"gnss_error_std": 3.68})
    outliers = {2000: 50.0, 2040: 50.0, 2080: 50.0}
    run = _driving_run(outliers)
    trace = run_ekf(model, run)
    g = trace.group_index("position")
    steps = list(outliers)
    gated = trace.tested & ~trace.updated
    assert sorted(np.flatnonzero(gated[:, g])) == steps  # only the outliers, none of the healthy fixes
    assert np.all(trace.nis_group[steps, g] > 50.0)  # their NIS kept for the detectors
    assert np.all(np.abs(trace.y[steps, trace.group_slice("position")][:, 1]) > 40.0)
    without = _driving_run({})
    without.groups["position"].fresh[steps] = False
    # the estimate is the one of a drive without those fixes: they were never taken in
    assert np.max(np.abs(trace.x_post - run_ekf(model, without).x_post)) < 1e-9
    ref = reference_ekf(model, pack_run(model, run))
    np.testing.assert_array_equal(gated, ref["gated"])
    np.testing.assert_array_equal(trace.updated, ref["updated"])
    assert np.max(np.abs(trace.x_post - ref["x_post"])) < 1e-9


def test_a_large_gnss_outlier_on_the_real_drive_alarms_and_the_filter_recovers(cli, tmp_path):
    """50 m north for 2 s (5 fixes) at 200 s. Before the gate the cusum's alarms ran to 308 s."""
    jumped = tmp_path / "outlier.bag"
    assert shift_fix(need_testdata(ROS1_BAG), jumped, "/fix", 200.0, 202.0, 50.0) == 5
    code, entry, text = _summary(cli, jumped, tmp_path)
    assert code == 1, text
    first = entry["incidents"][0]
    assert first["source"] == "position" and 199.5 <= first["start"] <= 201.0, first
    # the outlier's alarm, then the filter back: the window sum (10 fixes, 4 s) lets go after it
    assert all(incident["end"] <= 210.0 for incident in entry["incidents"]), entry["incidents"]


def test_a_gnss_spoof_that_drifts_half_a_metre_per_second_still_alarms(cli, tmp_path):
    """A slow pull-off (0.5 m/s north from 150 s) is never gated as one outlier: it still alarms."""

    def drift(msg, first) -> None:
        since = (msg.header.stamp.sec - first.header.stamp.sec) + 1e-9 * (
            msg.header.stamp.nanosec - first.header.stamp.nanosec
        )
        msg.latitude += 0.5 * since / METRES_PER_DEG_LAT

    spoofed = tmp_path / "drift.bag"
    assert edit_messages(need_testdata(ROS1_BAG), spoofed, "/fix", 150.0, 400.0, drift) > 600
    code, entry, text = _summary(cli, spoofed, tmp_path)
    assert code == 1, text
    assert entry["incidents"][0]["source"] == "position"
    assert 150.0 <= entry["incidents"][0]["start"] <= 250.0, entry["incidents"]
