"""Baselines (logscan/verdict/baseline.py, `analyze --baseline --fail-on new`): alarms matched with a previous
summary by log name, detector, statistic and overlapping time; only new alarms fail the run."""

from __future__ import annotations

import json

from logscan.verdict.baseline import compare, exit_code_on_new


def _schema():
    import jsonschema
    from conftest import REPO

    schema = json.loads((REPO / "docs" / "schema" / "analyze-summary.schema.json").read_text(encoding="utf-8"))
    return jsonschema.Draft202012Validator(schema)


def summary(*logs) -> dict:
    """A summary document: logs as (file, exit_code, [(detector, signal, start, end), ...])."""
    return {
        "logs": [
            {"file": f, "exit_code": code,
             "detectors": [{"detector": "d", "alarms": [
                 {"detector": d, "signal": s, "start": a, "end": b} for d, s, a, b in alarms]}]}
            for f, code, alarms in logs
        ],
        "errors": [],
    }  # fmt: skip


def test_new_gone_unchanged_and_shifted_alarms():
    previous = summary(("/old/run.mcap", 1, [("nis", "nis.accel", 10, 12), ("nis", "nis.gps", 20, 21),
                                             ("nis", "nis.all", 30, 31), ("nis", "nis.gyro", 40, 41)]))  # fmt: skip
    current = summary(
        ("/new/run.mcap", 1, [
            ("nis", "nis.accel", 10.5, 12.5),  # shifted, still overlapping: unchanged
            ("nis", "nis.all", 35, 36),  # shifted apart: new, and the old one gone
            ("nis", "nis.gyro", 40, 41),  # same detector and time, but...
            ("kgn", "nis.gyro", 40, 41),  # ...another detector: new
        ]),
        ("/new/other.mcap", 1, [("nis", "nis.accel", 10, 12)]),  # a log the baseline lacks: new
    )  # fmt: skip
    totals = compare(current, previous)
    marks = [a["baseline"] for log in current["logs"] for a in log["detectors"][0]["alarms"]]
    assert marks == ["unchanged", "new", "unchanged", "new", "new"]
    assert totals == {"new": 3, "unchanged": 2, "gone": 2}
    gone = current["logs"][0]["baseline"]["gone"]
    assert sorted(a["signal"] for a in gone) == ["nis.all", "nis.gps"]
    assert exit_code_on_new(current) == 1
    quiet = summary(("/new/run.mcap", 1, [("nis", "nis.accel", 11, 11.5)]))
    compare(quiet, previous)
    assert exit_code_on_new(quiet) == 0  # only known alarms
    bad = summary(("/new/run.mcap", 2, [("nis", "nis.accel", 11, 11.5)]))
    compare(bad, previous)
    assert exit_code_on_new(bad) == 2  # a log not fully checked still fails


def test_fail_on_new_through_the_cli(cli, sample, tmp_path):
    bias, flip = sample("quad_imu_bias.mcap"), sample("quad_imu_bitflip.mcap")
    base = tmp_path / "base.json"
    assert cli("analyze", bias, "--no-report", "-q", "--json", base).exit_code == 1
    same = cli("analyze", bias, "--no-report", "-q", "--baseline", base, "--fail-on", "new")
    assert same.exit_code == 0 and "baseline: 0 new, 14 unchanged, 0 gone" in same.stdout
    out = tmp_path / "now.json"
    more = cli("analyze", bias, flip, "--no-report", "-q", "--baseline", base, "--fail-on", "new", "--json", out)
    assert more.exit_code == 1 and "baseline: 4 new, 14 unchanged, 0 gone" in more.stdout
    document = json.loads(out.read_text())
    assert document["exit_code"] == 1 and document["baseline"]["new"] == 4
    assert document["baseline"]["not_analysed"] == []  # the baseline's one log was analysed
    assert list(_schema().iter_errors(document)) == []
    flipped = next(log for log in document["logs"] if log["file"].endswith("quad_imu_bitflip.mcap"))
    assert all(a["baseline"] == "new" for r in flipped["detectors"] for a in r["alarms"])
    from logscan.report.ci_artifacts import junit_xml, markdown_summary

    table = markdown_summary(document)
    assert table.count("| new |") == 4 and table.count("| unchanged |") == 14
    assert "nis.accel 30.13-31.27 s, peak/threshold 7.46 [new]" in junit_xml(document)


def test_baseline_mistakes_exit_two(cli, sample, tmp_path):
    bias = sample("quad_imu_bias.mcap")
    needs = cli("analyze", bias, "--no-report", "--fail-on", "new")
    assert needs.exit_code == 2 and "--baseline" in needs.stderr
    junk = tmp_path / "junk.json"
    junk.write_text("[1, 2]")
    bad = cli("analyze", bias, "--no-report", "--baseline", junk)
    assert bad.exit_code == 2 and "not a logscan analyze summary" in bad.stderr


def test_baselined_logs_missing_from_the_run_are_not_analysed():
    previous = summary(("/old/a.mcap", 1, [("nis", "nis.accel", 10, 12)]), ("/old/b.mcap", 0, []))
    previous["errors"] = [{"file": "/old/c.mcap", "error": "unreadable", "exit_code": 2}]
    current = summary(("/new/b.mcap", 0, []))
    current["logs"][0]["verdict"] = "no alarms"
    current["errors"] = [{"file": "/new/c.mcap", "error": "unreadable", "exit_code": 2}]
    totals = compare(current, previous)
    assert current["baseline"]["not_analysed"] == ["/old/a.mcap"]  # c failed to read: an error, not missing
    assert totals["gone"] == 0  # a.mcap's alarm was not looked for: not gone
    from logscan.report.ci_annotations import github_annotations
    from logscan.report.ci_artifacts import junit_xml, markdown_summary

    assert "**Not analysed**: 1 log(s) of the baseline not analysed in this run:\n\n- /old/a.mcap" in (
        markdown_summary(current)
    )
    assert '<skipped message="in the --baseline summary, not analysed in this run"' in junit_xml(current)
    assert github_annotations(current)[-1] == (
        "::warning file=/old/a.mcap,title=logscan log not analysed::in the --baseline summary, not analysed in this run"
    )
    every = summary(("/new/a.mcap", 0, []), ("/new/b.mcap", 0, []), ("/new/c.mcap", 0, []))
    compare(every, previous)
    assert every["baseline"]["not_analysed"] == []


def test_a_missing_log_is_said_in_the_terminal(cli, sample, tmp_path):
    base = tmp_path / "base.json"
    base.write_text(json.dumps(summary(("/old/quad_imu_bias.mcap", 1, []), ("/old/gone_flight.mcap", 0, []))))
    result = cli("analyze", sample("quad_imu_bias.mcap"), "--no-report", "-q", "--baseline", base)
    assert "baseline: 1 log(s) not analysed in this run: /old/gone_flight.mcap" in result.stdout
