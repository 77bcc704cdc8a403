"""Trained tables transfer to the other flights of one vehicle, and only to them.

The tables' profile fingerprint is what identifies the vehicle and its profile (the board, its
unique id and airframe from the ULog, the model, channels and transforms), not what a built-in
profile measures from each log (the IMU at 247.5 Hz on one flight, 250 Hz on the next); the rates
are held to within 10 % of the tables' instead. Every command a refusal suggests is run here and
must write tables the log then accepts.

Real logs, edited: PX4's SITL flight sample_px4_events.ulg with its clock stretched by 1 % (every
rate 1 % lower: the IMU at 247.5 Hz), and with its GNSS decimated to half its rate.
"""

from __future__ import annotations

import json
import shlex

import numpy as np
import pytest
from conftest import need_testdata
from pyulog import ULog

from logscan.pipeline import load_profile_for
from logscan.training.tables import profile_fingerprint

pytestmark = pytest.mark.testdata("px4-ulog/sample_px4_events.ulg")
FLIGHT = "px4-ulog/sample_px4_events.ulg"
OTHER_AIRFRAME = "px4-ulog/sample_logging_tagged_and_default_params.ulg"  # SITL too, airframe 10016


def _edited(source, path, *, stretch: float = 1.0, every: dict | None = None):
    """The real log with its clock stretched by ``stretch`` and each topic of ``every`` kept one
    sample in that many."""
    ulog = ULog(str(source))
    t0 = ulog.start_timestamp
    for data in ulog.data_list:
        t = data.data["timestamp"].astype(np.float64)
        data.data["timestamp"] = np.round(t0 + (t - t0) * stretch).astype(np.uint64)
        step = (every or {}).get(data.name, 1)
        data.data = {name: values[::step] for name, values in data.data.items()}
    for message in ulog.logged_messages:
        message.timestamp = int(round(t0 + (message.timestamp - t0) * stretch))
    ulog.write_ulog(str(path))
    return path


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """Tables calibrated on the real flight (built-in px4 profile), and the flight."""
    from logscan.cli.main import main

    root = tmp_path_factory.mktemp("transfer")
    tables = root / "flight.tables.json"
    with pytest.raises(SystemExit) as done:
        main(["train", str(need_testdata(FLIGHT)), "--calibrate", "-o", str(tables), "--no-report", "-q"])
    assert done.value.code in (0, None)
    return tables, root


def _suggested(stderr: str) -> list[str]:
    """The `logscan ...` command a refusal suggests, as arguments (without "logscan")."""
    command = stderr.split("`")[1]
    words = shlex.split(command)
    assert words[0] == "logscan"
    return words[1:]


def _mean_nis(cli, log, tmp_path, *extra) -> dict[str, float]:
    out = tmp_path / f"summary{len(extra)}.json"
    result = cli("analyze", log, "--no-report", "--json", out, "--allow-partial", *extra)
    assert result.exit_code in (0, 1), result.stderr
    return json.loads(out.read_text())["logs"][0]["filter"]["mean_nis"]


def test_tables_of_one_flight_apply_to_the_same_vehicle_at_a_slightly_other_rate(cli, trained, tmp_path):
    tables, root = trained
    assert json.loads(tables.read_text())["calibration"]["failures"] == []  # it worked on the real flight
    stretched = _edited(need_testdata(FLIGHT), root / "stretched.ulg", stretch=1.01)
    own, other = load_profile_for(need_testdata(FLIGHT), None), load_profile_for(stretched, None)
    assert own.profile.vehicle.rate_hz == 250 and other.profile.vehicle.rate_hz == 248  # measured rates differ
    assert own.profile.vehicle.id == other.profile.vehicle.id == "PX4_SITL airframe 10017"
    assert profile_fingerprint(own.profile) == profile_fingerprint(other.profile)
    without = _mean_nis(cli, stretched, tmp_path)
    with_tables = _mean_nis(cli, stretched, tmp_path, "--tables", tables)  # accepted: exit 0 or 1
    calibrated = json.loads(tables.read_text())["calibration"]["groups"]
    changed = [g for g, entry in calibrated.items() if entry["calibrated"]]
    assert changed and all(with_tables[g] != pytest.approx(without[g], rel=1e-3) for g in changed)


def test_another_airframe_is_refused_with_a_command_that_trains_its_tables(cli, trained, tmp_path):
    tables, _ = trained
    other = need_testdata(OTHER_AIRFRAME)
    refused = cli("analyze", other, "--tables", tables, "--no-report")
    assert refused.exit_code == 2 and "trained for another profile" in refused.stderr
    args = _suggested(refused.stderr)
    assert "--profile" not in args  # a built-in profile: none to pass (it used to be the .ulg)
    assert args[:2] == ["train", "HEALTHY_LOG..."] and "--calibrate" in args
    new_tables = tmp_path / "other.tables.json"
    args = [str(other) if a == "HEALTHY_LOG..." else (str(new_tables) if a == str(tables) else a) for a in args]
    assert cli(*args, "--no-report", "-q").exit_code == 0
    assert cli("analyze", other, "--tables", new_tables, "--no-report", "--allow-partial").exit_code in (0, 1)


def test_a_sensor_at_another_rate_is_refused_and_the_command_retrains(cli, trained, tmp_path):
    tables, root = trained
    half = _edited(need_testdata(FLIGHT), root / "half_rate.ulg", every={"vehicle_gps_position": 2})  # 9.6 Hz
    refused = cli("analyze", half, "--tables", tables, "--no-report")
    assert refused.exit_code == 2
    assert "trained at other rates: measurements.gnss_position.rate_hz 9.6" in refused.stderr
    args = [str(half) if a == "HEALTHY_LOG..." else a for a in _suggested(refused.stderr)]
    new_tables = tmp_path / "half.tables.json"
    args[args.index("-o") + 1] = str(new_tables)
    assert cli(*args, "--no-report", "-q").exit_code == 0
    assert cli("analyze", half, "--tables", new_tables, "--no-report", "--allow-partial").exit_code in (0, 1)


def test_tables_of_an_older_schema_name_the_command_that_rewrites_them(cli, trained, tmp_path):
    tables, _ = trained
    old = json.loads(tables.read_text())
    old["schema_version"] = 2
    stale = tmp_path / "stale.tables.json"
    stale.write_text(json.dumps(old))
    refused = cli("analyze", need_testdata(FLIGHT), "--tables", stale, "--no-report")
    assert refused.exit_code == 2 and "schema version 2" in refused.stderr
    args = _suggested(refused.stderr)
    assert args == ["train", str(need_testdata(FLIGHT)), "--calibrate", "-o", str(stale)]  # its own logs
    assert cli(*args, "--no-report", "-q").exit_code == 0
    assert json.loads(stale.read_text())["schema_version"] != 2


def test_the_warning_that_asks_for_calibration_names_a_command_that_runs(cli, tmp_path):
    flight = need_testdata(FLIGHT)
    profile = tmp_path / "px4.toml"
    profile.write_text(load_profile_for(flight, None).text)
    for chosen in ((), ("--profile", str(profile))):
        out = tmp_path / "summary.json"
        cli("analyze", flight, *chosen, "--no-report", "--json", out, "--allow-partial")
        warnings = json.loads(out.read_text())["logs"][0]["warnings"]
        asking = [w for w in warnings if "--calibrate -o tables.json`" in w]
        assert asking, warnings
        args = _suggested(asking[0])
        assert args[:2] == ["train", "HEALTHY_LOG..."] and ("--profile" in args) == bool(chosen)
        tables = tmp_path / "tables.json"
        args = [str(flight) if a == "HEALTHY_LOG..." else (str(tables) if a == "tables.json" else a) for a in args]
        assert cli(*args, "--no-report", "-q").exit_code == 0
        analysed = cli("analyze", flight, *chosen, "--tables", tables, "--no-report", "--allow-partial")
        assert analysed.exit_code in (0, 1), analysed.stderr
