"""Calibration of the process noise Q by `logscan train --calibrate` (logscan.training.process_noise).

Simulated quadcopter logs (their process noise is the model's default Q) analysed with a profile
whose Q is 10x too large (and one 10x too small), the measurement noise right: R-only calibration
cannot bring the gyro's mean NIS per output to 1 (most of its innovation covariance is H P H^T);
calibrating Q too brings every group of an unseen healthy log within 0.5-2, and `analyze --tables`
applies the Q scales (the same tables without them leave the gyro far from 1).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.filters.q_scale import scale_vector, scaled_Q
from logscan.models import get_model
from logscan.pipeline import load_profile_for
from logscan.report.training_page import render_training_html
from logscan.training.calibration import base_noise_std, calibrate, calibrated_runs, process_noise_scale
from logscan.training.process_noise import evaluate, state_blocks

Q_ACCEL, Q_ANGACC = 0.2, 1.0  # the quadcopter's defaults: the simulated process noise
SIZES = {"accel": 3, "gyro": 3, "position": 3, "attitude": 3}


def _profile_with_q(text: str, factor: float) -> str:
    """The profile with the quadcopter's process noise variance times ``factor``."""
    root = math.sqrt(factor)
    params = f"params = {{ q_accel = {Q_ACCEL * root:.6g}, q_angacc = {Q_ANGACC * root:.6g} }}\n"
    assert "params" not in text.split("[inputs]")[0]
    return text.replace("[inputs]", params + "\n[inputs]", 1)


@pytest.fixture(scope="module")
def quad_logs(tmp_path_factory):
    from logscan.simulate import simulate, write_simulation

    root = tmp_path_factory.mktemp("qcal")
    paths = []
    for seed in (8201, 8202, 8203):
        path = root / f"healthy-{seed}.mcap"
        write_simulation(simulate("quadcopter", [], duration=60.0, seed=seed), path)
        paths.append(str(path))
    text = load_profile_for(paths[0], None).text
    profiles = {}
    for factor in (10.0, 0.1):
        profiles[factor] = root / f"q{factor:g}.toml"
        profiles[factor].write_text(_profile_with_q(text, factor))
    return paths, profiles


def _unseen_nis(cli, unseen, profile, tmp_path, *extra) -> dict[str, float]:
    summary = tmp_path / f"summary-{len(list(tmp_path.glob('summary-*')))}.json"
    result = cli("analyze", unseen, "--profile", profile, "--no-report", "--json", str(summary), *extra)
    assert result.exit_code in (0, 1), result.stderr
    entry = json.loads(summary.read_text())["logs"][0]
    return {g: v / SIZES[g] for g, v in entry["filter"]["mean_nis"].items()}


def _unseen_fit(paths, profile_path, calibration: dict | None) -> tuple[dict[str, float], float, dict]:
    """The unseen log's (mean NIS per output of each group, innovation cost per output) with
    ``calibration`` (None: R calibrated alone on the two training logs), and the calibration."""
    from logscan.align import align
    from logscan.readers import read_log

    loaded = load_profile_for(paths[0], str(profile_path))
    model = get_model(loaded.profile.vehicle.model, loaded.profile.vehicle.params)
    if calibration is None:
        runs = [align(read_log(p), loaded.profile) for p in paths]
        calibration = calibrate(model, runs[:2], process_noise=False)
        assert "process_noise_scale" not in calibration  # R alone: the document as before
    (unseen,) = calibrated_runs([align(read_log(paths[2]), loaded.profile)], calibration)
    scale = scale_vector(model, process_noise_scale(calibration))
    found = evaluate(model, [unseen], base_noise_std(model, unseen), scale)
    return {g: v for g, (v, _) in found.nis.items()}, found.cost / found.samples, calibration


def _worst(nis: dict[str, float]) -> float:
    return max(abs(math.log(v)) for v in nis.values())


@pytest.mark.parametrize("factor", [10.0, 0.1])
def test_q_calibration_brings_an_unseen_log_within_nis_half_to_two_better_than_r_alone(
    quad_logs, cli, tmp_path, factor
):
    (train_a, train_b, unseen), profiles = quad_logs
    tables = tmp_path / "cal.json"
    result = cli("train", train_a, train_b, "--profile", profiles[factor], "-o", tables, "--no-report", "--calibrate")
    assert result.exit_code == 0, result.stderr
    assert "process noise Q x scale per block" in result.stdout
    calibration = json.loads(tables.read_text())["calibration"]
    blocks = calibration["process_noise_blocks"]
    # velocity, attitude and body rate are told apart; the position's Q (dt^4 / 4) changes nothing
    assert not blocks["position"]["identified"] and blocks["position"]["scale"] == 1.0
    for name in ("velocity", "attitude", "body_rate"):
        assert blocks[name]["identified"], name
        assert 1 / (2.5 * factor) < blocks[name]["scale"] < 2.5 / factor, (name, blocks[name])
    for name, entry in calibration["groups"].items():  # R was right: it stays near the profile's
        np.testing.assert_allclose(entry["noise_std"], entry["profile_noise_std"], rtol=0.15, err_msg=name)
    assert 1 <= calibration["iterations"] <= 6
    page = render_training_html(json.loads(tables.read_text()))  # the training report's table
    assert (
        f"process noise Q: body_rate (p, q, r)</td><td>model&#39;s Q x 1</td><td>Q x {blocks['body_rate']['scale']:.3g}"
        in page
    )
    assert "Q x 1 (not identifiable from these logs)" in page

    before = _unseen_nis(cli, unseen, profiles[factor], tmp_path)
    after = _unseen_nis(cli, unseen, profiles[factor], tmp_path, "--tables", tables)
    assert not 0.5 <= before["gyro"] <= 2.0, before  # the wrong Q shows in the gyro's NIS
    assert all(0.5 <= v <= 2.0 for v in after.values()), after

    paths = [train_a, train_b, unseen]
    both, both_cost, _ = _unseen_fit(paths, profiles[factor], calibration)
    r_only, r_only_cost, r_alone = _unseen_fit(paths, profiles[factor], None)
    assert both == pytest.approx(after, rel=1e-6)  # the library's fit is the CLI's
    # better than R alone: its innovations likelier (lower -2 log L per output), NIS no further
    # from 1, and R alone has to distort the gyro's noise to make up for the wrong Q
    assert both_cost < r_only_cost - 0.05, (both_cost, r_only_cost)
    assert _worst(both) <= _worst(r_only) + 0.01, (both, r_only)
    gyro = r_alone["groups"]["gyro"]
    assert not 0.5 < gyro["noise_std"][0] / gyro["profile_noise_std"][0] < 1.5, gyro
    if factor > 1:  # R alone cannot bring the gyro back: most of its S is H P H^T
        assert r_only["gyro"] < 0.5 and _worst(both) < _worst(r_only) - 0.5, (both, r_only)

    # analyze applies the Q scales: the same tables without them leave the gyro's NIS far from 1
    document = json.loads(tables.read_text())
    document["calibration"].pop("process_noise_scale")
    without = tmp_path / "without_q.json"
    without.write_text(json.dumps(document))
    unscaled = _unseen_nis(cli, unseen, profiles[factor], tmp_path, "--tables", without)
    assert abs(math.log(unscaled["gyro"])) > abs(math.log(after["gyro"])) + 0.5, (after, unscaled)


def test_state_blocks_group_the_axes_of_one_quantity():
    ins = state_blocks(get_model("ins"))
    assert list(ins) == ["position", "velocity", "attitude", "gyro_bias", "accel_bias", "baro_offset"]
    assert ins["velocity"] == [3, 4, 5] and ins["baro_offset"] == [15]
    quad = state_blocks(get_model("quadcopter"))
    assert list(quad) == ["position", "velocity", "attitude", "body_rate"]
    steer = state_blocks(get_model("steer_by_wire"))
    assert [len(states) for states in steer.values()] == [1, 1, 1, 1]  # no axes: one block per state


@settings(max_examples=50, deadline=None)
@given(
    st.integers(2, 8).flatmap(
        lambda n: st.tuples(
            st.lists(st.floats(-3, 3), min_size=n * n, max_size=n * n),
            st.lists(st.floats(1e-4, 1e4), min_size=n, max_size=n),
        )
    )
)
def test_scaled_q_stays_symmetric_psd_with_each_variance_times_its_scale(data):
    entries, scales = data
    n = len(scales)
    A = np.asarray(entries).reshape(n, n)
    Q = A @ A.T
    scaled = scaled_Q(Q, np.asarray(scales))
    np.testing.assert_allclose(scaled, scaled.T, rtol=0, atol=1e-12 * max(1.0, np.abs(scaled).max()))
    np.testing.assert_allclose(np.diag(scaled), np.diag(Q) * scales, rtol=1e-12, atol=1e-300)
    assert np.linalg.eigvalsh(scaled).min() >= -1e-9 * max(1.0, np.abs(scaled).max())
