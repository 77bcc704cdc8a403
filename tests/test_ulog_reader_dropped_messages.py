"""The ULog reader counts every message pyulog drops without a word as damage: a duplicated or lost
subscription ('A' record), a message type byte the format does not define, a timestamp whose
nanoseconds do not fit int64 (in a data message or the file header): each makes the read partial,
saying how many messages were lost."""

from __future__ import annotations

import struct
from pathlib import Path

from conftest import need_testdata

from logscan.readers import read_log


def _ulog(name: str = "sample_log_small.ulg") -> bytes:
    return (need_testdata("px4-ulog") / name).read_bytes()


def _messages(data: bytes) -> list[tuple[int, int, str]]:
    """(offset, payload size, type) of every ULog message after the 16-byte file header."""
    out, pos = [], 16
    while pos + 3 <= len(data):
        size, kind = struct.unpack_from("<HB", data, pos)
        out.append((pos, size, chr(kind)))
        pos += 3 + size
    return out


def _read(tmp_path: Path, data: bytes):
    path = tmp_path / "edited.ulg"
    path.write_bytes(data)
    return read_log(path)


def test_the_intact_log_is_not_partial():
    log = read_log(need_testdata("px4-ulog") / "sample_log_small.ulg")
    assert not log.source.partial, log.source.partial_reason


def test_a_data_message_type_byte_changed_to_an_undefined_type_is_counted(tmp_path):
    data = bytearray(_ulog())
    data_messages = [m for m in _messages(data) if m[2] == "D"]
    for offset, _size, _kind in data_messages[100:103]:
        data[offset + 2] = 0xBB
    log = _read(tmp_path, bytes(data))
    assert log.source.partial
    assert "3 message(s) of types the ULog format does not define skipped (0xbb x3)" in log.source.partial_reason


def test_a_lost_subscription_drops_its_messages_as_damage(tmp_path):
    data = bytearray(_ulog())
    subscription = next(m for m in _messages(data) if m[2] == "A")
    data[subscription[0] + 2] = 0xBB  # the 'A' record becomes a message of an undefined type
    log = _read(tmp_path, bytes(data))
    assert log.source.partial
    assert "data message(s) dropped as corrupt: no subscription" in log.source.partial_reason


def test_a_subscription_reusing_a_message_id_replaces_one_and_is_counted(tmp_path):
    data = bytearray(_ulog())
    subs = [m for m in _messages(data) if m[2] == "A"]
    first_id = struct.unpack_from("<H", data, subs[0][0] + 4)[0]
    struct.pack_into("<H", data, subs[1][0] + 4, first_id)  # the second 'A' takes the first's msg_id
    log = _read(tmp_path, bytes(data))
    assert log.source.partial
    assert "subscription(s) replaced by an 'A' record reusing their message id" in log.source.partial_reason


def test_a_topic_subscribed_twice_is_partial_with_the_count_dropped(tmp_path):
    data = bytearray(_ulog())
    subs = [m for m in _messages(data) if m[2] == "A"]
    pairs = [(a, b) for i, a in enumerate(subs) for b in subs[i + 1 :] if a[1] == b[1]]  # same name length
    one, other = pairs[0]
    name = bytes(data[one[0] + 6 : one[0] + 3 + one[1]])
    data[other[0] + 3] = data[one[0] + 3]  # same multi_id
    data[other[0] + 6 : other[0] + 3 + other[1]] = name  # the other subscribes the first's topic
    log = _read(tmp_path, bytes(data))
    assert log.source.partial
    # its messages are read under the first topic's format: dropped as corrupt (sizes differ), or as
    # a second copy of the topic (same format): counted either way
    reason = log.source.partial_reason
    assert "subscribed twice" in reason or "data message(s) dropped as corrupt" in reason


def test_a_header_timestamp_near_two_to_the_64_is_damage_not_an_overflow(tmp_path):
    data = bytearray(_ulog())
    struct.pack_into("<Q", data, 8, 2**64 - 5)
    log = _read(tmp_path, bytes(data))
    assert log.source.partial and "start timestamp 18446744073709551611 us" in log.source.partial_reason
    assert "start_timestamp_us" not in log.source.metadata["ulog.log"]
    assert log.origin_ns == log.start_ns  # the first sample, not an overflowed start


def test_a_data_timestamp_beyond_int64_nanoseconds_is_dropped_and_counted(tmp_path):
    data = bytearray(_ulog())
    offset = [m for m in _messages(data) if m[2] == "D"][200][0]
    struct.pack_into("<Q", data, offset + 5, 2**64 - 7)  # after size, type and msg_id: the timestamp
    log = _read(tmp_path, bytes(data))
    assert log.source.partial and "timestamp beyond int64 nanoseconds" in log.source.partial_reason
    assert all(c.t.min() >= 0 for c in log.channels.values() if len(c))
