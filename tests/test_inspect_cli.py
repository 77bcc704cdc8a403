"""`logscan inspect` on every shared test log, its --json facts and its terminal rendering."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from logscan.cli.render_inspect import compact_fields, render_inspect

TESTDATA = Path(__file__).resolve().parents[2] / "shared" / "testdata"
ULOGS = sorted((TESTDATA / "px4-ulog").glob("*.ulg"))
MCAPS = sorted((TESTDATA / "mcap-conformance").rglob("*.mcap"))
HAVE_MCAP_READER = importlib.util.find_spec("logscan.readers.mcap") is not None


@pytest.mark.testdata("px4-ulog")
@pytest.mark.parametrize("path", ULOGS, ids=lambda p: p.name)
def test_inspect_every_real_ulog(path, cli):
    result = cli("inspect", path)
    assert result.exit_code == 0, result.stderr
    assert "Traceback" not in result.stderr and result.stderr == ""
    out = result.stdout
    assert "format:    ulog" in out and "system:    sys_name=PX4" in out
    assert "parameter(s)" in out and "topic(s)" in out and "PARTIAL" not in out
    # every topic row has a message count and a rate
    rows = [line.split() for line in out.splitlines() if line.startswith("  ") and "ulog /" in line]
    assert len(rows) >= 20 and all(r[1].isdigit() and float(r[2]) >= 0 for r in rows)


@pytest.mark.testdata("px4-ulog")
def test_inspect_json_to_stdout_parses_and_has_the_keys(cli):
    result = cli("inspect", TESTDATA / "px4-ulog" / "sample_log_small.ulg", "--json", "-")
    assert result.exit_code == 0, result.stderr
    facts = json.loads(result.stdout)
    for key in (
        "file",
        "format",
        "start_ns",
        "end_ns",
        "duration_s",
        "time_unit",
        "partial",
        "topics",
        "channels",
        "skipped",
        "warnings",
        "metadata",
    ):
        assert key in facts
    imu = facts["topics"]["vehicle_imu_0"]
    assert imu["message_count"] >= 10 and imu["rate_hz"] > 1 and "delta_velocity[0]" in imu["fields"]
    channel = facts["channels"]["/vehicle_imu_0/delta_velocity[0]"]
    assert channel["samples"] == imu["message_count"] and channel["nonfinite"] == 0
    assert facts["metadata"]["ulog.info"]["ver_hw"] == "CUBEPILOT_CUBEORANGE"


@pytest.mark.testdata("px4-ulog")
def test_inspect_json_file_and_channels_and_topic_filter(tmp_path, cli):
    target = tmp_path / "facts.json"
    result = cli(
        "inspect",
        TESTDATA / "px4-ulog" / "sample_px4_events.ulg",
        "--channels",
        "--topic",
        "vehicle_status_0",
        "--json",
        target,
    )
    assert result.exit_code == 0 and result.stderr == ""
    facts = json.loads(target.read_text())
    assert list(facts["topics"]) == ["vehicle_status_0"]
    assert "/vehicle_status_0/nav_state" in result.output and "rate Hz" in result.output
    # epoch-based SITL log: the span is shown as UTC wall-clock time
    assert "time span: 2024-03-18T" in result.output


def test_inspect_csv_dir_and_wide_csv(tmp_path, cli):
    d = tmp_path / "flight"
    d.mkdir()
    (d / "flight_vehicle_imu_0.csv").write_text("timestamp,accel[0],accel[1]\n1000,1,2\n2000,3,4\n")
    (d / "flight_battery_status_0.csv").write_text("timestamp,voltage_v\n1000,12\n")
    result = cli("inspect", d)
    assert result.exit_code == 0
    out = result.output
    assert "vehicle_imu_0" in out and "csv / ulog2csv" in out and "fields: accel[0..1]" in out
    assert "time col:  2 files (battery_status_0, vehicle_imu_0): 'timestamp' in us" in out
    wide = tmp_path / "wide.csv"
    wide.write_text("time,speed,label\n0,1,a\n10,2,b\n20,nan,c\n")  # a written nan is a sample
    result = cli("inspect", wide)
    assert result.exit_code == 0
    out = result.output
    assert "time col:  wide.csv: 'time' in ms" in out
    assert "text column 'label' of wide.csv: not numeric" in out
    assert "1 with NaN/inf values" in out


def conformance_message_count(mcap: Path) -> int:
    records = json.loads(mcap.with_suffix(".json").read_text())["records"]
    return sum(1 for record in records if record["type"] == "Message")


@pytest.mark.testdata("mcap-conformance")
@pytest.mark.skipif(not HAVE_MCAP_READER, reason="logscan.readers.mcap not written yet")
def test_inspect_every_conformance_mcap(cli):
    failures = []
    for path in MCAPS:
        result = cli("inspect", path, "--json", "-")
        if result.exit_code != 0 or "Traceback" in result.stderr:
            failures.append(f"{path.name}: exit {result.exit_code}: {result.stderr.strip()[:200]}")
            continue
        facts = json.loads(result.output)
        counted = sum(info["message_count"] for info in facts["topics"].values())
        expected = conformance_message_count(path)
        if counted != expected or facts["partial"]:
            failures.append(f"{path.name}: {counted} messages (expected {expected}), partial={facts['partial']}")
    assert len(MCAPS) == 416
    assert not failures, f"{len(failures)} of {len(MCAPS)} failed:\n" + "\n".join(failures[:20])


# ---- rendering ---------------------------------------------------------------------------------


def facts(**overrides) -> dict:
    base = {
        "file": "f.ulg",
        "format": "ulog",
        "start_ns": 1_000_000_000,
        "end_ns": 3_500_000_000,
        "duration_s": 2.5,
        "time_unit": "us",
        "time_source": "ulog timestamp",
        "partial": False,
        "partial_reason": "",
        "topics": {},
        "channels": {},
        "skipped": [],
        "warnings": [],
        "has_truth": False,
        "has_profile": False,
        "metadata": {},
    }
    base.update(overrides)
    return base


def topic(name: str, fields: list[str], count: int = 10, rate: float = 4.0) -> dict:
    return {
        "name": name,
        "message_count": count,
        "rate_hz": rate,
        "encoding": "ulog",
        "schema": name.rsplit("_", 1)[0],
        "first_ns": 0,
        "last_ns": 1,
        "fields": fields,
    }


def test_compact_fields_joins_runs_of_array_elements():
    fields = ["a", "q[0]", "q[1]", "q[2]", "b", "v[0]", "w[3]", "w[4]", "w[6]"]
    assert compact_fields(fields) == ["a", "q[0..2]", "b", "v[0]", "w[3..4]", "w[6]"]


def test_long_field_lists_are_truncated_with_a_count_unless_full():
    many = [f"field_number_{i}" for i in range(200)]
    data = facts(topics={"big_0": topic("big_0", many)})
    short = render_inspect(data, False, width=100)
    assert "... +" in short and "more (--full lists all)" in short
    shown = short.split("fields: ", 1)[1]
    hidden = int(shown.split("... +", 1)[1].split(" ", 1)[0])
    listed = sum(1 for name in many if f"{name}," in shown)
    assert listed + hidden == 200 and max(len(line) for line in short.splitlines()) <= 100
    full = render_inspect(data, False, full=True, width=100)
    assert "field_number_199" in full and "more (--full" not in full


def test_partial_skipped_warnings_and_channel_table_are_rendered():
    data = facts(
        partial=True,
        partial_reason="truncated: the message read at byte 10 runs past the end",
        topics={"imu_0": topic("imu_0", ["x"])},
        channels={"/imu_0/x": {"samples": 10, "unit": None, "rate_hz": 4.0, "nonfinite": 2, "min": -1.5, "max": 2.0}},
        skipped=[{"what": "text column 'mode' of a.csv", "why": "not numeric", "count": 1}],
        warnings=["a.csv: 2 NaN value(s) kept"],
        metadata={
            "ulog.info": {"sys_name": "PX4", "ver_hw": "SITL"},
            "ulog.log": {"dropouts": "2", "dropout_total_ms": "40", "logged_messages": "5", "changed_parameters": "1"},
            "ulog.parameters": {"A": "1", "B": "2"},
        },
    )
    text = render_inspect(data, True)
    assert "PARTIAL:   only part of the file was read: truncated" in text
    assert "system:    sys_name=PX4, ver_hw=SITL" in text
    assert "2 parameter(s), 1 changed in flight, 5 logged message(s), 2 dropout(s) (40 ms)" in text
    assert "1 topic(s), 10 message(s)" in text
    assert "1 numeric channel(s), 1 with NaN/inf values" in text
    row = next(line for line in text.splitlines() if line.startswith("  /imu_0/x"))
    assert row.split() == ["/imu_0/x", "10", "4.000", "2", "-1.5", "..", "2"]
    assert "skipped (1 kind(s), 1 item(s)):" in text and "warnings (1):" in text


def test_empty_log_and_relative_time_span():
    text = render_inspect(facts(start_ns=None, end_ns=None, duration_s=0.0), False)
    assert "time span: (no messages)" in text and "0 topic(s), 0 message(s)" in text
    text = render_inspect(facts(), False)
    assert "time span: 1.000000 s .. 3.500000 s (2.500 s)" in text


def test_many_warnings_are_truncated_with_a_count():
    text = render_inspect(facts(warnings=[f"w{i}" for i in range(100)]), False)
    assert "  w39" in text and "  w40" not in text and "... 60 more warnings" in text
