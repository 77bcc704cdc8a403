"""The `health` detector (docs/algorithms.md section 3c): plausibility checks on PX4's own topics,
read from crafted ULog files with known events and from the real PX4 logs of ../shared/testdata/px4-ulog,
always through the real CLI (`logscan analyze ... --detector health`)."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest
import pyulog
from conftest import REPO, need_testdata, one_state_profile
from ulog_writer import write_ulog

from logscan.detectors.health import NO_TOPICS, NOTHING, HealthDetector

THRUST = "/vehicle_thrust_setpoint_0/xyz[2]"
ACCEL = "/sensor_combined_0/accelerometer_m_s2[2]"
DURATION_S = 60.0
PARAMETERS = {"BAT1_N_CELLS": 4, "BAT1_V_EMPTY": 3.5}
ERROR_AT_S = 12.0
# how late an alarm may start after its event: min_duration_s (1 s) at the source's rate, plus a
# source period and a grid step
LATE_S = 1.5


def times(rate_hz: float) -> np.ndarray:
    return np.arange(1, int(DURATION_S * rate_hz) + 1) * int(1e6 / rate_hz)  # microseconds


def between(t_us: np.ndarray, start: float, end: float) -> np.ndarray:
    t = t_us / 1e6
    return (t >= start) & (t < end)


def append_logged_messages(path: Path, messages: list[tuple[float, str, str]]) -> Path:
    """Append ULog 'L' messages (logged text: uint8 level as ASCII '0'..'7', uint64 timestamp us,
    the text) to a file ``write_ulog`` wrote; ``messages``: (seconds, level digit, text)."""
    out = bytearray()
    for t_s, level, text in messages:
        body = level.encode() + struct.pack("<Q", int(round(t_s * 1e6))) + text.encode()
        out += struct.pack("<HB", len(body), ord("L")) + body
    with open(path, "ab") as handle:
        handle.write(bytes(out))
    return path


def crafted_log(
    path: Path,
    *,
    faults: bool = True,
    eph_over: tuple[float, float] | None = None,
    px4_flags: bool = True,
    gps_until_s: float | None = None,
) -> Path:
    """60 s of a 4-cell quad armed from 5 s. With ``faults``: the battery at 12.4 V over [30, 35) s
    (under 4 x 3.5 V) and at 0 V over [45, 48) s, the GNSS fix lost (fix 1) over [20, 24) s,
    output 2 at its max (2000) over [40, 43) s, sensor_combined silent over (50, 52) s and an
    ERROR message at 12 s. ``eph_over``: eph at 4 m (over PX4's 3 m EKF2_REQ_EPH) over that span, with PX4's
    gps_check_fail_flags saying so (``px4_flags``) or clear. ``gps_until_s``: no GNSS sample from then on."""
    imu_us = times(100)
    keep = ~between(imu_us, 50.005, 52.0) if faults else np.ones(imu_us.size, bool)
    imu_us = imu_us[keep]
    n = imu_us.size
    rng = np.random.default_rng(3)
    accel = np.column_stack([np.zeros(n), np.zeros(n), -9.81 + rng.normal(0.0, 0.05, n)])
    thrust_us = times(100)
    m = thrust_us.size
    bat_us = times(10)
    voltage = np.full(bat_us.size, 15.6)
    gps_us = times(5)
    gps_us = gps_us if gps_until_s is None else gps_us[gps_us / 1e6 < gps_until_s]  # a receiver that stops
    fix = np.full(gps_us.size, 3.0)
    out_us = times(10)
    # motors as PX4 drives them: at the disarmed value (900) until armed, then near hover, varying
    outputs = np.round(1500.0 + rng.normal(0.0, 20.0, (out_us.size, 4)))
    outputs[out_us / 1e6 < 5.0] = 900.0
    if faults:
        voltage[between(bat_us, 30.0, 35.0)] = 12.4
        voltage[between(bat_us, 45.0, 48.0)] = 0.0
        fix[between(gps_us, 20.0, 24.0)] = 1.0
        outputs[between(out_us, 40.0, 43.0), 1] = 2000.0
    eph = np.full(gps_us.size, 1.0)
    if eph_over is not None:
        eph[between(gps_us, *eph_over)] = 4.0
    armed_us = times(2)
    topics = {
        "sensor_combined": (imu_us, {"accelerometer_m_s2": accel, "accelerometer_clipping": np.zeros(n)}),
        "vehicle_thrust_setpoint": (thrust_us, {"xyz": np.column_stack([np.zeros(m), np.zeros(m), np.full(m, -0.5)])}),
        "battery_status": (bat_us, {"voltage_v": voltage, "connected": np.ones(bat_us.size)}),
        "vehicle_gps_position": (
            gps_us,
            {
                "fix_type": fix,
                "eph": eph,
                "epv": np.full(gps_us.size, 1.5),
                "jamming_indicator": np.full(gps_us.size, 10.0),
            },
        ),
        "actuator_armed": (armed_us, {"armed": (armed_us / 1e6 >= 5.0).astype(float)}),
        "actuator_outputs": (out_us, {"noutputs": np.full(out_us.size, 4.0), "output": outputs}),
        "estimator_status": (
            times(10),
            {
                "filter_fault_flags": np.zeros(600),
                "gps_check_fail_flags": _eph_flags(times(10), eph_over if px4_flags else None),
            },
        ),
    }
    write_ulog(path, topics, parameters=PARAMETERS)
    messages = [(3.0, "6", "[commander] Ready for takeoff!")]
    if faults:
        messages.append((ERROR_AT_S, "3", "[sensors] accel 0 failed"))
    return append_logged_messages(path, messages)


def test_a_topic_that_never_reports_again_times_out_to_the_end_of_the_log(tmp_path, cli, profile):
    """The GNSS silent from 40 s to the end of the 60 s log: a gap no sample ends. The timeout was
    judged at the sample that ends a gap, so this one never alarmed; it alarms from when the silence
    passed 5 periods (the 5 Hz receiver: 1 s) to the log's end."""
    log = crafted_log(tmp_path / "gps_stops.ulg", faults=False, gps_until_s=40.0)
    code, entry = analyze(cli, log, profile, tmp_path / "report.html")
    alarms = health_entry(entry)["alarms"]
    assert code == 1 and {a["signal"] for a in alarms} == {"health.timeout.vehicle_gps_position_0"}, alarms
    (timeout,) = alarms
    assert timeout["start"] == pytest.approx(39.8 + 5 * 0.2, abs=0.05)  # its last sample at 39.8 s
    assert timeout["end"] >= 59.9


def _eph_flags(t_us: np.ndarray, eph_over: tuple[float, float] | None) -> np.ndarray:
    """PX4's gps_check_fail_flags: its eph bit (8) set where eph is over EKF2_REQ_EPH."""
    flags = np.zeros(t_us.size)
    if eph_over is not None:
        flags[between(t_us, *eph_over)] = 8.0
    return flags


@pytest.fixture
def profile(tmp_path) -> Path:
    path = tmp_path / "one.profile.toml"
    path.write_text(one_state_profile(THRUST, ACCEL), encoding="utf-8")
    return path


def analyze(cli, log: Path, profile: Path, report: Path) -> tuple[int, dict]:
    """`logscan analyze --detector health`: exit code and the log's JSON entry."""
    result = cli(
        "analyze", str(log), "--profile", str(profile), "--json", "-", "-o", str(report), "--detector", "health"
    )
    assert result.exit_code in (0, 1, 2), result.stderr
    return result.exit_code, json.loads(result.stdout)["logs"][0]


def health_entry(entry: dict) -> dict:
    return next(d for d in entry["detectors"] if d["detector"] == "health")


def only(alarms: list, signal: str) -> dict:
    found = [a for a in alarms if a["signal"] == signal]
    assert len(found) == 1, (signal, [(a["signal"], a["start"]) for a in alarms])
    return found[0]


# --- the crafted logs ----------------------------------------------------------------------------


def test_crafted_log_is_read_by_pyulog(tmp_path):
    path = crafted_log(tmp_path / "crafted.ulg")
    ulog = pyulog.ULog(str(path))
    assert [(m.log_level_str(), m.timestamp) for m in ulog.logged_messages] == [
        ("INFO", 3_000_000),
        ("ERROR", 12_000_000),
    ]
    assert ulog.get_dataset("actuator_outputs").data["output[1]"].max() == 2000.0


def test_each_fault_is_one_alarm_of_its_check_at_its_time(tmp_path, cli, profile):
    code, entry = analyze(cli, crafted_log(tmp_path / "crafted.ulg"), profile, tmp_path / "report.html")
    assert code == 1
    result = health_entry(entry)
    alarms = result["alarms"]
    expected = {
        "health.battery": (30.0, 35.0),
        "health.battery_zero": (45.0, 48.0),
        "health.gnss_fix": (20.0, 24.0),
        "health.motor_max.2": (40.0, 43.0),
    }
    for signal, (start, end) in expected.items():
        alarm = only(alarms, signal)
        assert alarm["first_exceed"] == pytest.approx(start, abs=0.15), signal
        assert start <= alarm["start"] <= start + LATE_S, signal
        assert alarm["end"] <= end + 0.15, signal
    assert only(alarms, "health.battery")["peak_value"] == pytest.approx(4 * 3.5 / 12.4, rel=1e-5)
    timeout = only(alarms, "health.timeout.sensor_combined_0")
    # from when the silence passed 5 periods (the gap begins at 50 s) to the sample that ends it
    assert timeout["start"] == pytest.approx(50.0 + 5 * 0.01, abs=0.02)
    assert timeout["end"] == pytest.approx(52.0, abs=0.02)
    assert timeout["peak_value"] == pytest.approx(2.0 / (5 * 0.01), rel=0.01)  # the gap / (5 periods)
    error = only(alarms, "health.logged_error")
    assert error["start"] == pytest.approx(ERROR_AT_S, abs=0.02)
    assert {a["signal"] for a in alarms} == set(expected) | {"health.timeout.sensor_combined_0", "health.logged_error"}

    info = result["info"]
    (logged,) = info["logged_errors"]
    assert logged["level"] == "ERROR" and logged["text"] == "[sensors] accel 0 failed"
    assert logged["time"] == pytest.approx(ERROR_AT_S, abs=0.02)  # the grid counts from the first sample
    battery = info["checks"]["health.battery"]["limit"]
    assert battery["cells"] == 4 and battery["cells_from"] == "BAT1_N_CELLS" and battery["cell_empty_v"] == 3.5
    assert info["checks"]["health.motor_saturated"]["limit"]["outputs"] == ["1", "2", "3", "4"]
    assert info["checks"]["health.gnss_eph"]["limit"]["m"] == 3.0  # PX4's default EKF2_REQ_EPH
    assert "health.imu_clipping" in info["checks"] and "health.estimator_fault" in info["checks"]
    assert "health.motor_saturated" not in {a["signal"] for a in alarms}  # one output of four
    assert result["warnings"] == [] and entry["unchecked"] == []


def test_a_clean_log_raises_no_alarm(tmp_path, cli, profile):
    code, entry = analyze(cli, crafted_log(tmp_path / "clean.ulg", faults=False), profile, tmp_path / "report.html")
    result = health_entry(entry)
    assert result["alarms"] == [] and code == 0
    assert result["info"]["logged_errors"] == []
    assert len(result["info"]["checks"]) >= 15


def test_a_shorter_dip_than_min_duration_is_no_alarm(tmp_path, cli, profile):
    text = profile.read_text(encoding="utf-8") + "\n[detectors.health]\nmin_duration_s = 6.0\n"
    profile.write_text(text, encoding="utf-8")
    _, entry = analyze(cli, crafted_log(tmp_path / "crafted.ulg"), profile, tmp_path / "report.html")
    signals = {a["signal"] for a in health_entry(entry)["alarms"]}
    # 5 s battery dip, 4 s fix loss, 3 s saturation: all shorter than 6 s; timeouts and logged
    # errors are one-sample checks
    assert signals == {"health.timeout.sensor_combined_0", "health.logged_error"}


@pytest.mark.parametrize(("over_s", "alarmed"), [(4.0, False), (8.0, True)])
def test_gnss_accuracy_alarms_only_once_px4_would_call_its_checks_failing(over_s, alarmed, tmp_path, cli, profile):
    """eph over EKF2_REQ_EPH is a fault once it has lasted PX4's own 5 s (gps_checks_failing), not before."""
    log = crafted_log(tmp_path / "eph.ulg", faults=False, eph_over=(20.0, 20.0 + over_s))
    _, entry = analyze(cli, log, profile, tmp_path / "report.html")
    result = health_entry(entry)
    eph = [a for a in result["alarms"] if a["signal"] == "health.gnss_eph"]
    assert bool(eph) == alarmed, eph
    if alarmed:
        assert eph[0]["first_exceed"] == pytest.approx(25.0, abs=0.2)  # the 5 s PX4 waits, then the alarm
        assert 25.0 <= eph[0]["start"] <= 25.0 + LATE_S
    assert result["info"]["checks"]["health.gnss_eph"]["limit"]["for_s"] == 5.0


def test_gnss_accuracy_over_the_limit_is_no_fault_while_px4_own_checks_pass(tmp_path, cli, profile):
    """eph over EKF2_REQ_EPH for 8 s, but PX4's own gps_check_fail_flags clear (PX4 passed its checks
    on its own values): PX4 never called its GNSS failing, so neither does logscan."""
    log = crafted_log(tmp_path / "eph.ulg", faults=False, eph_over=(20.0, 28.0), px4_flags=False)
    _, entry = analyze(cli, log, profile, tmp_path / "report.html")
    assert not [a for a in health_entry(entry)["alarms"] if a["signal"] == "health.gnss_eph"]


def test_without_raw_channels_the_detector_says_so_on_any_run():
    from test_detector_contract import synthetic_run

    run = synthetic_run()
    result = HealthDetector().run(run)  # no raw= and no metadata= context
    assert result.alarms == [] and result.warnings == [NO_TOPICS]
    assert set(result.series) == {NOTHING} and not np.isfinite(result.series[NOTHING]).any()


def test_parameters_are_checked():
    from logscan.detectors.registry import default_registry
    from logscan.errors import ProfileError

    for key, value in (("min_duration_s", -1.0), ("jamming_limit", 0.0), ("timeout_periods", 0.5)):
        with pytest.raises(ProfileError, match=key):
            default_registry().create("health", {key: value})


# --- the real PX4 logs ---------------------------------------------------------------------------

EXAMPLES = REPO / "docs" / "examples"
REAL_LOGS = {  # log -> the example profile of its PX4 generation (as tests/test_px4_ins_profiles.py)
    "sample_log_small.ulg": "px4-ins.profile.toml",
    "sample_logging_tagged_and_default_params.ulg": "px4-ins.profile.toml",
    "sample_px4_events.ulg": "px4-ins-v1.14.profile.toml",
    "sample_appended_multiple.ulg": "px4-ins-legacy.profile.toml",
}


@pytest.mark.parametrize(("log", "profile"), sorted(REAL_LOGS.items()))
def test_real_px4_logs(log, profile, cli, capsys, tmp_path):
    path = need_testdata(Path("px4-ulog") / log)
    code, entry = analyze(cli, path, EXAMPLES / profile, tmp_path / "report.html")
    assert code in (0, 1)
    result = health_entry(entry)
    assert result["info"]["checks"] and not any(line.startswith("health") for line in entry["unchecked"])
    # healthy logs: the only alarms are sample_log_small's GNSS accuracy, which PX4 itself flagged
    # (its estimator_status gps_check_fail_flags has the eph and epv bits set)
    signals = {a["signal"] for a in result["alarms"]}
    assert signals <= {"health.gnss_eph", "health.gnss_epv"}
    if signals:
        assert result["info"]["gps_check_fail_flags"]["estimator_status_0"]["bits_ever_set"] & (8 | 32)
    with capsys.disabled():
        counts: dict[str, int] = {}
        for alarm in result["alarms"]:
            counts[alarm["signal"]] = counts.get(alarm["signal"], 0) + 1
        print(f"\n{log}: {len(result['info']['checks'])} checks, alarms {counts or 'none'}")
