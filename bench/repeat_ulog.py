"""A long PX4 ULog made of one real ULog's data section repeated back to back: the memory and time
of a long real-shaped log without flying one.

    python bench/repeat_ulog.py ../shared/testdata/px4-ulog/sample_px4_events.ulg 116 events_1h.ulg

The header, definitions, subscriptions and parameter changes are written once; the data section's
data messages, logged text, dropouts and sync markers as often as asked, copy k with every data
message's and logged message's timestamp shifted by k x (the section's span + 20 ms). A timestamp of 0 (PX4's
"never set") stays 0. The vehicle jumps back to its start state at every seam, so the long log's
verdict is not a flight's (each seam is a sensor gap), only its memory and time are: each copy has
the work of the original. sample_px4_events.ulg (31.4 s, 250 Hz IMU) 116 times is one hour (170 MB,
911,915 grid steps), 464 times four hours (681 MB).
"""

from __future__ import annotations

import struct
import sys

_HEADER = 16
_GAP_US = 20_000
_REPEATED = "DLCOS"  # repeated: data, logged text, dropouts, sync; subscriptions ('A') and parameter changes ('P') once
_STAMP_AT = {"D": 5, "L": 4, "C": 6}  # where the uint64 timestamp lies in each (3-byte header included)


def messages(data: bytes) -> list[tuple[str, bytes]]:
    """(type, message bytes) of every whole message after the file header."""
    out, pos = [], _HEADER
    while pos + 3 <= len(data):
        size, kind = struct.unpack_from("<HB", data, pos)
        if pos + 3 + size > len(data):
            break
        out.append((chr(kind), data[pos : pos + 3 + size]))
        pos += 3 + size
    return out


def shifted(kind: str, message: bytes, by_us: int) -> bytes:
    at = _STAMP_AT.get(kind)
    if at is None:
        return message
    (stamp,) = struct.unpack_from("<Q", message, at)
    return message[:at] + struct.pack("<Q", stamp + by_us if stamp else 0) + message[at + 8 :]


def repeat(source: str, copies: int, target: str) -> float:
    """Write ``copies`` of ``source``'s data section into ``target``; returns one copy's span (s)."""
    with open(source, "rb") as fh:
        data = fh.read()
    found = messages(data)
    first = next(i for i, (kind, _) in enumerate(found) if kind == "A")
    definitions, body = found[:first], found[first:]
    stamps = [struct.unpack_from("<Q", m, 5)[0] for kind, m in body if kind == "D"]
    set_stamps = [t for t in stamps if t > 0]
    period = max(stamps) - min(set_stamps) + _GAP_US
    with open(target, "wb") as fh:
        fh.write(data[:_HEADER])
        for _, message in definitions:
            fh.write(message)
        for _, message in body:
            fh.write(message)
        for k in range(1, copies):
            for kind, message in body:
                if kind in _REPEATED:
                    fh.write(shifted(kind, message, k * period))
    return period / 1e6


if __name__ == "__main__":
    if len(sys.argv) != 4:
        raise SystemExit(__doc__)
    span = repeat(sys.argv[1], int(sys.argv[2]), sys.argv[3])
    print(f"{sys.argv[3]}: {int(sys.argv[2])} copies of {span:.3f} s")
