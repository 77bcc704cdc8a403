"""CI artifacts of `logscan analyze` (logscan/report/ci_artifacts.py): the JUnit XML validates against the
schema CI servers read and says what the JSON says, the Markdown summary's tables, GitHub Actions
annotations (one per incident, at most 10 per log, escaped as GitHub's toolkit), the analysis times in
JUnit, and `--fail-on never`."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from logscan.report.ci_annotations import MAX_PER_LOG, github_annotations, summary_words
from logscan.report.ci_artifacts import junit_xml, markdown_summary
from logscan.timebase.clock import Clock

XSD = Path(__file__).parent / "data" / "junit.xsd"


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """analyze on a faulty sample, a healthy one and a missing file, every artifact written."""
    from conftest import SAMPLES

    from logscan.cli.main import main

    root = tmp_path_factory.mktemp("ci")
    logs = [SAMPLES / "quad_imu_bitflip.mcap", SAMPLES / "quad_healthy.mcap", root / "missing.mcap"]
    if not logs[0].exists():
        pytest.skip("sample logs missing")
    out = {name: root / name for name in ("r.xml", "r.md", "r.json")}
    args = ["analyze", *map(str, logs), "--no-report", "-q", "--junit", str(out["r.xml"]), "--markdown",
            str(out["r.md"]), "--json", str(out["r.json"])]  # fmt: skip
    with pytest.raises(SystemExit) as exit_info:
        main(args)
    return exit_info.value.code, out, json.loads(out["r.json"].read_text())


def test_the_junit_xml_validates_against_the_schema(run):
    from lxml import etree

    _, out, _ = run
    schema = etree.XMLSchema(etree.parse(str(XSD)))
    document = etree.parse(str(out["r.xml"]))
    assert schema.validate(document), schema.error_log
    broken = etree.fromstring(b'<testsuites><testsuite name="x"><testcase name="y"/></testsuite></testsuites>')
    assert not schema.validate(broken)  # the schema can fail: no counts, no classname


def test_the_junit_xml_says_what_the_json_says(run):
    from lxml import etree

    code, out, document = run
    assert code == 2  # the missing file
    suites = etree.parse(str(out["r.xml"])).getroot()
    by_name = {s.get("name"): s for s in suites.findall("testsuite")}
    for log in document["logs"]:
        suite = by_name[log["file"]]
        alarmed = {(r["detector"], a["signal"]) for r in log["detectors"] for a in r["alarms"]}
        failed = {tc.get("name") for tc in suite.findall("testcase") if tc.find("failure") is not None}
        assert failed == {f"{d}: {s}" for d, s in alarmed}
        assert int(suite.get("failures")) == len(alarmed)
        for result in log["detectors"]:
            for alarm in result["alarms"]:
                case = suite.find(f"testcase[@name='{result['detector']}: {alarm['signal']}']")
                assert f"{alarm['start']:.2f}-{alarm['end']:.2f} s" in case.find("failure").text
    (error,) = document["errors"]
    assert by_name[error["file"]].find("testcase/error") is not None
    assert int(suites.get("errors")) == 1 and int(suites.get("failures")) == sum(
        int(s.get("failures")) for s in suites.findall("testsuite")
    )


def test_the_markdown_summary_has_the_verdict_and_alarm_tables(run):
    _, out, document = run
    text = out["r.md"].read_text()
    for log in document["logs"]:
        assert f"| {log['file']} | {log['verdict']} | {log['n_incidents']} | {log['n_alarms']} |" in text
    assert "| quad_imu_bitflip.mcap | 1 | nis | nis.accel | 30.13 s | 31.27 s | peak/threshold 7.46 | - |" in text
    assert "22 samples outside the physical range" in text  # refused samples in words, not a ratio
    assert "missing.mcap | error:" in text


def test_github_annotations_one_error_per_incident_escaped(run):
    _, _, document = run
    lines = github_annotations(document)
    n_incidents = sum(log["n_incidents"] for log in document["logs"])
    assert n_incidents < sum(log["n_alarms"] for log in document["logs"])  # the test tells the two apart
    assert sum(line.startswith("::error file=") for line in lines) == n_incidents + len(document["errors"])
    (incident,) = [line for line in lines if "title=logscan incident" in line]
    (expected,) = [i for log in document["logs"] for i in log["incidents"]]
    assert f"::{expected['headline']}; {expected['n_alarms']} alarm(s) on " in incident
    hostile = {"logs": [{"file": "a,b:c%.mcap", "incidents": [_incident(1.0, "s 50%\nx")], "detectors": []}],
               "errors": []}  # fmt: skip
    (line,) = github_annotations(hostile)
    # as @actions/core: escapeProperty (%, CR, LF, ':' and ',') in properties, escapeData in the message
    assert line == "::error file=a%2Cb%3Ac%25.mcap,title=logscan incident 1 of 1::s 50%25%0Ax; 1 alarm(s) on s"


def _incident(start: float, headline: str = "h") -> dict:
    return {"start": start, "end": start + 0.5, "headline": headline, "checks": ["d:s"], "n_alarms": 1}


def test_github_annotations_at_most_ten_per_log_then_one_notice():
    many = {"file": "runs/a.mcap", "report": "out/a.report.html", "detectors": [],
            "incidents": [_incident(float(i)) for i in range(13)],
            "unchecked": [f"u{i}" for i in range(11)]}  # fmt: skip
    few = {"file": "runs/b.mcap", "detectors": [], "incidents": [_incident(1.0)]}
    lines = github_annotations({"logs": [many, few], "errors": []}, summary="summary.md")
    errors = [line for line in lines if line.startswith("::error file=runs/a.mcap")]
    warnings = [line for line in lines if line.startswith("::warning file=runs/a.mcap")]
    assert len(errors) == MAX_PER_LOG == 10 and len(warnings) == 10
    notices = [line for line in lines if line.startswith("::notice")]
    assert notices == [
        "::notice file=runs/a.mcap,title=logscan::3 more incidents in a.mcap: see out/a.report.html",
        "::notice file=runs/a.mcap,title=logscan::1 more warning in a.mcap: see out/a.report.html",
    ]
    assert [line for line in lines if "runs/b.mcap" in line] == [
        "::error file=runs/b.mcap,title=logscan incident 1 of 1::h; 1 alarm(s) on s"
    ]
    del many["report"]
    assert "3 more incidents in a.mcap: see summary.md" in "\n".join(github_annotations({"logs": [many]}, "summary.md"))


def test_github_annotations_say_new_incidents_with_a_baseline():
    alarm = {"detector": "d", "signal": "s", "start": 1.0, "end": 1.5, "baseline": "new"}
    log = {"file": "a.mcap", "incidents": [_incident(1.0)], "detectors": [{"detector": "d", "alarms": [alarm]}]}
    (line,) = github_annotations({"logs": [log]})
    assert line.endswith("1 alarm(s) on s [1 new]")
    alarm["baseline"] = "unchanged"
    assert github_annotations({"logs": [log]})[0].endswith(" [unchanged]")


def test_the_markdown_links_are_relative_to_its_folder_with_an_incident_column(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "ci" / "summary").mkdir(parents=True)
    alarm = {"detector": "d", "signal": "s", "start": 1.2, "end": 1.4, "peak_ratio": 2.0}
    log = {"file": "a.mcap", "verdict": "1 alarm", "n_alarms": 1, "n_incidents": 2,
           "report": "out/my run.report.html", "incidents": [_incident(5.0), _incident(1.0)],
           "detectors": [{"detector": "d", "alarms": [alarm]}]}  # fmt: skip
    text = markdown_summary({"logs": [log], "errors": []}, "ci/summary/s.md")
    assert "[my run.report.html](../../out/my%20run.report.html)" in text  # from ci/summary/, not from the cwd
    assert "| log | verdict | incidents | alarms |" in text and "| a.mcap | 1 alarm | 2 | 1 |" in text
    assert "| a.mcap | 2 | d | s | 1.20 s | 1.40 s | peak/threshold 2 | - |" in text  # the second incident holds it
    assert "](out/my%20run.report.html)" in markdown_summary({"logs": [log], "errors": []}, "s.md")
    assert "](out/my%20run.report.html)" in markdown_summary({"logs": [log], "errors": []}, "/dev/stdout")


def test_the_junit_time_is_each_logs_analysis_time(run):
    from lxml import etree

    _, out, document = run
    suites = etree.parse(str(out["r.xml"])).getroot()
    analysed = [s for s in suites.findall("testsuite") if s.get("name") in {log["file"] for log in document["logs"]}]
    assert len(analysed) == 2
    for suite in analysed:
        seconds = float(suite.get("time"))
        assert 0.001 < seconds < 600  # measured, not a placeholder (a short log: 0.05 s on a fast machine)
        cases = [float(c.get("time")) for c in suite.findall("testcase")]
        assert sum(cases) == pytest.approx(seconds, abs=0.001 * len(cases))
    assert float(suites.get("time")) == pytest.approx(sum(float(s.get("time")) for s in analysed), abs=0.002)
    xml = junit_xml(document, [1.5, 2.25])
    assert 'time="1.500"' in xml and 'time="2.250"' in xml


def test_fail_on_never_exits_zero_with_alarms(cli, sample):
    result = cli("analyze", sample("quad_imu_bias.mcap"), "--no-report", "--fail-on", "never", "--github-annotations")
    assert result.exit_code == 0
    assert "::error file=" in result.stdout


def test_an_artifact_named_like_a_log_is_refused(cli, sample, tmp_path):
    result = cli("analyze", sample("quad_healthy.mcap"), "--no-report", "--junit", tmp_path / "x.mcap")
    assert result.exit_code == 2


def test_the_notice_names_the_job_summary_when_the_markdown_goes_there(monkeypatch):
    monkeypatch.setenv("GITHUB_STEP_SUMMARY", "/runner/_temp/step_summary_1")
    assert summary_words("/runner/_temp/step_summary_1", "s.json") == "the job summary"
    assert summary_words("out/s.md", "s.json") == "out/s.md"
    assert summary_words(None, "s.json") == "s.json" and summary_words(None, "-") is None


def test_the_markdown_says_how_many_alarms_its_table_leaves_out():
    from logscan.report.ci_artifacts import MAX_MARKDOWN_ROWS

    alarms = [{"detector": "d", "signal": "s", "start": float(i), "end": i + 0.5} for i in range(MAX_MARKDOWN_ROWS + 3)]
    log = {"file": "a.mcap", "verdict": "alarms", "detectors": [{"detector": "d", "alarms": alarms}]}
    text = markdown_summary({"logs": [log], "errors": []})
    assert text.count("| a.mcap | - | d | s |") == MAX_MARKDOWN_ROWS  # no incident holds them: "-"
    assert "... 3 more alarm(s) in the JSON summary" in text  # also when no baseline alarm is gone


@pytest.mark.parametrize(
    ("clock", "cell", "span"),
    [
        ({"name": "PX4 boot time", "offset_s": 3.129, "utc": False, "utc_start": "2023-10-31T07:42:40.496Z"},
         "5.27 s", "5.27-5.67 s"),
        ({"name": "UTC", "offset_s": 1710773350.346, "utc": True, "utc_start": "2024-03-18T14:49:10.346Z"},
         "14:49:12.489 UTC", "2024-03-18 14:49:12.489-14:49:12.889 UTC"),
    ],
)  # fmt: skip
def test_the_markdown_and_junit_show_times_in_the_logs_own_clock(clock, cell, span):
    """The terminal, the report and the annotations show a PX4 log's alarm at 5.27 s of boot time (or
    a UTC log's at its time of day); the job summary and JUnit said 2.14 s, seconds since time zero,
    with no clock named. They now show what the terminal shows."""
    from lxml import etree

    alarm = {"detector": "health", "signal": "health.battery", "start": 2.1435, "end": 2.5435, "peak_ratio": 1.04}
    log = {"file": "f.ulg", "verdict": "1 alarm", "clock": clock, "detectors": [
        {"detector": "health", "alarms": [alarm], "series": {"health.battery": {}}}]}  # fmt: skip
    document = {"logs": [log], "errors": []}
    text = markdown_summary(document)
    end = cell.replace("12.489", "12.889").replace("5.27", "5.67")
    assert f"| f.ulg | - | health | health.battery | {cell} | {end} | peak/threshold 1.04 | - |" in text
    # the clock is named once above the times, as the terminal's "times:" line: "5.27 s" alone
    # could be seconds since the log's start
    assert f"\nTimes: {Clock.from_dict(clock).describe()}.\n" in text
    assert text.index("Times: ") < text.index("| f.ulg | - | health")
    case = etree.fromstring(junit_xml(document).encode()).find(".//testcase[@name='health: health.battery']")
    assert f"health.battery {span}, peak/threshold 1.04" in case.find("failure").text


def test_the_markdown_names_each_logs_clock_when_they_differ_and_none_without_times():
    boot = {"name": "PX4 boot time", "offset_s": 3.129, "utc": False, "utc_start": None}
    utc = {"name": "UTC", "offset_s": 1710773350.346, "utc": True, "utc_start": "2024-03-18T14:49:10.346Z"}
    alarm = {"detector": "health", "signal": "health.battery", "start": 2.0, "end": 2.5}
    logs = [
        {"file": f, "verdict": "1 alarm", "clock": c, "detectors": [{"detector": "health", "alarms": [alarm]}]}
        for f, c in (("a.ulg", boot), ("b.ulg", utc))
    ]
    text = markdown_summary({"logs": logs, "errors": []})
    assert "Times, in each log's own clock:" in text
    assert "- a.ulg: PX4 boot time (s); time zero at 3.129 s\n" in text
    assert "- b.ulg: UTC (the log's clock; time zero 2024-03-18T14:49:10.346Z)\n" in text
    quiet = {"file": "c.ulg", "verdict": "no alarms", "clock": boot, "detectors": [{"detector": "d", "alarms": []}]}
    assert "Times" not in markdown_summary({"logs": [quiet], "errors": []})
