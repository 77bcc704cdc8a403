"""The --json summary written piece by piece (`logscan.artifacts.stage_json`): the same bytes as
`json_text`, without the whole text (and the pieces it is joined from) in memory at once."""

from __future__ import annotations

import io
import math
import tracemalloc

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from logscan import artifacts

scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**40), 2**40),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
)
documents = st.recursive(
    scalars,
    lambda inner: st.one_of(st.lists(inner, max_size=5), st.dictionaries(st.text(max_size=8), inner, max_size=5)),
    max_leaves=40,
)


def _many_alarms(n: int) -> dict:
    alarm = {
        "detector": "nis",
        "statistic": "nis.gyro",
        "start_s": np.float64(1.25),
        "end_s": 4.5,
        "peak": np.float32(3.5),
        "threshold": math.nan,
        "samples": np.int64(7),
        "why": "gyroscope disagrees with the model's prediction beyond its noise (innovation test) °σ",
    }
    return {"schema_version": 1, "logs": [{"alarms": [dict(alarm, index=k) for k in range(n)]}]}


def _staged_bytes(tmp_path, document) -> bytes:
    target = tmp_path / "summary.json"
    artifacts.commit([artifacts.stage_json(target, document)])
    return target.read_bytes()


@settings(max_examples=150, deadline=None)
@given(document=documents)
def test_streamed_json_is_json_text_byte_for_byte(tmp_path_factory, document):
    tmp_path = tmp_path_factory.mktemp("json")
    assert _staged_bytes(tmp_path, document) == artifacts.json_text(document).encode("utf-8")
    stream = io.StringIO()
    artifacts.write_json_into(stream, document)
    assert stream.getvalue() == artifacts.json_text(document)


def test_numpy_values_and_nan_follow_the_json_policy_when_streamed(tmp_path):
    written = _staged_bytes(tmp_path, _many_alarms(3)).decode("utf-8")
    assert written == artifacts.json_text(_many_alarms(3))
    assert '"threshold": null' in written and '"samples": 7' in written and '"peak": 3.5' in written


def test_a_device_target_waits_with_the_same_bytes(tmp_path, monkeypatch):
    monkeypatch.setattr(artifacts, "check_target", lambda path: True)
    staged = artifacts.stage_json(tmp_path / "fifo", _many_alarms(2))
    assert staged.tmp is None
    assert staged.data == artifacts.json_text(_many_alarms(2)).encode("utf-8")


def test_the_binary_file_stays_open_for_its_owner(tmp_path):
    with open(tmp_path / "out.json", "wb") as fh:
        artifacts.write_json_into(fh, {"a": [1, 2]})
        fh.write(b"owner's tail")
    assert (tmp_path / "out.json").read_bytes() == b'{\n  "a": [\n    1,\n    2\n  ]\n}\nowner\'s tail'


def _peak_bytes(write) -> int:
    tracemalloc.start()
    try:
        write()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_streaming_holds_a_fraction_of_what_the_joined_text_holds(tmp_path):
    document = _many_alarms(4000)  # about 1.5 MB of JSON
    joined = _peak_bytes(lambda: (tmp_path / "joined.json").write_bytes(artifacts.json_text(document).encode()))
    streamed = _peak_bytes(lambda: artifacts.commit([artifacts.stage_json(tmp_path / "streamed.json", document)]))
    assert (tmp_path / "joined.json").read_bytes() == (tmp_path / "streamed.json").read_bytes()
    # the joined text holds every piece (a str object each) and the text twice; streamed: the copy
    # under the JSON policy and the writer's buffer
    assert streamed < joined / 3, (streamed, joined)
