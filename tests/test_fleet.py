"""The runner over many logs: expansion, output naming, failure isolation, and --jobs N giving the
same results as --jobs 1."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from logscan.errors import InputError, UsageError
from logscan.fleet import LogFailure, expand_logs, output_paths, run_many

SAMPLES = Path(__file__).resolve().parents[1] / "sample_logs"


def test_a_directory_expands_to_its_logs_and_csv_directories_stay_one_log(tmp_path):
    (tmp_path / "b.mcap").write_bytes(b"x")
    (tmp_path / "a.ULG").write_bytes(b"x")
    (tmp_path / "notes.txt").write_text("x")
    csv_dir = tmp_path / "flight_csv"
    csv_dir.mkdir()
    (csv_dir / "flight_sensor_0.csv").write_text("timestamp,x\n1,2\n")
    (csv_dir / "flight_gps_0.csv").write_text("timestamp,lat\n1,2\n")
    assert expand_logs([str(tmp_path)]) == [str(tmp_path / n) for n in ("a.ULG", "b.mcap", "flight_csv")]
    assert expand_logs([str(csv_dir), "missing.mcap"]) == [str(csv_dir), "missing.mcap"]


def test_a_directory_of_wide_csvs_is_one_log_per_file(tmp_path):
    flights = tmp_path / "flights"
    flights.mkdir()
    for name in ("b.csv", "a.csv"):
        (flights / name).write_text("time,speed\n0,1\n1,2\n")
    (flights / "a.truth.json").write_text("{}")
    expected = [str(flights / "a.csv"), str(flights / "b.csv")]
    assert expand_logs([str(flights)]) == expected
    (tmp_path / "x.mcap").write_bytes(b"x")  # a folder of logs: its CSV sub-folders expand the same way
    assert expand_logs([str(tmp_path)]) == [str(tmp_path / "x.mcap"), *expected]
    assert expand_logs([str(tmp_path / "empty")]) == [str(tmp_path / "empty")]  # its reader says what is wrong


def test_analyze_on_a_folder_of_wide_csvs_reports_each_file(cli, tmp_path, sample):
    folder = tmp_path / "flights"
    folder.mkdir()
    for suffix in (".csv", ".truth.json", ".profile.toml"):
        source = sample("quad_healthy.csv").with_suffix(suffix)
        for name in ("one", "two"):
            (folder / f"{name}{suffix}").write_bytes(source.read_bytes())
    out = tmp_path / "summary.json"
    result = cli("analyze", folder, "--no-report", "--json", out, "--exit-zero")
    assert result.exit_code == 0, result.stderr
    logs = json.loads(out.read_text())["logs"]
    assert [Path(log["file"]).name for log in logs] == ["one.csv", "two.csv"]
    assert all(log["log"]["duration_s"] == pytest.approx(60.0) and not log["warnings"] for log in logs)


def test_outputs_are_named_after_their_logs_and_same_names_get_their_folder(tmp_path):
    assert output_paths(["x/a.mcap"], None) == ["a.report.html"]
    assert output_paths(["x/a.mcap"], "r.html") == ["r.html"]
    names = output_paths(["x/a.mcap", "y/a.mcap"], f"{tmp_path / 'out'}/")  # "/": a directory to create
    assert names == [str(tmp_path / "out" / "x_a.report.html"), str(tmp_path / "out" / "y_a.report.html")]
    (tmp_path / "file").write_text("")
    with pytest.raises(UsageError, match="is a file"):
        output_paths(["a.mcap", "b.mcap"], str(tmp_path / "file"))


def _task(path: str) -> str:
    if path == "bad":
        raise InputError("cannot read", path=path, hint="fix it")
    if path == "bug":
        raise ZeroDivisionError("boom")
    return path.upper()


@pytest.mark.parametrize("jobs", [1, 2])
def test_one_failing_log_never_stops_the_others(jobs):
    outcomes = run_many(["a", "bad", "bug", "b"], _task, jobs=jobs)
    assert outcomes[0] == "A" and outcomes[3] == "B"
    bad, bug = outcomes[1], outcomes[2]
    assert isinstance(bad, LogFailure) and bad.exit_code == 2 and bad.message == "bad: cannot read (fix it)"
    assert isinstance(bug, LogFailure) and bug.exit_code == 3 and "ZeroDivisionError: boom" in bug.message


def test_without_isolation_the_error_propagates():
    with pytest.raises(InputError):
        run_many(["bad"], _task, isolate=False)


def test_analyze_with_two_jobs_gives_the_same_json_as_one(cli, tmp_path):
    logs = [str(SAMPLES / n) for n in ("quad_healthy.mcap", "quad_imu_bias.mcap", "sbw_yaw_rate_bitflip.mcap")]
    outputs = {}
    for jobs in (1, 2):
        path = tmp_path / f"jobs{jobs}.json"
        result = cli("analyze", *logs, "--no-report", "--json", str(path), "--jobs", str(jobs), "--exit-zero")
        assert result.exit_code == 0, result.output
        outputs[jobs] = path.read_text()
    assert outputs[1] == outputs[2]
    assert [log["file"] for log in json.loads(outputs[2])["logs"]] == logs


def test_evaluate_with_two_jobs_gives_the_same_json_as_one(cli, tmp_path):
    logs = [str(SAMPLES / n) for n in ("quad_healthy.mcap", "quad_imu_bias.mcap", "quad_motor_offset.mcap")]
    outputs = {}
    for jobs in (1, 2):
        path = tmp_path / f"jobs{jobs}.json"
        result = cli("evaluate", *logs, "--json", str(path), "--jobs", str(jobs))
        assert result.exit_code == 0, result.output
        outputs[jobs] = path.read_text()
    assert outputs[1] == outputs[2]
    assert json.loads(outputs[1])["n_logs"] == 3


def test_a_bad_log_among_many_is_one_line_and_exit_2(cli, tmp_path):
    bad = tmp_path / "broken.mcap"
    bad.write_bytes(b"not an mcap at all")
    result = cli("analyze", str(SAMPLES / "quad_healthy.mcap"), str(bad), "--no-report", "--jobs", "2")
    assert result.exit_code == 2
    assert "quad_healthy.mcap: no alarms" in result.stdout
    assert result.stderr.count("logscan: error:") == 1 and "broken.mcap" in result.stderr
