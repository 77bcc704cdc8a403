"""The clean ULog read parses the definitions without pyulog's loop (logscan.readers.ulog_definitions)
and converts the columns with one kernel per topic (logscan.readers.ulog_columns): the same log as
the careful read, pyulog's, for every message type and field type; what it cannot match goes the
careful way."""

from __future__ import annotations

import dataclasses
import struct
from pathlib import Path

import numpy as np
import pytest

import logscan.readers.ulog_reader as ulog_reader
from logscan.log import Channel
from logscan.readers.ulog_columns import ColumnLayout
from logscan.readers.ulog_framed import parse_clean
from logscan.readers.ulog_reader import read_ulog

_RECORD_A = struct.Struct("<QbBhHiIqQfd?4s" + "ffB" * 2)  # topic_a without its trailing padding
_FORMATS = [
    b"inner:float[2] v;uint8_t flag;",
    b"topic_a:uint64_t timestamp;int8_t a;uint8_t b;int16_t c;uint16_t d;int32_t e;uint32_t f;int64_t g;"
    b"uint64_t h;float i;double j;bool k;char[4] label;inner[2] nested;uint8_t[3] _padding0;",
    b"topic_b:uint64_t timestamp;float x",  # no ';' after the last field: pyulog's steps, not the regex
]


def _message(kind: str, body: bytes) -> bytes:
    return struct.pack("<HB", len(body), ord(kind)) + body


def _typed(kind: str, key: str | bytes, value: bytes, prefix: bytes = b"") -> bytes:
    """An info, parameter or default body: [prefix] key length, "type key", value bytes."""
    text = kind.encode() + b" " + (key if isinstance(key, bytes) else key.encode())
    return prefix + bytes([len(text)]) + text + value


def _subscribe(multi_id: int, msg_id: int, name: str) -> bytes:
    return _message("A", bytes([multi_id]) + struct.pack("<H", msg_id) + name.encode())


def _data(msg_id: int, record: bytes) -> bytes:
    return _message("D", struct.pack("<H", msg_id) + record)


def _definitions(parameters: list[bytes]) -> bytes:
    flags = b"\x01" + bytes(39)  # compat flag: the log has default parameters
    out = b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 1_000) + _message("B", flags)
    out += b"".join(_message("F", text) for text in _FORMATS)
    out += _message("I", _typed("char[3]", "sys_name", b"PX4"))
    out += _message("I", _typed("int32_t", "ver_sw_release", struct.pack("<i", 0x010C03FF)))
    out += _message("I", _typed("uint64_t", "board_id", struct.pack("<Q", 2**63 + 5)))
    out += _message("M", _typed("char[5]", "perf", b"hello", b"\x00"))
    out += _message("M", _typed("char[5]", "perf", b" more", b"\x01"))
    out += _message("M", _typed("char[3]", "perf", b"new", b"\x00"))
    out += b"".join(_message("P", body) for body in parameters)
    return out + _message("Q", _typed("float", "EKF_X", struct.pack("<f", 1.0), b"\x03"))


def _log_bytes(parameters: list[bytes] | None = None) -> bytes:
    """A ULog with every message type of the specification and every field type pyulog reads."""
    parameters = parameters or [
        _typed("int32_t", "SYS_A", struct.pack("<i", -5)),
        _typed("float", "EKF_X", struct.pack("<f", 0.1)),
    ]
    out = _definitions(parameters)
    out += _subscribe(0, 0, "topic_a") + _subscribe(0, 1, "topic_b") + _subscribe(1, 2, "topic_b")
    for i in range(5):
        t = 2_000 + 1_000 * i
        record = _RECORD_A.pack(
            t, -i, 200 + i, -300, 60_000, -(2**31), 2**32 - 1, -(2**62), 2**64 - 1 - i, 0.1 * i, 1e300, i % 2,
            b"ab\x00\x00", 1.5, -2.5, 1, float("nan"), 3.0, 0,
        )  # fmt: skip
        out += _data(0, record) + _data(1, struct.pack("<Qf", t + 1, i)) + _data(2, struct.pack("<Qf", t + 2, -i))
        if i == 1:
            out += _message("L", b"6" + struct.pack("<Q", t) + b"logged text")
            out += _message("C", b"4" + struct.pack("<HQ", 7, t) + b"tagged text")
            out += _message("O", struct.pack("<H", 20)) + _message(
                "S", bytes([0x2F, 0x73, 0x13, 0x20, 0x25, 0x0C, 0xBB, 0x12])
            )
        if i == 2:
            out += _message("P", _typed("float", "EKF_X", struct.pack("<f", 0.7)))
            out += _message("I", _typed("char[2]", "late", b"ok"))
            out += _message("Q", _typed("int32_t", "SYS_A", struct.pack("<i", 3), b"\x01"))
    return out


def _careful(path: Path, monkeypatch, wanted=None):
    with monkeypatch.context() as patch:
        patch.setattr(ulog_reader, "parse_clean", lambda *args: None)
        return read_ulog(path, wanted)


def _assert_same(a, b) -> None:
    assert list(a.channels) == list(b.channels)
    for name, channel in a.channels.items():
        other = b.channels[name]
        assert channel.t.dtype == other.t.dtype and channel.values.dtype == other.values.dtype
        assert channel.t.tobytes() == other.t.tobytes(), name
        assert channel.values.tobytes() == other.values.tobytes(), name  # NaN payloads too
    assert dataclasses.asdict(a.source) == dataclasses.asdict(b.source)


@pytest.mark.parametrize("wanted", [None, {"topic_b_1"}, {"/topic_a_0/e", "/topic_a_0/nested[1].v[0]"}])
def test_every_message_and_field_type_reads_as_the_careful_read(tmp_path, monkeypatch, wanted):
    path = tmp_path / "every_type.ulg"
    path.write_bytes(_log_bytes())
    assert parse_clean(str(path), ulog_reader.message_filter(wanted)) is not None
    log = read_ulog(path, wanted)
    _assert_same(log, _careful(path, monkeypatch, wanted))
    if wanted is None:
        assert log.channels["/topic_a_0/h"].values[0] == float(2**64 - 1)
        assert log.source.metadata["ulog.parameters"] == {"SYS_A": "-5", "EKF_X": repr(float(np.float32(0.1)))}
        assert "perf" in log.source.metadata["ulog.log"]["info_multiple_keys"]
        assert log.source.metadata["ulog.parameters_default"] == {"EKF_X": "1.0", "SYS_A": "3"}


@pytest.mark.parametrize(
    "parameter",
    [
        _typed("float", "CAF\u00c9_".encode() + b"\xff", struct.pack("<f", 2.0)),  # UTF-8 and an invalid byte
        _typed("double", "GAIN", struct.pack("<d", 0.25)),
        _typed("char[3]", "NAME", b"abc"),
    ],
    ids=["non-ascii-key", "double", "text"],
)
def test_parameters_outside_the_bulk_read_are_read_one_by_one(tmp_path, monkeypatch, parameter):
    path = tmp_path / "parameters.ulg"
    common = _typed("int32_t", "SYS_A", struct.pack("<i", 1))
    path.write_bytes(_log_bytes([common, parameter, common]))
    assert parse_clean(str(path), None) is not None
    _assert_same(read_ulog(path, None), _careful(path, monkeypatch))


def test_a_parameter_value_of_the_wrong_size_is_read_the_careful_way(tmp_path):
    path = tmp_path / "short_value.ulg"
    path.write_bytes(_log_bytes([_typed("float", "EKF_X", b"\x00\x00")]))
    assert parse_clean(str(path), None) is None
    assert read_ulog(path, None).source.partial


def _nested(depth: int) -> list[bytes]:
    """Formats n0 .. n{depth}: each holds the next one, the last a float; topic_a holds n0."""
    chain = [f"n{i}:n{i + 1} inner;".encode() for i in range(depth)] + [f"n{depth}:float x;".encode()]
    return [*chain, b"topic_a:uint64_t timestamp;n0 deep;"]


@pytest.mark.parametrize(
    "formats",
    [
        [b"topic_a:uint64_t timestamp;topic_a again;"],
        _nested(70),
        [b"topic_a:uint64_t timestamp;undefined_t x;"],
        [b"topic_a:uint64_t timestamp;float[70000] x;"],  # pyulog refuses an array over 65535
    ],
    ids=["contains-itself", "nested-70-deep", "undefined-type", "array-too-long"],
)
def test_formats_the_careful_read_refuses_are_not_read_framed(tmp_path, formats):
    out = b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0) + _message("B", bytes(40))
    out += b"".join(_message("F", text) for text in formats)
    out += _subscribe(0, 0, "topic_a") + _data(0, struct.pack("<Q", 1) + bytes(4))
    path = tmp_path / "formats.ulg"
    path.write_bytes(out)
    assert parse_clean(str(path), None) is None
    assert read_ulog(path, None).source.partial


def test_a_format_nested_within_the_limit_is_read_framed(tmp_path, monkeypatch):
    out = b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0) + _message("B", bytes(40))
    out += b"".join(_message("F", text) for text in _nested(60))
    out += _subscribe(0, 0, "topic_a") + _data(0, struct.pack("<Qf", 1, 2.5)) + _data(0, struct.pack("<Qf", 2, 3.5))
    path = tmp_path / "nested.ulg"
    path.write_bytes(out)
    assert parse_clean(str(path), None) is not None
    log = read_ulog(path, None)
    assert list(log.channels["/topic_a_0/deep" + ".inner" * 60 + ".x"].values) == [2.5, 3.5]
    _assert_same(log, _careful(path, monkeypatch))


def test_column_rows_are_numpy_casts_of_every_field_type():
    kinds = [
        "int8_t",
        "uint8_t",
        "int16_t",
        "uint16_t",
        "int32_t",
        "uint32_t",
        "int64_t",
        "uint64_t",
        "float",
        "double",
    ]
    dtypes = ["i1", "u1", "<i2", "<u2", "<i4", "<u4", "<i8", "<u8", "<f4", "<f8"]
    record = np.dtype({"names": kinds, "formats": dtypes})
    rng = np.random.default_rng(3)
    records = np.frombuffer(rng.integers(0, 256, record.itemsize * 50, dtype=np.uint8).tobytes(), dtype=record).copy()
    records["float"][:2] = np.array([0x7F800001, 0xFFC00001], dtype="<u4").view("<f4")  # signalling and quiet NaN
    records["uint64_t"][0] = 2**64 - 1
    layout = ColumnLayout(kinds, kinds, [record[k].itemsize for k in kinds])
    rows = layout.rows(records.view(np.uint8).reshape(-1), kinds[::-1])
    with np.errstate(invalid="ignore"):
        expected = np.array([records[k].astype(np.float64) for k in kinds[::-1]])
    assert rows.shape == (10, 50) and rows.tobytes() == expected.tobytes()


def test_channels_sharing_time_are_channels_of_their_rows():
    t = np.arange(4, dtype=np.int64)
    rows = np.arange(8, dtype=np.float64).reshape(2, 4)
    made = Channel.sharing_time(["/a/x", "/a/y"], t, rows)
    assert [c.name for c in made] == ["/a/x", "/a/y"] and all(c.t is t and c.unit is None for c in made)
    assert [c.values.tolist() for c in made] == rows.tolist() and len(made[1]) == 4
    converted = Channel.sharing_time(["/a/x"], t.astype(np.int32), rows[:1])  # not the stored types: converted
    assert converted[0].t.dtype == np.int64
    with pytest.raises(ValueError, match="equal length"):
        Channel.sharing_time(["/a/x", "/a/y"], t[:3], rows)
