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
