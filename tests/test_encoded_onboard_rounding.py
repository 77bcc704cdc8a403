"""The encoded EKF's on-board state check e_s against the rounding of the logged estimate
(detectors/encoded_ekf.py, `onboard_state_series`): a logged value keeps about 7 significant
digits, so an unwrapped heading that crosses 100 rad loses a digit at once. The ground robot's
healthy 30-min flights raised e_s false alarms exactly there (98.6-99.8 s and 998.8-999.9 s)."""

from __future__ import annotations

import numpy as np
import pytest

import logscan.detectors.encoded_ekf as encoded
from logscan.detectors.encoded_ekf import EncodedEkfDetector


def _significant(values: np.ndarray, digits: int = 7) -> np.ndarray:
    """``values`` printed with ``digits`` significant digits and read back (a text logger's '%.7g')."""
    return np.array([float(f"{v:.{digits}g}") for v in values.ravel()]).reshape(values.shape)


@pytest.fixture(scope="module")
def heading_past_100(tmp_path_factory):
    """A healthy ground-robot drive of 150 s as `logscan simulate` writes it (JSON, 7 significant
    digits): its on-board estimator's unwrapped heading turns about 1 rad/s and crosses 100 rad
    near 98 s, where the logged heading drops from 5 decimals to 4."""
    from logscan.needs import Needs
    from logscan.pipeline import load_profile_for, prepare
    from logscan.simulate import simulate, write_simulation

    path = tmp_path_factory.mktemp("ground_robot") / "healthy.mcap"
    write_simulation(simulate("ground_robot", duration=150.0, seed=22000, scenario="healthy"), path, "mcap-json")
    prepared = prepare(path, load_profile_for(path, None), Needs.of(ekf=()))
    theta = np.asarray(prepared.run.onboard_state[:])[:, list(prepared.model.state_names).index("theta")]
    assert np.nanmin(theta) < 99.0 and np.nanmax(theta) > 101.0  # the case: it crosses 100 rad
    return prepared


def _e_s_alarms(prepared) -> list:
    detector = EncodedEkfDetector(ex_statistic="raw")  # e_s does not depend on the e_x statistic
    result = detector.run(prepared.run, prepared.trace, model=prepared.model)
    return [a for a in result.alarms if a.signal == "e_s"]


def test_the_digit_lost_at_100_rad_raises_no_e_s_alarm(heading_past_100):
    assert _e_s_alarms(heading_past_100) == []


def test_without_the_rounding_floor_the_lost_digit_alarms(heading_past_100, monkeypatch):
    # the floor is what keeps it quiet: the band fitted on the finer digits alone is crossed
    monkeypatch.setattr(encoded, "LOGGED_PRECISION", 0.0)
    assert _e_s_alarms(heading_past_100)


def test_the_floor_covers_the_rounding_of_each_logged_state():
    rng = np.random.default_rng(7)
    x = rng.uniform(-2000.0, 2000.0, size=(5000, 3))
    error = _significant(x) - x
    assert np.all(np.abs(error) <= encoded.LOGGED_PRECISION * np.abs(x) * (1 + 1e-12))
