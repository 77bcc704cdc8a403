"""The MCAP reader under damage inside chunks: decompression bounded by the bytes produced (a real,
extremely compressible chunk reads; a chunk lying about its size stops within the cap), a damaged
chunk skipped with the read marked partial, and messages on undefined or redefined channels counted
as damage."""

from __future__ import annotations

import json
import struct
import subprocess
import sys
import textwrap
import zlib
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from logscan.errors import CorruptLogError
from logscan.readers import read_log
from logscan.readers.mcap.scan import MAX_CHUNK_BYTES

ZEROS = 4 << 20  # one message of 4 MiB of zeros: zstd makes ~130 bytes of it


def _zero_chunk_log(path: Path, compression: CompressionType) -> Path:
    """A JSON IMU topic (2000 messages) and one 4 MiB all-zero message on a raw topic, in its own chunk."""
    with open(path, "wb") as fh:
        writer = Writer(fh, compression=compression, chunk_size=64 * 1024)
        writer.start()
        schema = writer.register_schema("imu", "jsonschema", b"{}")
        imu = writer.register_channel("/imu", "json", schema)
        blob = writer.register_channel("/blob", "raw", 0)
        for i in range(2000):
            t = i * 10_000_000
            writer.add_message(imu, t, json.dumps({"accel": {"x": 0.1 * i}}).encode(), t)
            if i == 1000:
                writer.add_message(blob, t, bytes(ZEROS), t)
        writer.finish()
    return path


def _library_count(path: Path) -> int:
    with open(path, "rb") as fh:
        return sum(1 for _ in make_reader(fh).iter_messages())


@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.LZ4], ids=["zstd", "lz4"])
def test_an_all_zero_chunk_reads_as_the_mcap_library_reads_it(tmp_path, compression):
    path = _zero_chunk_log(tmp_path / "zeros.mcap", compression)  # zstd: the chunk compresses >10,000x
    log = read_log(path)
    assert not log.source.partial, log.source.partial_reason
    assert sum(t.message_count for t in log.source.topics.values()) == _library_count(path) == 2001
    assert log.source.topics["/blob"].message_count == 1
    assert len(log.channels["/imu/accel.x"]) == 2000


def _record(op: int, body: bytes) -> bytes:
    return bytes([op]) + struct.pack("<Q", len(body)) + body


def _string(text: str) -> bytes:
    return struct.pack("<I", len(text)) + text.encode()


def _chunk(compression: str, payload: bytes, declared: int, crc: int = 0) -> bytes:
    body = struct.pack("<QQQI", 0, 0, declared, crc) + _string(compression) + struct.pack("<Q", len(payload)) + payload
    return _record(0x06, body)


def _mcap(*records: bytes) -> bytes:
    header = _record(0x01, _string("") + _string("damaged"))
    body = header + b"".join(records) + _record(0x0F, struct.pack("<I", 0))
    return b"\x89MCAP0\r\n" + body + _record(0x02, struct.pack("<QQI", 0, 0, 0)) + b"\x89MCAP0\r\n"


def _channel(cid: int, topic: str) -> bytes:
    return _record(0x04, struct.pack("<HH", cid, 0) + _string(topic) + _string("json") + struct.pack("<I", 0))


def _message(cid: int, t: int, value: float) -> bytes:
    return _record(0x05, struct.pack("<HIQQ", cid, 0, t, t) + json.dumps({"x": value}).encode())


def _plain_chunk(records: list[bytes]) -> bytes:
    """An uncompressed chunk with its CRC: an edit inside it passes the CRC check."""
    inner = b"".join(records)
    return _chunk("", inner, len(inner), zlib.crc32(inner))


def _good_chunk(t0: int) -> bytes:
    return _plain_chunk([_channel(1, "/a"), _channel(2, "/b")] + [_message(1 + i % 2, t0 + i, i) for i in range(20)])


def test_a_chunk_declaring_more_than_the_cap_is_skipped_unread_and_the_rest_is_kept(tmp_path):
    import lz4.frame

    lie = _chunk("lz4", lz4.frame.compress(bytes(1000)), 1 << 30)  # 1 GiB declared, 1000 bytes inside
    path = tmp_path / "lie.mcap"
    path.write_bytes(_mcap(_good_chunk(0), lie, _good_chunk(1000)))
    log = read_log(path)
    assert log.source.partial
    assert f"over logscan's limit of {MAX_CHUNK_BYTES >> 20} MiB per chunk" in log.source.partial_reason
    assert "1 damaged chunk(s) skipped" in log.source.partial_reason
    assert len(log.channels["/a/x"]) == 20  # both good chunks


def test_an_lz4_chunk_lying_about_its_size_costs_what_it_produces(tmp_path):
    """A chunk declaring 500 MiB (under the cap) that holds 2 MiB: the buffer's pages are touched
    only as they are written, so memory follows the 2 MiB produced, not the size declared."""
    import lz4.frame

    declared = 500 << 20
    path = tmp_path / "lie.mcap"
    path.write_bytes(_mcap(_good_chunk(0), _chunk("lz4", lz4.frame.compress(bytes(2 << 20)), declared)))
    script = textwrap.dedent(
        """
        import resource, sys
        from logscan.readers import read_log
        read_log(sys.argv[2])  # imports and compiled kernels first
        base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        log = read_log(sys.argv[1])
        print(log.source.partial_reason)
        print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base)
        """
    )
    warm = tmp_path / "warm.mcap"
    warm.write_bytes(_mcap(_good_chunk(0)))
    proc = subprocess.run(
        [sys.executable, "-c", script, str(path), str(warm)], capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stderr
    reason, grew_kb = proc.stdout.strip().splitlines()
    assert f"chunk holds {2 << 20} bytes, its header says {declared}" in reason
    assert int(grew_kb) < 64 * 1024, f"RSS grew {int(grew_kb) // 1024} MB"


def test_a_damaged_chunk_between_good_ones_is_skipped(tmp_path):
    bad = bytearray(_good_chunk(500))
    bad[-5] ^= 0xFF  # inside the last message: the chunk CRC fails
    path = tmp_path / "crc.mcap"
    path.write_bytes(_mcap(_good_chunk(0), bytes(bad), _good_chunk(1000)))
    log = read_log(path)
    assert log.source.partial and "chunk CRC mismatch" in log.source.partial_reason
    assert len(log.channels["/a/x"]) == 20


def test_messages_on_an_undefined_channel_id_make_the_read_partial(tmp_path):
    records = [_channel(1, "/a"), _channel(2, "/b")] + [_message(1 + i % 2, i, i) for i in range(20)]
    records[5] = _message(7, 3, 3.0)  # a channel id no Channel record defines (valid chunk CRC)
    path = tmp_path / "undefined.mcap"
    path.write_bytes(_mcap(_plain_chunk(records)))
    log = read_log(path)
    assert log.source.partial
    assert "1 message(s) on channel ids no Channel record defines were dropped" in log.source.partial_reason


def test_a_channel_redefined_with_other_content_makes_the_read_partial(tmp_path):
    second = [_channel(1, "/b")] + [_message(1, 100 + i, i) for i in range(5)]  # id 1 was "/a"
    path = tmp_path / "redefined.mcap"
    path.write_bytes(_mcap(_good_chunk(0), _plain_chunk(second)))
    log = read_log(path)
    assert log.source.partial
    assert "1 Channel/Schema record(s) redefine an id" in log.source.partial_reason
    assert "'/a', redefined as '/b'" in log.source.partial_reason
    assert "5 message(s)" in log.source.partial_reason


def test_a_repeated_identical_channel_record_is_no_damage(tmp_path):
    path = tmp_path / "repeated.mcap"
    path.write_bytes(_mcap(_good_chunk(0), _good_chunk(1000)))
    log = read_log(path)
    assert not log.source.partial and len(log.channels["/a/x"]) == 20


def test_every_chunk_damaged_is_a_corrupt_log(tmp_path):
    path = tmp_path / "all.mcap"
    path.write_bytes(_mcap(_chunk("zstd", b"not zstd at all", 100)))
    with pytest.raises(CorruptLogError, match="zstd chunk does not decompress"):
        read_log(path)


def test_a_log_time_beyond_int64_nanoseconds_is_dropped_and_counted(tmp_path):
    records = [_channel(1, "/a"), _channel(2, "/b")] + [_message(1 + i % 2, i, i) for i in range(20)]
    records[4] = _record(0x05, struct.pack("<HIQQ", 1, 0, 2**64 - 1, 0) + b'{"x": 1}')  # wraps negative as int64
    path = tmp_path / "time.mcap"
    path.write_bytes(_mcap(_plain_chunk(records)))
    log = read_log(path)
    assert log.source.partial and "1 message(s) dropped: a log_time beyond int64" in log.source.partial_reason
    assert log.channels["/a/x"].t.min() >= 0 and len(log.channels["/a/x"]) == 9
