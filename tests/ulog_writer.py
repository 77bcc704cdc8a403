"""A minimal PX4 ULog writer for tests: crafted logs with known events that pyulog reads.

    write_ulog(path, topics={"sensor_combined": (t_us, {"accelerometer_m_s2": (n, 3) array, ...})},
               parameters={"EKF2_GPS_P_GATE": 5.0}, info={"sys_name": "PX4"})

Layout (the ULog file format): a 16-byte header (magic ``ULog\\x01\\x12\\x35``, version 1, uint64
start timestamp in microseconds), a flag-bits message 'B', then per topic a format 'F'
(``name:uint64_t timestamp;float field[k];...``), info 'I' and parameter 'P' messages, and the
data section: a subscription 'A' per topic and its data 'D' messages in time order. Every message
is uint16 size + uint8 type + body. Fields are float32 (a 1-D value per sample, or an (n, k)
array for an array field), or uint64 for a 1-D uint64 array (a GNSS ``time_utc_usec``).
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from pathlib import Path

import numpy as np

MAGIC = b"ULog\x01\x12\x35"


def _message(kind: bytes, body: bytes) -> bytes:
    return struct.pack("<HB", len(body), kind[0]) + body


def _format(name: str, fields: Mapping[str, np.ndarray]) -> tuple[str, list[str]]:
    """The 'F' text and the field order of a topic (timestamp first, floats after)."""
    parts = ["uint64_t timestamp"]
    for field, values in fields.items():
        values = np.asarray(values)
        if values.dtype == np.uint64:
            parts.append(f"uint64_t {field}")
        else:
            parts.append(f"float {field}" if values.ndim == 1 else f"float[{values.shape[1]}] {field}")
    return f"{name}:{';'.join(parts)};", list(fields)


def _column_bytes(values, n: int) -> np.ndarray:
    """(n, bytes) little-endian rows of one field: uint64 as is, anything else as float32."""
    values = np.asarray(values)
    typed = values.astype("<u8") if values.dtype == np.uint64 else values.astype("<f4")
    return np.ascontiguousarray(typed.reshape(n, -1)).view(np.uint8).reshape(n, -1)


def write_ulog(
    path: str | Path,
    topics: Mapping[str, tuple[np.ndarray, Mapping[str, np.ndarray]]],
    *,
    parameters: Mapping[str, float] | None = None,
    info: Mapping[str, str] | None = None,
    start_us: int = 0,
) -> Path:
    """Write a ULog file: ``topics`` maps a message name (instance 0) to (t_us, {field: values})."""
    out = bytearray(MAGIC + bytes([1]) + struct.pack("<Q", start_us))
    out += _message(b"B", bytes(40))  # flag bits: no compat/incompat flags, no appended data
    orders = {}
    for name, (_, fields) in topics.items():
        text, orders[name] = _format(name, fields)
        out += _message(b"F", text.encode())
    for key, value in {"sys_name": "PX4", **(info or {})}.items():
        encoded = value.encode()
        header = f"char[{len(encoded)}] {key}".encode()
        out += _message(b"I", bytes([len(header)]) + header + encoded)
    for key, value in (parameters or {}).items():
        header = f"float {key}".encode()
        out += _message(b"P", bytes([len(header)]) + header + struct.pack("<f", float(value)))
    # data section: subscriptions, then every topic's samples merged in time order
    samples = []
    for msg_id, (name, (t_us, fields)) in enumerate(topics.items()):
        out += _message(b"A", struct.pack("<BH", 0, msg_id) + name.encode())
        columns = [_column_bytes(fields[f], len(t_us)) for f in orders[name]]
        table = np.hstack(columns) if columns else np.zeros((len(t_us), 0), np.uint8)
        for i, t in enumerate(np.asarray(t_us, dtype=np.int64)):
            payload = struct.pack("<HQ", msg_id, int(t)) + table[i].tobytes()
            samples.append((int(t), msg_id, payload))
    for _, _, payload in sorted(samples, key=lambda s: (s[0], s[1])):
        out += _message(b"D", payload)
    path = Path(path)
    path.write_bytes(bytes(out))
    return path
