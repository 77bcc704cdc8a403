"""Helpers every reader shares: format magic bytes, which topics and channels are wanted, time-order warnings."""

from __future__ import annotations

import numpy as np

from logscan.log import SourceInfo

MCAP_MAGIC = b"\x89MCAP0\r\n"
ULOG_MAGIC = b"ULog\x01\x12\x35"

ZERO_TIMESTAMP_WHY = "timestamp 0 (never set by the publisher)"  # ULog and ulog2csv rows


def topic_wanted(topic: str, wanted: set[str] | None) -> bool:
    """True when ``topic`` is wanted (``wanted`` None: all): it is in ``wanted``, a wanted channel
    lies under it (``topic/...``), or it lies under a wanted prefix (a profile may name an on-board
    estimator by the prefix ``/ekf/state`` of channels that a CSV holds as columns). Leading and
    trailing "/" are ignored, so ULog and CSV topics without one match too."""
    if wanted is None:
        return True
    name = topic.strip("/")
    for item in wanted:
        want = item.strip("/")
        if name == want or want.startswith(name + "/") or name.startswith(want + "/"):
            return True
    return False


def channel_wanted(channel: str, topic: str, wanted: set[str] | None) -> bool:
    """Keep ``channel`` of ``topic`` when all are wanted, it is asked for, or its whole topic is
    (as ``topic`` or ``/topic``)."""
    if wanted is None or topic in wanted or "/" + topic in wanted:
        return True
    return topic_wanted(channel, wanted)


def report_time_order(t_ns: np.ndarray, label: str, source: SourceInfo, note: str = "") -> None:
    """Warn about timestamps that go backwards or repeat; the values stay in file order.

    Used by the ULog and CSV readers. Alignment (logscan.align) sorts and deduplicates.
    """
    if t_ns.size < 2:
        return
    steps = np.diff(t_ns)
    backwards = int((steps < 0).sum())
    if backwards == 0 and bool((steps > 0).all()):
        return
    duplicates = int((np.diff(np.sort(t_ns)) == 0).sum())
    source.warnings.append(
        f"{label}: timestamps not strictly increasing ({backwards} step(s) backwards, "
        f"{duplicates} duplicate(s)); kept in file order, alignment sorts and deduplicates"
        + (f" ({note})" if note and backwards else "")
    )
