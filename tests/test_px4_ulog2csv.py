"""A PX4 log exported with pyulog's ``ulog2csv`` (a folder of ``<log>_<topic>_<n>.csv``) gets the
built-in px4 profile, as the .ulg does: the same measurement groups and grid, PX4's default
parameters (the export holds none) said in a warning, and the same detectors run.

The folder is made by pyulog's own converter from a real log (PX4 SITL, sample_px4_events.ulg).
"""

from __future__ import annotations

import json

import pytest
from conftest import need_testdata
from pyulog.ulog2csv import convert_ulog2csv

from logscan.pipeline import builtin_profile_for, load_profile_for

pytestmark = pytest.mark.testdata("px4-ulog/sample_px4_events.ulg")
SOURCE = "px4-ulog/sample_px4_events.ulg"


def _export(folder, messages=None):
    """pyulog's ulog2csv of the real log into ``folder`` (only ``messages``, comma-separated, if given)."""
    folder.mkdir()
    convert_ulog2csv(str(need_testdata(SOURCE)), messages, str(folder), ",", None, None)
    return folder


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    return _export(tmp_path_factory.mktemp("ulog2csv") / "sample_px4_events")


def test_the_export_gets_the_px4_profile_of_the_ulog(exported):
    from_csv = load_profile_for(exported, None)
    from_ulog = load_profile_for(need_testdata(SOURCE), None)
    assert from_csv.source == from_ulog.source == "built-in px4"
    assert set(from_csv.profile.measurements) == set(from_ulog.profile.measurements)
    assert from_csv.profile.vehicle.rate_hz == from_ulog.profile.vehicle.rate_hz
    assert from_csv.profile.enabled_detectors() == from_ulog.profile.enabled_detectors()
    # the same channels: ulog2csv's topics are named as the ULog reader names them
    assert from_csv.profile.topics() == from_ulog.profile.topics()
    (note,) = [n for n in from_csv.notes if "ulog2csv" in n]
    assert "no parameters" in note and "PX4's defaults" in note
    assert not any("ulog2csv" in n for n in from_ulog.notes)


def test_analyzing_the_export_runs_every_check_with_a_warning_on_parameters(cli, exported, tmp_path):
    out = tmp_path / "summary.json"
    result = cli("analyze", exported, "--no-report", "--json", out, "--allow-partial")
    assert result.exit_code in (0, 1), result.stderr
    summary = json.loads(out.read_text())["logs"][0]
    assert summary["profile_source"] == "built-in px4"
    assert {d["detector"] for d in summary["detectors"]} >= {"nis", "px4_estimator", "health"}
    assert summary["filter"]["updates"]["gnss_position"] > 0 and summary["filter"]["updates"]["baro"] > 0
    assert any("ulog2csv export holds no parameters" in w for w in summary["warnings"])
    assert "ulog2csv export holds no parameters" in result.stdout  # among the warnings the summary shows


def test_an_export_without_px4_imu_topics_still_asks_for_a_profile(cli, tmp_path):
    folder = _export(tmp_path / "sample_px4_events", "vehicle_status,battery_status")
    assert builtin_profile_for(folder) is None
    result = cli("analyze", folder, "--no-report")
    assert result.exit_code == 2 and "no profile" in result.stderr and "Traceback" not in result.stderr


def test_the_export_trains_tables_it_then_accepts(cli, exported, tmp_path):
    tables = tmp_path / "export.tables.json"
    trained = cli("train", exported, "--calibrate", "-o", tables, "--no-report", "-q")
    assert trained.exit_code == 0, trained.stderr
    (log,) = json.loads(tables.read_text())["training_logs"]  # the folder, hashed over its files
    assert log["name"] == exported.name and len(log["sha256"]) == 64
    assert log["bytes"] == sum(p.stat().st_size for p in exported.iterdir())
    analysed = cli("analyze", exported, "--tables", tables, "--no-report", "--allow-partial")
    assert analysed.exit_code in (0, 1), analysed.stderr


@pytest.mark.testdata("px4-ulog-extra/robologs_fmu_v5_test.ulg")
def test_an_export_without_a_disarmed_value_below_the_motors_does_not_call_them_stopped(tmp_path, cli):
    """The real robologs flight's actuator_outputs_0 holds 1500 while disarmed (rows of another
    publisher, noutputs 4) and 1000-1300 in flight; its .ulg has PWM_MAIN_DISARM = 900. Its export
    holds no parameters: read as "stopped", 1500 put every motor at zero for the whole flight (an
    alarm over 2.96-6.16 s). A disarmed value not below the motors' armed values is not a stop:
    the check says it cannot judge them."""
    folder = tmp_path / "robologs_fmu_v5_test"  # ulog2csv names its files after the log
    folder.mkdir()
    convert_ulog2csv(str(need_testdata("px4-ulog-extra/robologs_fmu_v5_test.ulg")), None, str(folder), ",", None, None)
    out = tmp_path / "s.json"
    result = cli("analyze", folder, "--no-report", "--json", out)
    assert result.exit_code in (0, 1, 2), result.stdout + result.stderr
    log = json.loads(out.read_text())["logs"][0]
    signals = [a["signal"] for d in log["detectors"] for a in d["alarms"]]
    assert not any(s.startswith("health.motor") for s in signals)
    assert any("value while disarmed (1500) is not below" in line for line in log["skipped_checks"])


@pytest.mark.testdata("px4-ulog-extra/robologs_fmu_v5_test.ulg")
def test_the_export_reads_in_the_ulogs_clock(cli, tmp_path):
    """ulog2csv keeps the ULog's timestamps (microseconds since PX4 booted): the real robologs
    flight's export reads in PX4 boot time as its .ulg does, not "time since log start", so one
    event has one time in both."""
    source = need_testdata("px4-ulog-extra/robologs_fmu_v5_test.ulg")
    folder = tmp_path / "robologs_fmu_v5_test"
    folder.mkdir()
    convert_ulog2csv(str(source), "vehicle_gps_position,sensor_combined,vehicle_attitude", str(folder), ",", None, None)
    clocks = {}
    for name, path in (("csv", folder), ("ulg", source)):
        out = tmp_path / f"{name}.json"
        cli("analyze", path, "--no-report", "--json", out)
        clocks[name] = json.loads(out.read_text())["logs"][0]["clock"]
    assert clocks["csv"]["name"] == clocks["ulg"]["name"] == "PX4 boot time", clocks
