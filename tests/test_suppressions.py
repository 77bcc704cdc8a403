"""Suppressions (logscan/verdict/suppressions.py, `analyze --suppressions`): known alarms leave the verdict and
exit code with their reason listed everywhere; an entry without a reason, or expired, is exit 2."""

from __future__ import annotations

import json
from datetime import date

import pytest

from logscan.errors import InputError
from logscan.verdict.suppressions import read_suppressions

ENTRY = """[[suppress]]
detector = "nis"
check = "{check}"
log = "quad_imu_*.mcap"
start = 25.0
end = 60.0
reason = "the position group follows the accelerometer bias (OPS-1)"
expires = 2099-01-01
"""


def test_every_alarm_of_the_log_suppressed_turns_the_verdict(cli, sample, tmp_path):
    rules = tmp_path / "s.toml"
    nis = "".join(ENTRY.format(check=c) for c in ("nis.accel", "nis.all", "nis.position", "nis.attitude"))
    cusum = ENTRY.replace('detector = "nis"', 'detector = "cusum"').replace('check = "{check}"\n', "")
    encoded = ENTRY.replace('detector = "nis"', 'detector = "encoded_ekf"').format(check="e_x")
    rules.write_text(nis + cusum + encoded)  # the cusum entry names no check: every one of its statistics
    out, junit, md = tmp_path / "s.json", tmp_path / "s.xml", tmp_path / "s.md"
    result = cli("analyze", sample("quad_imu_bias.mcap"), "--no-report", "--suppressions", rules,
                 "--json", out, "--junit", junit, "--markdown", md)  # fmt: skip
    assert result.exit_code == 0, result.stdout
    log = json.loads(out.read_text())["logs"][0]
    assert log["n_alarms"] == 0 and len(log["suppressed"]) == 14 and log["verdict"] == "no alarms; 14 suppressed"
    assert all(s["reason"].startswith("the position group") for s in log["suppressed"])
    assert "suppressed: nis nis.position" in result.stdout and "suppressed: cusum cusum.position.px" in result.stdout
    assert junit.read_text().count("<skipped message=") == 14 and "14 alarm(s) suppressed" in md.read_text()


def test_a_rule_suppresses_only_what_it_names(cli, sample, tmp_path):
    rules = tmp_path / "s.toml"
    rules.write_text(ENTRY.format(check="nis.position"))
    result = cli("analyze", sample("quad_imu_bias.mcap"), "--no-report", "--suppressions", rules)
    assert result.exit_code == 1 and "13 alarms in 1 incident; 1 suppressed" in result.stdout
    other = cli("analyze", sample("quad_imu_bitflip.mcap"), "--no-report", "--suppressions", rules)
    assert "suppressed" not in other.stdout  # nis.position did not alarm there


@pytest.mark.parametrize(
    "text, message",
    [
        ('[[suppress]]\ndetector = "nis"\n', "has no reason"),
        ('[[suppress]]\ndetector = "nis"\nreason = "x"\nexpires = 2020-01-01\n', "expired on 2020-01-01"),
        ('[[suppress]]\ndetector = "nis"\nreason = "x"\nwhen = 3\n', "unknown key"),
        ('[[suppress]]\nreason = "x"\n', "names no detector"),
    ],
)
def test_bad_entries_are_refused(tmp_path, text, message):
    path = tmp_path / "s.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=message):
        read_suppressions(str(path), today=date(2026, 11, 24))


def test_a_bad_file_stops_analyze_before_any_log(cli, sample, tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('[[suppress]]\ndetector = "nis"\n')
    result = cli("analyze", sample("quad_imu_bias.mcap"), "--no-report", "--suppressions", path)
    assert result.exit_code == 2 and "has no reason" in result.stderr


def test_an_entry_that_matched_nothing_is_a_warning_everywhere(cli, sample, tmp_path):
    rules = tmp_path / "s.toml"
    shadowed = ENTRY.format(check="nis.position").replace("(OPS-1)", "(OPS-2)")  # its alarm went to entry 1
    unused = ENTRY.format(check="nis.gps_speed").replace("OPS-1", "OPS-3")
    rules.write_text(ENTRY.format(check="nis.position") + shadowed + unused)
    out, md = tmp_path / "s.json", tmp_path / "s.md"
    result = cli("analyze", sample("quad_imu_bias.mcap"), "--no-report", "--suppressions", rules, "--json", out,
                 "--markdown", md, "--github-annotations")  # fmt: skip
    assert result.exit_code == 1  # the alarms left decide, not the unused entries
    lines = [line for line in result.stderr.splitlines() if "matched no alarm" in line]
    assert lines == [
        f"logscan: warning: {rules}: [[suppress]] entry 2 (detector nis, check nis.position, log quad_imu_*.mcap, "
        "25-60 s) matched no alarm; reason: the position group follows the accelerometer bias (OPS-2)",
        f"logscan: warning: {rules}: [[suppress]] entry 3 (detector nis, check nis.gps_speed, log quad_imu_*.mcap, "
        "25-60 s) matched no alarm; reason: the position group follows the accelerometer bias (OPS-3)",
    ]
    document = json.loads(out.read_text())
    assert [e["entry"] for e in document["suppressions"]["unused"]] == [2, 3]
    assert list(_schema().iter_errors(document)) == []  # docs/schema describes suppressions.unused
    document["suppressions"]["unused"][0]["entry"] = 0
    assert list(_schema().iter_errors(document))  # ...and can fail
    assert document["suppressions"]["file"] == str(rules)
    assert "**Warning**: 2 suppression entries matched no alarm:" in md.read_text()
    assert result.stdout.count(f"::warning file={rules},title=logscan unused suppression::") == 2


def test_every_entry_used_gives_no_warning(cli, sample, tmp_path):
    rules = tmp_path / "s.toml"
    rules.write_text(ENTRY.format(check="nis.position"))
    out = tmp_path / "s.json"
    result = cli("analyze", sample("quad_imu_bias.mcap"), "--no-report", "--suppressions", rules, "--json", out)
    assert "matched no alarm" not in result.stderr + result.stdout
    assert json.loads(out.read_text())["suppressions"]["unused"] == []


def _schema():
    import jsonschema
    from conftest import REPO

    schema = json.loads((REPO / "docs" / "schema" / "analyze-summary.schema.json").read_text(encoding="utf-8"))
    return jsonschema.Draft202012Validator(schema)
