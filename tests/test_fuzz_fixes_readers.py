"""Reader fixes for bugs the fuzzing campaign found (tests/fuzz_regressions/README.md): each test
names its bug id and checks the exit code and the message the user sees."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from logscan.readers import read_log
from logscan.readers.flatten import flatten_messages
from logscan.readers.json_decoder import json_columns

REGRESSIONS = Path(__file__).resolve().parent / "fuzz_regressions"
HUGE = "1" + "0" * 400  # beyond float range (~1.8e308)
HUGE_WHY = "integer beyond float range (read as NaN)"


# -- json-huge-integer -------------------------------------------------------------------------------


def test_a_json_integer_beyond_float_range_is_a_counted_nan_on_every_path():
    """Fast (template) path, generic path, first message or a later one: NaN, counted, never inf or
    an OverflowError; a float literal beyond range (1e400) stays what json.loads makes it (inf)."""
    one = b'{"a": 1.5, "b": 2}'
    huge = b'{"a": 2.5, "b": ' + HUGE.encode() + b"}"
    negative = b'{"a": 3.5, "b": -' + HUGE.encode() + b"}"
    written_inf = b'{"a": 4.5, "b": 1e400}'
    for messages in ([one, huge, written_inf, negative], [huge, one], [huge, huge], [huge]):
        flat, failed = json_columns(messages)
        assert failed == []
        b = flat.columns["b"][1]
        expected = [np.nan if m in (huge, negative) else json.loads(m)["b"] for m in messages]
        np.testing.assert_array_equal(b, expected)
        assert flat.skipped == {("b", HUGE_WHY): sum(m in (huge, negative) for m in messages)}
    flat = flatten_messages([json.loads(one), json.loads(huge)])  # decoded messages (other encodings)
    np.testing.assert_array_equal(flat.columns["b"][1], [2.0, np.nan])
    assert flat.skipped == {("b", HUGE_WHY): 1}


def test_json_huge_integer_reproducer_analyses_without_error(cli_process):
    """`json-huge-integer`: was OverflowError, exit 3."""
    path = REGRESSIONS / "json_huge_integer.mcap"
    result = cli_process("analyze", path, "--no-report", "--json", "-")
    assert result.exit_code == 0, result.stderr
    assert "Error" not in result.stderr and "Warning" not in result.stderr  # no traceback, no numpy warning
    entry = json.loads(result.stdout)["logs"][0]
    assert {"what": "/cmd/thrust", "why": HUGE_WHY, "count": 1} in entry["log"]["skipped"]
    assert not entry["log"]["partial"]
    assert np.isnan(read_log(path).channels["/cmd/thrust"].values).sum() == 1


# -- ulog-missing-timestamp --------------------------------------------------------------------------

UNTIMED_WHY = "its message format has no timestamp field, which the ULog spec requires: the definition is damaged"
LINEAR_PROFILE = """\
name = "untimed topic"
[vehicle]
model = "linear"
rate_hz = 100
[vehicle.params]
A = [[0.0]]
B = [[0.0]]
C = { accel = [[1.0]] }
R = { accel = [1.0] }
inputs = ["thrust"]
states = ["az"]
[inputs]
thrust = "/act_0/thrust"
stale_s = 0.5
[measurements.accel]
channels = ["/acc_0/z"]
rate_hz = 100
"""


def _ulog(topics: list[tuple[str, str]], n: int = 400) -> bytes:
    """A ULog: header, flag bits, one format and subscription per (name, fields) and ``n`` data
    messages of each at 100 Hz, interleaved; every format is a uint64 then a float."""
    import math
    import struct

    def message(kind: str, body: bytes) -> bytes:
        return struct.pack("<HB", len(body), ord(kind)) + body

    out = b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0) + message("B", bytes(40))
    out += b"".join(message("F", f"{name}:{fields}".encode()) for name, fields in topics)
    out += b"".join(message("A", struct.pack("<BH", 0, i) + name.encode()) for i, (name, _) in enumerate(topics))
    for k in range(n):
        for i in range(len(topics)):
            out += message("D", struct.pack("<HQf", i, 1_000_000 + 10_000 * k, math.sin(k / 10)))
    return out


def test_ulog_missing_timestamp_reproducer_is_a_one_line_error(cli):
    """`ulog-missing-timestamp`: was KeyError 'timestamp', exit 3; its only topic has no timestamp."""
    path = REGRESSIONS / "ulog_missing_timestamp.ulg"
    result = cli("inspect", path)
    assert result.exit_code == 2
    assert result.stderr.strip() == (
        f"logscan: error: {path}: no data to read: topic sensor_combined_0 skipped, {UNTIMED_WHY} "
        "(re-export or re-record the log)"
    )


def test_a_ulog_topic_without_timestamp_is_skipped_and_the_rest_read_as_partial(cli, tmp_path):
    """Its data come first in the file: pyulog alone stops reading there and loses the other topic."""
    path = tmp_path / "untimed.ulg"
    path.write_bytes(_ulog([("acc", "uint64_t time_stamp;float z;"), ("act", "uint64_t timestamp;float thrust;")]))
    log = read_log(path)
    assert list(log.source.topics) == ["act_0"] and log.source.topics["act_0"].message_count == 400
    assert log.source.partial and f"topic acc_0 not read: {UNTIMED_WHY}" in log.source.partial_reason
    assert log.source.warnings == [f"topic acc_0 skipped: {UNTIMED_WHY}"]
    assert [(s.what, s.why, s.count) for s in log.source.skipped] == [("topic acc_0", UNTIMED_WHY, 400)]
    result = cli("inspect", path)
    assert result.exit_code == 0 and "PARTIAL" in result.stdout and "topic acc_0 skipped" in result.stdout


def test_a_ulog_missing_the_profiles_topic_for_lack_of_timestamp_is_never_no_alarms(cli, tmp_path):
    profile = tmp_path / "linear.toml"
    profile.write_text(LINEAR_PROFILE)
    intact = tmp_path / "intact.ulg"
    intact.write_bytes(_ulog([("acc", "uint64_t timestamp;float z;"), ("act", "uint64_t timestamp;float thrust;")]))
    assert cli("analyze", intact, "--profile", profile, "--no-report").exit_code == 0
    for untimed, topic in (("acc", "acc_0"), ("act", "act_0")):
        path = tmp_path / f"no_{untimed}_timestamp.ulg"
        fields = {"acc": "uint64_t timestamp;float z;", "act": "uint64_t timestamp;float thrust;"}
        fields[untimed] = fields[untimed].replace("timestamp", "time_stamp")
        path.write_bytes(_ulog(list(fields.items())))
        result = cli("analyze", path, "--profile", profile, "--no-report", "--json", "-")
        assert result.exit_code == 2, result.stderr
        assert "no alarms" not in result.stdout
        assert f"'/{topic}/" in result.stderr  # the profile's channel that the log lacks
