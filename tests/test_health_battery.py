"""The battery checks judge what PX4 itself judges (docs/algorithms.md section 3c): its filtered
voltage, not the raw reading that swings with the motors' current, and its own battery warning."""

from __future__ import annotations

import json

import pytest
from conftest import need_testdata

ROBOLOGS = "px4-ulog-extra/robologs_fmu_v5_test.ulg"
BOOT_AT_ZERO_S = 3.12937  # the log's first timestamp, PX4 boot time
LAST_BATTERY_S = 12.07  # battery_status's last sample, boot time


@pytest.mark.testdata(ROBOLOGS)
def test_the_robologs_battery_alarms_from_its_filtered_voltage_under_empty_to_the_end(cli, tmp_path):
    """battery_status.voltage_filtered_v is under 4 x BAT1_V_EMPTY (3.5 V) = 14.0 V from 4.28 s boot
    time to the log's end, and ``warning`` is EMERGENCY (3) in all 46 samples (PX4 said "Dangerous
    battery level!" at 3.24 s); the raw voltage_v swings 12.9-14.3 V around the limit and gave an
    alarm of 0.4 s (5.27-5.67 s) alone."""
    out = tmp_path / "s.json"
    result = cli("analyze", str(need_testdata(ROBOLOGS)), "-d", "health", "--no-report", "--json", str(out))
    assert result.exit_code == 1, result.stdout + result.stderr
    (log,) = json.loads(out.read_text())["logs"]
    (health,) = [d for d in log["detectors"] if d["detector"] == "health"]
    alarms = {a["signal"]: a for a in health["alarms"]}
    battery = alarms["health.battery"]
    assert battery["first_exceed"] + BOOT_AT_ZERO_S == pytest.approx(4.28, abs=0.03)
    assert battery["end_clock"] == pytest.approx(LAST_BATTERY_S, abs=0.03)
    assert battery["peak_value"] == pytest.approx(14.0 / 13.652, rel=1e-3)  # the filtered minimum
    limit = health["info"]["checks"]["health.battery"]["limit"]
    assert limit["voltage"] == "battery_status_0.voltage_filtered_v" and limit["empty_v"] == 14.0
    warning = alarms["health.battery_warning"]  # PX4's EMERGENCY from its first sample on
    assert warning["start_clock"] == pytest.approx(3.27, abs=0.03)
    assert warning["end_clock"] == pytest.approx(LAST_BATTERY_S, abs=0.03)
    assert "battery warning critical or worse" in result.stdout
