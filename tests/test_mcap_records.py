"""The compiled grouping of a container's messages by channel (`records.group_messages`) against the
numpy gathers and stable argsort it replaces."""

from __future__ import annotations

import numpy as np

from logscan.readers.mcap.records import (
    CHANNEL_IDS,
    MESSAGE_HEADER,
    OP_CHANNEL,
    OP_MESSAGE,
    OP_SCHEMA,
    group_messages,
)


def _container(rng: np.random.Generator, count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Records of one container: schema and channel records among messages whose channel ids are a
    few (one the largest uint16), whose log times run both ways, some beyond int64."""
    ops = rng.choice(np.array([OP_MESSAGE, OP_MESSAGE, OP_MESSAGE, OP_SCHEMA, OP_CHANNEL], dtype=np.uint8), count)
    lengths = rng.integers(MESSAGE_HEADER, MESSAGE_HEADER + 40, size=count).astype(np.int64)
    offsets = 9 + np.cumsum(lengths + 9) - (lengths + 9)  # each body after its 9-byte record header
    buf = np.zeros(int((offsets + lengths).max(initial=0)), dtype=np.uint8)
    for k in np.flatnonzero(ops == OP_MESSAGE).tolist():
        pos = int(offsets[k])
        buf[pos : pos + 2] = np.frombuffer(np.uint16(rng.choice([3, 1, 7, 65535])).tobytes(), dtype=np.uint8)
        time = rng.integers(0, 2**62) if rng.random() > 0.1 else 2**63 + int(rng.integers(0, 2**62))
        buf[pos + 6 : pos + 14] = np.frombuffer(np.uint64(time).tobytes(), dtype=np.uint8)
    return buf, ops, offsets, lengths


def test_messages_are_grouped_by_channel_as_a_stable_argsort_groups_them():
    rng = np.random.default_rng(7)
    slot = np.full(CHANNEL_IDS, -1, dtype=np.int64)
    for count in (0, 1, 5, 400):
        buf, ops, offsets, lengths = _container(rng, count)
        found = group_messages(buf, ops, offsets, lengths, slot)
        m_off, m_len = offsets[ops == OP_MESSAGE], lengths[ops == OP_MESSAGE]
        raw = np.array([int.from_bytes(buf[p + 6 : p + 14].tobytes(), "little") for p in m_off.tolist()], dtype=object)
        fits = np.array([t < 2**63 for t in raw], dtype=bool)
        ids = np.array([int(buf[p]) | int(buf[p + 1]) << 8 for p in m_off[fits].tolist()], dtype=np.int64)
        times = raw[fits].astype(np.int64)
        assert found.short_at == -1 and found.messages == m_off.size
        assert found.channel_ids.tolist() == ids.tolist() and found.log_times.tolist() == times.tolist()
        assert found.offsets.tolist() == m_off[fits].tolist() and found.lengths.tolist() == m_len[fits].tolist()
        order = np.argsort(ids, kind="stable")
        assert found.group_ids.tolist() == sorted(set(ids.tolist()))
        assert found.grouped_times.tolist() == times[order].tolist()
        assert found.grouped_starts.tolist() == (m_off[fits][order] + MESSAGE_HEADER).tolist()
        assert found.grouped_ends.tolist() == (m_off[fits] + m_len[fits])[order].tolist()
        for g, cid in enumerate(found.group_ids.tolist()):
            group = times[ids == cid]
            assert found.bounds[g + 1] - found.bounds[g] == group.size
            assert (found.low[g], found.high[g]) == (group.min(), group.max())
        assert (slot == -1).all()  # the scratch is left as found, for the next container


def test_a_message_shorter_than_its_header_is_found_before_anything_is_grouped():
    rng = np.random.default_rng(8)
    buf, ops, offsets, lengths = _container(rng, 50)
    messages = np.flatnonzero(ops == OP_MESSAGE)
    lengths[messages[[3, 5]]] = MESSAGE_HEADER - 1
    found = group_messages(buf, ops, offsets, lengths, np.full(CHANNEL_IDS, -1, dtype=np.int64))
    assert found.short_at == offsets[messages[3]]
    assert found.group_ids.size == 0 and found.messages == messages.size
