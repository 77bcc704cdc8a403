"""The built-in px4 profile's IMU: sensor_combined, or vehicle_imu's increments at the full rate.

vehicle_imu logs delta_angle (rad) and delta_velocity (m/s) integrated over delta_angle_dt
microseconds; the profile turns them into rates with the log's median period. Crafted ULogs
(tests/ulog_writer.py) of a vehicle at rest: a constant rotation rate and gravity.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from ulog_writer import write_ulog

from logscan.pipeline import builtin_profile_for
from logscan.profiles import parse_profile

RATE = np.array([0.01, -0.02, 0.03])  # rad/s
SPECIFIC_FORCE = np.array([0.0, 0.0, -9.80665])  # m/s^2, FRD at rest


def _sensor_combined(hz: float, seconds: float = 20.0):
    t_us = np.arange(0, seconds, 1 / hz) * 1e6 + 1e6
    n = t_us.size
    return t_us.astype(np.uint64), {
        "gyro_rad": np.tile(RATE, (n, 1)),
        "accelerometer_m_s2": np.tile(SPECIFIC_FORCE, (n, 1)),
    }


def _vehicle_imu(hz: float, seconds: float = 20.0):
    dt_us = 1e6 / hz
    t_us = np.arange(0, seconds, 1 / hz) * 1e6 + 1e6
    n = t_us.size
    return t_us.astype(np.uint64), {
        "delta_angle": np.tile(RATE * dt_us * 1e-6, (n, 1)),
        "delta_velocity": np.tile(SPECIFIC_FORCE * dt_us * 1e-6, (n, 1)),
        "delta_angle_dt": np.full(n, dt_us),
        "delta_velocity_dt": np.full(n, dt_us),
    }


def _air_data(seconds: float = 20.0):
    t_us = np.arange(0, seconds, 0.05) * 1e6 + 1e6
    return t_us.astype(np.uint64), {"baro_alt_meter": np.full(t_us.size, 100.0)}


def _write(path, topics):
    return write_ulog(path, {**topics, "vehicle_air_data": _air_data()})


def _profile(tmp_path, **topics):
    path = _write(tmp_path / "imu.ulg", topics)
    return path, parse_profile(builtin_profile_for(path).text)


def test_vehicle_imu_alone_is_the_ins_input_as_rates(tmp_path):
    path, profile = _profile(tmp_path, vehicle_imu=_vehicle_imu(400.0))
    gyro = profile.inputs.mapping["gyro"]
    assert gyro["channels"][0] == "/vehicle_imu_0/delta_angle[0]"
    assert gyro["scale"] == pytest.approx([400.0] * 3)  # increments per 2.5 ms -> per second
    assert profile.vehicle.rate_hz == 400.0


@pytest.mark.parametrize(("combined_hz", "imu_hz", "chosen"), [(200, 800, "vehicle_imu"), (250, 250, "sensor")])
def test_the_faster_imu_is_chosen_sensor_combined_on_a_tie(tmp_path, combined_hz, imu_hz, chosen):
    _, profile = _profile(tmp_path, sensor_combined=_sensor_combined(combined_hz), vehicle_imu=_vehicle_imu(imu_hz))
    channels = profile.inputs.mapping["gyro"]
    first = channels["channels"][0] if isinstance(channels, dict) else channels[0]
    assert first.startswith(f"/{chosen}")
    assert profile.vehicle.rate_hz == max(combined_hz, imu_hz)


def test_a_slow_vehicle_imu_is_a_not_checked_model(cli, tmp_path):
    """Too slow for the ins model: the filter-free checks run (nothing to read in this crafted log)
    and the model is a `not checked` line; the filter's detector alone is one clear error."""
    path = _write(tmp_path / "slow.ulg", {"vehicle_imu": _vehicle_imu(20.0)})
    result = cli("analyze", str(path), "--no-report")
    assert result.exit_code == 2
    assert "not checked: the ins model (logscan's filter): vehicle_imu is logged at 20 Hz" in result.stdout
    alone = cli("analyze", str(path), "--no-report", "-d", "nis")
    assert alone.exit_code == 2 and "Traceback" not in alone.stderr
    assert "vehicle_imu is logged at 20 Hz" in alone.stderr and len(alone.stderr.strip().splitlines()) == 1


def test_vehicle_imu_drives_the_filter_like_sensor_combined(cli, tmp_path):
    """The same vehicle at rest logged either way: the filter's barometer innovations agree (unscaled
    increments would read as free fall, 250 times less than gravity, and the baro NIS would soar)."""
    filters = []
    for name, topic in (
        ("a", {"sensor_combined": _sensor_combined(250.0)}),
        ("b", {"vehicle_imu": _vehicle_imu(250.0)}),
    ):
        path = _write(tmp_path / f"{name}.ulg", topic)
        out = tmp_path / f"{name}.json"
        result = cli("analyze", str(path), "--no-report", "--json", str(out), "-d", "nis")
        assert result.exit_code in (0, 1), result.output
        filters.append(json.loads(out.read_text())["logs"][0]["filter"])
    assert filters[0]["updates"] == filters[1]["updates"]
    assert filters[1]["mean_nis"]["baro"] == pytest.approx(filters[0]["mean_nis"]["baro"], rel=1e-3)
    assert filters[0]["mean_nis"]["baro"] < 0.1
