"""CI artifacts of `logscan analyze` (logscan/report/ci_artifacts.py): the JUnit XML validates against the
schema CI servers read and says what the JSON says, the Markdown summary's tables, GitHub Actions
annotations (one per alarm, escaped), and `--fail-on never`."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from logscan.report.ci_artifacts import github_annotations

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
        assert f"| {log['file']} | {log['verdict']} | {log['n_alarms']} |" in text
    assert "| quad_imu_bitflip.mcap | nis | nis.accel | 30.13 | 31.27 | peak/threshold 7.46 | - |" in text
    assert "22 samples outside the physical range" in text  # refused samples in words, not a ratio
    assert "missing.mcap | error:" in text


def test_github_annotations_one_error_per_alarm_escaped(run):
    _, _, document = run
    lines = github_annotations(document)
    n_alarms = sum(log["n_alarms"] for log in document["logs"])
    assert sum(line.startswith("::error file=") for line in lines) == n_alarms + len(document["errors"])
    hostile = {"logs": [{"file": "a,b:c%.mcap", "detectors": [{"detector": "d", "alarms": [
        {"signal": "s", "start": 1.0, "end": 2.0, "peak_ratio": 3.0}]}]}], "errors": []}  # fmt: skip
    (line,) = github_annotations(hostile)
    assert line.startswith("::error file=a%2Cb%3Ac%25.mcap,title=logscan d s::s 1.00-2.00 s")


def test_fail_on_never_exits_zero_with_alarms(cli, sample):
    result = cli("analyze", sample("quad_imu_bias.mcap"), "--no-report", "--fail-on", "never", "--github-annotations")
    assert result.exit_code == 0
    assert "::error file=" in result.stdout


def test_an_artifact_named_like_a_log_is_refused(cli, sample, tmp_path):
    result = cli("analyze", sample("quad_healthy.mcap"), "--no-report", "--junit", tmp_path / "x.mcap")
    assert result.exit_code == 2
