"""The frozen-sensor check (docs/algorithms.md section 1f): an exact freeze and a freeze with tiny
quantisation noise alarm naming the channel, with the change time read back to the freeze; a slow
healthy channel, a smooth noiseless ramp, a forward-filled CSV channel and a sensor that holds its
value whenever it is still are not called stuck; end-to-end on simulated stuck sensors of both
models."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan.align import AlignedGroup, AlignedRun
from logscan.detectors.frozen import FrozenSensorDetector, held_runs

DT = 0.01
N = 6000  # 60 s at 100 Hz


def make_run(columns: dict[str, tuple[np.ndarray, np.ndarray, float]]) -> AlignedRun:
    """A run of one-channel groups: name -> (values held on the grid, fresh mask, noise std)."""
    t = np.arange(N) * DT
    groups = {
        name: AlignedGroup(name, [f"/sensor/{name}"], z[:, None], fresh, noise_std=np.array([std]))
        for name, (z, fresh, std) in columns.items()
    }
    return AlignedRun(t, DT, 0, np.zeros((N, 0)), np.ones(N, bool), [], groups)


def noisy(seed: int, std: float = 0.1) -> np.ndarray:
    return np.random.default_rng(seed).normal(1.0, std, N)


EVERY_STEP = np.ones(N, dtype=bool)


def test_an_exact_freeze_alarms_naming_the_channel_within_a_tenth_of_a_second():
    z = noisy(1)
    z[3000:3500] = z[2999]  # frozen at its last value from 30 s to 35 s
    result = FrozenSensorDetector().run(make_run({"gyro": (z, EVERY_STEP, 0.1), "baro": (noisy(2), EVERY_STEP, 0.1)}))
    assert [a.signal for a in result.alarms] == ["frozen.gyro"]
    alarm = result.alarms[0]
    assert 30.0 < alarm.start < 30.1
    assert alarm.end == pytest.approx(34.99)
    assert alarm.change_time == pytest.approx(30.0)
    assert result.info["channels"]["frozen.gyro"] == "/sensor/gyro"
    assert "stuck" in FrozenSensorDetector.signal_label("frozen.gyro")


def test_a_freeze_with_tiny_quantisation_noise_alarms():
    """The value stops but wobbles by 1e-5 (a thousandth of the sensor's noise): still stuck."""
    z = noisy(3)
    wobble = 1e-5 * np.random.default_rng(4).choice([-1.0, 0.0, 1.0], 500)
    z[3000:3500] = z[2999] + wobble
    result = FrozenSensorDetector().run(make_run({"accel": (z, EVERY_STEP, 0.1)}))
    assert len(result.alarms) == 1
    assert 30.0 < result.alarms[0].start < 30.1


def test_a_slow_channel_held_on_a_fast_grid_is_not_stuck():
    """A 1 Hz sensor is held for 100 grid steps between its samples: only fresh samples count."""
    fresh = np.zeros(N, dtype=bool)
    fresh[::100] = True
    samples = noisy(5)[fresh]
    z = np.repeat(samples, 100)
    result = FrozenSensorDetector().run(make_run({"baro": (z, fresh, 0.1)}))
    assert result.alarms == []
    assert result.info["fill"]["frozen.baro"] == 1.0


def test_a_smooth_noiseless_ramp_is_not_stuck():
    """Each step is far below the stated noise, but the value keeps moving away from where it was."""
    z = 1.0 + 1e-4 * np.arange(N)
    result = FrozenSensorDetector().run(make_run({"position": (z, EVERY_STEP, 0.5)}))
    assert result.alarms == []


def test_a_sensor_that_holds_its_value_whenever_still_is_not_checked():
    """A noiseless, quantised velocity (0.01 steps, exactly 0 at rest on most steps) is left out,
    with the reason, rather than called stuck at every standstill."""
    t = np.arange(N) * DT
    speed = np.where((t % 10.0) < 3.0, np.sin(2 * np.pi * t / 3.0), 0.0)
    z = np.round(speed, 2)
    result = FrozenSensorDetector().run(make_run({"velocity": (z, EVERY_STEP, 0.1)}))
    assert result.alarms == []
    assert "frozen.velocity" in result.info["not_checked"]
    # said beside the verdict too, as a check with nothing to judge (the verdict stands)
    (line,) = [c for c in result.not_checked if c.reason.startswith("velocity: repeats its sample")]
    assert not line.partial


def test_a_forward_filled_channel_counts_its_own_samples():
    """A 10 Hz channel repeated on every 100 Hz row: ten equal samples per value are its fill, not a
    freeze (L = 10); holding it for 2 s (20 of its samples) is stuck."""
    slow = np.repeat(noisy(6)[::10], 10)
    filled = make_run({"position": (slow, EVERY_STEP, 0.1)})
    result = FrozenSensorDetector().run(filled)
    assert result.alarms == []
    assert result.info["fill"]["frozen.position"] == 10.0
    frozen = slow.copy()
    frozen[3000:3200] = frozen[2999]
    result = FrozenSensorDetector().run(make_run({"position": (frozen, EVERY_STEP, 0.1)}))
    assert [a.signal for a in result.alarms] == ["frozen.position"]
    assert 30.0 < result.alarms[0].start < 31.0


@settings(max_examples=30, deadline=None)
@given(st.lists(st.integers(-3, 3), min_size=1, max_size=60), st.floats(0.0, 2.0))
def test_held_runs_anchor_every_sample_within_tol_of_its_run_start(values, tol):
    v = np.asarray(values, dtype=np.float64)
    anchor, held, lengths = held_runs(v, tol, np.zeros(0, dtype=bool))
    assert held.tolist() == (np.arange(1, v.size + 1) - anchor).tolist()
    assert lengths.sum() == v.size and lengths.size == np.count_nonzero(held == 1)
    assert anchor[0] == 0
    assert np.all(anchor <= np.arange(v.size))
    assert np.all(np.abs(v - v[anchor]) <= tol)
    starts = np.flatnonzero(anchor == np.arange(v.size))[1:]
    assert np.all(np.abs(v[starts] - v[anchor[starts - 1]]) > tol)  # a run ends only by leaving the band


# --- a wide CSV, forward-filled, through the pipeline -------------------------------------------


def forward_filled_csv(sample, tmp_path, freeze: str | None = None):
    """The shipped quad_healthy.csv with every empty cell forward-filled (the 10 Hz GPS and 50 Hz
    attitude repeated on each 100 Hz row), optionally one column frozen from 30 s to 35 s."""
    source = sample("quad_healthy.csv")
    frame = pd.read_csv(source).ffill()
    if freeze is not None:
        t = frame["time_ns"] / 1e9
        held = frame.loc[t < 30.0, freeze].iloc[-1]
        frame.loc[(t >= 30.0) & (t < 35.0), freeze] = held
    path = tmp_path / "filled.csv"
    frame.to_csv(path, index=False)
    (tmp_path / "filled.profile.toml").write_text(source.with_suffix(".profile.toml").read_text())
    return path


def frozen_alarms(path):
    from logscan.pipeline import analyze_log

    analysis = analyze_log(path, detector_names=["frozen"])
    assert not analysis.failures
    return analysis.results[0]


def test_the_shipped_csv_and_its_forward_filled_copy_raise_no_alarm(sample, tmp_path):
    assert frozen_alarms(sample("quad_healthy.csv")).alarms == []
    result = frozen_alarms(forward_filled_csv(sample, tmp_path))
    assert result.alarms == []
    assert result.info["fill"]["frozen.position.px"] == pytest.approx(10.0)


@pytest.mark.parametrize(
    "column, signal", [("/imu/accel.y", "frozen.accel.ay"), ("/gps/position.x", "frozen.position.px")]
)
def test_a_frozen_column_of_a_forward_filled_csv_alarms(sample, tmp_path, column, signal):
    result = frozen_alarms(forward_filled_csv(sample, tmp_path, freeze=column))
    assert [a.signal for a in result.alarms] == [signal]
    assert 30.0 <= result.alarms[0].start < 31.0
    assert result.info["channels"][signal] == column


# --- end to end on simulated stuck sensors -------------------------------------------------------


@pytest.mark.parametrize(
    "model, fault, signal",
    [
        ("quadcopter", "stuck:gyro.y:30:35", "frozen.gyro.gy"),
        ("steer_by_wire", "stuck:yaw_rate:30:35", "frozen.yaw_rate"),
    ],
)
def test_a_simulated_stuck_sensor_is_caught_within_a_second(cli, tmp_path, model, fault, signal):
    from logscan.pipeline import analyze_log

    path = tmp_path / f"{model}.mcap"
    assert cli("simulate", model, "--fault", fault, "--seed", "11", "--duration", "45", "-o", path).exit_code == 0
    analysis = analyze_log(path, detector_names=["frozen"])
    alarms = analysis.results[0].alarms
    assert [a.signal for a in alarms] == [signal]
    assert 30.0 < alarms[0].start < 31.0
    assert alarms[0].change_time == pytest.approx(30.0, abs=0.05)


def test_a_channel_without_samples_gets_no_statistic_and_says_why():
    """A statistic with no finite value would make the log "not fully checked": a group without
    samples is the other checks' to report; this one lists it as not checked."""
    fresh = np.zeros(N, dtype=bool)
    result = FrozenSensorDetector().run(
        make_run({"gps": (np.full(N, np.nan), fresh, 0.5), "gyro": (noisy(9), EVERY_STEP, 0.1)})
    )
    assert list(result.series) == ["frozen.gyro"]
    assert result.info["not_checked"] == {"frozen.gps": "fewer than 2 samples"}
    assert [(c.reason, c.partial) for c in result.not_checked] == [("gps: fewer than 2 samples", False)]
