"""The CDR layout kernels: a definition without strings is read at fixed offsets (`_cdr_fixed`), and
gives what the program walk (`_cdr_run`) and the ``mcap_ros2`` decoder give, verdicts included."""

from __future__ import annotations

import numpy as np
import pytest

from logscan.readers.mcap.cdr import _cdr_fixed, _cdr_run, cdr_fast, cdr_layout
from logscan.readers.mcap.scan_records import SchemaRec

# every primitive size and alignment, a byte array (a skip), nested fixed arrays, no strings
FIXED_NO_STRINGS = """int8 a
uint16 b
int32 c
uint64 d
float32 e
bool f
float64[3] g
uint8[3] h
int16 i
geometry_msgs/Point[2] pts
int64 z
================================================================================
MSG: geometry_msgs/Point
float64 x
float64 y
float64 z
"""


def _layout(text: str):
    layout = cdr_layout(SchemaRec(1, "test_msgs/msg/Fixed", "ros2msg", text.encode()))
    assert layout is not None
    return layout


def _messages(count: int) -> list[dict]:
    rng = np.random.default_rng(11)
    return [
        {
            "a": int(rng.integers(-128, 128)),
            "b": int(rng.integers(0, 65536)),
            "c": int(rng.integers(-(2**31), 2**31)),
            "d": int(rng.integers(0, 2**63)),
            "e": float(np.float32(rng.normal())),
            "f": bool(k % 2),
            "g": rng.normal(size=3).tolist(),
            "h": bytes([k % 256, 1, 2]),
            "i": int(rng.integers(-(2**15), 2**15)),
            "pts": [{"x": float(k), "y": 1.5, "z": -2.0}, {"x": 3.0, "y": float(-k), "z": 4.0}],
            "z": -k * 10**12,
        }
        for k in range(count)
    ]


def _encoded(messages: list[dict]) -> list[bytes]:
    from mcap_ros2._dynamic import serialize_dynamic

    encode = serialize_dynamic("test_msgs/msg/Fixed", FIXED_NO_STRINGS)["test_msgs/msg/Fixed"]
    return [encode(message) for message in messages]


def test_a_definition_without_strings_is_read_at_fixed_offsets_as_the_decoder_reads_it():
    from mcap.records import Schema
    from mcap_ros2.decoder import DecoderFactory

    layout = _layout(FIXED_NO_STRINGS)
    assert layout.offsets is not None
    # a 4-byte int after a 2-byte one starts at the next multiple of 4; the byte array is skipped
    assert layout.offsets[:3].tolist() == [0, 2, 4] and layout.skipped == ["h"]
    datas = _encoded(_messages(30))
    flat = cdr_fast(layout, datas)
    assert flat is not None
    decode = DecoderFactory().decoder_for(
        "cdr", Schema(id=1, name="test_msgs/msg/Fixed", encoding="ros2msg", data=FIXED_NO_STRINGS.encode())
    )
    decoded = [decode(data) for data in datas]
    assert flat.fields == layout.paths
    np.testing.assert_array_equal(flat.columns["d"][1], [float(m.d) for m in decoded])
    np.testing.assert_array_equal(flat.columns["e"][1], [m.e for m in decoded])
    np.testing.assert_array_equal(flat.columns["i"][1], [m.i for m in decoded])
    np.testing.assert_array_equal(flat.columns["pts[1].y"][1], [m.pts[1].y for m in decoded])
    np.testing.assert_array_equal(flat.columns["z"][1], [float(m.z) for m in decoded])


@pytest.mark.parametrize("text", [FIXED_NO_STRINGS, "float64 x\nfloat64 y\n", "uint8 a\nfloat64 b\nuint8[5] c\n"])
def test_fixed_offsets_give_the_program_walks_columns_and_verdicts(text):
    """Every message length from empty to whole, a foreign byte order, and trailing bytes: the
    fixed-offset kernel and the program walk agree on each (fits or not, and the values)."""
    layout = _layout(text)
    assert layout.offsets is not None
    ncol = len(layout.paths)
    per_column = layout.columns >= 0
    rng = np.random.default_rng(3)
    whole = b"\x00\x01\x00\x00" + rng.integers(0, 256, size=4 + layout.need, dtype=np.uint8).tobytes()
    cases = [whole[:length] for length in range(len(whole) + 1)] + [b"\x01\x00" + whole[2:]]
    verdicts = []
    for data in cases:
        buf = np.frombuffer(data, dtype=np.uint8)
        starts, ends = np.array([0], dtype=np.int64), np.array([len(data)], dtype=np.int64)
        walked, fixed = np.full((ncol, 1), -1.0), np.full((ncol, 1), -1.0)
        args = (layout.kinds, layout.sizes, layout.codes, layout.columns)
        fits = _cdr_run(buf, starts, ends, *args, walked, 0)
        sizes, codes = layout.sizes[per_column], layout.codes[per_column]
        assert _cdr_fixed(buf, starts, ends, layout.need, layout.offsets, sizes, codes, fixed, 0) == fits
        if fits:
            np.testing.assert_array_equal(fixed, walked)
        verdicts.append(fits)
    # too short up to the header plus `need` bytes, then fits (trailing bytes allowed); not LE: refused
    assert verdicts == [False] * (4 + layout.need) + [True] * 5 + [False]


def test_a_definition_with_strings_steps_through_the_program():
    layout = _layout("float64 x\nstring name\nfloat64 y\n")
    assert layout.offsets is None and layout.need == -1
    data = b"\x00\x01\x00\x00" + np.float64(1.5).tobytes() + b"\x03\x00\x00\x00ab\x00" + b"\x00"
    flat = cdr_fast(layout, [data + np.float64(-2.0).tobytes()])
    assert flat is not None and flat.columns["y"][1].tolist() == [-2.0]
