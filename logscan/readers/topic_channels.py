"""A topic's flattened message columns become channels: names, header-stamp times, time order.

Shared by the readers of message logs (MCAP, ROS 1 bags, rosbag2), so the same messages give the
same channels whichever container they came in.

Channel names: ``<topic>/<field path>``, where the topic's trailing "/" is dropped before joining,
so ``/imu`` + ``linear_acceleration.x`` -> ``/imu/linear_acceleration.x``; a message that is itself
a number gives a channel named by the topic alone. Each field keeps the times of the messages that
had it. With header stamps asked for, messages with ``header.stamp`` (``sec``/``nanosec``, or
``secs``/``nsecs``) are timed by it instead of their log time.
"""

from __future__ import annotations

from collections.abc import Hashable

import numpy as np

from logscan.log import Channel, SourceInfo
from logscan.readers import spill
from logscan.readers.flatten import FlatColumns

MAX_STAMP_S = 9.2e9  # header.stamp seconds int64 nanoseconds can hold (2**63 ns ~ 9.22e9 s)
_STAMP_FIELDS = (
    ("header.stamp.sec", "header.stamp.nanosec"),
    ("header.stamp.secs", "header.stamp.nsecs"),
)


class TopicPieces:
    """Channel pieces (name -> [(t, values)]) collected topic batch by topic batch (`add`); the
    skips met and the fields found go to the log's source at the end (`report_to`), the topics no
    decoder takes and the channels' time source after the channels are joined (`note_skipped`)."""

    def __init__(self, path: str, fmt: str, use_header_stamp: bool):
        self.use_header_stamp = use_header_stamp
        self.pieces: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
        self.decoded_topics: set[str] = set()
        self.stamp_topics: set[str] = set()  # topics timed by header.stamp
        self.fields: dict[str, list[str]] = {}  # topic -> field paths in first-seen order
        self.skips = SourceInfo(path=path, format=fmt)  # collects skip counts until report_to
        self.undecodable: set[str] = set()  # topics no decoder takes (`skip_topic`)
        self.skipped_fields: dict[str, set[str]] = {}  # topic -> the names of its fields skipped
        # channels whose times go back within one stream of the file (`add`), and each
        # (channel, stream)'s last time so far
        self.unsorted: set[str] = set()
        self.stream_ends: dict[tuple[str, Hashable], int] = {}

    def add(self, topic: str, flat: FlatColumns, log_times: np.ndarray, stream: Hashable = None) -> None:
        """One batch of ``topic``'s messages: ``flat`` columns index ``log_times`` (int ns).
        ``stream``: what wrote them (a channel, a message type), when a topic has several; the
        batches of one stream come in file order. Their times are checked in that order, stream by
        stream: a topic's streams interleave in the file, so its batches joined are out of order
        without the file being so."""
        self.decoded_topics.add(topic)
        for (field_path, why_skipped), count in flat.skipped.items():
            self.skips.skip(channel_name(topic, field_path), why_skipped, count)
            self.skipped_fields.setdefault(topic, set()).add(channel_name(topic, field_path))
        times = log_times
        if self.use_header_stamp:
            times, used, unfit = header_stamps(flat.columns, log_times)
            if used:
                self.stamp_topics.add(topic)
            if unfit:
                self.skips.skip(f"{topic} header.stamp", "not a time in range (log_time used)", unfit)
        fields = self.fields.setdefault(topic, [])
        backwards = times.size > 1 and bool((times[1:] < times[:-1]).any())
        times = spill.kept(times)  # the pieces wait on disk within `spill.spilling` (a long bag held)
        for field_path in flat.fields:
            if field_path not in fields:
                fields.append(field_path)
            index, values = flat.columns[field_path]
            # a field every message has shares the topic's times (one array, not one per field)
            field_times = times if index.size == times.size else spill.kept(times[index])
            name = channel_name(topic, field_path)
            self.pieces.setdefault(name, []).append((field_times, spill.kept(values)))
            self._check_order(name, stream, field_times, backwards)

    def _check_order(self, name: str, stream: Hashable, t: np.ndarray, backwards: bool) -> None:
        """``name`` unsorted when ``t`` goes back, or starts before its stream's last batch ended
        (``backwards``: whether the batch's times go back anywhere, else ``t`` need not be read)."""
        if t.size == 0:
            return
        end = self.stream_ends.get((name, stream))
        if (end is not None and int(t[0]) < end) or (backwards and bool((t[1:] < t[:-1]).any())):
            self.unsorted.add(name)
        self.stream_ends[(name, stream)] = int(t[-1])

    def skip_topic(self, topic: str, why: str, count: int) -> None:
        """A topic no decoder takes: its ``count`` messages skipped for ``why``."""
        self.skips.skip(topic, why, count)
        self.undecodable.add(topic)

    def report_to(self, source: SourceInfo) -> None:
        """The skips and fields found, into the log's source."""
        for item in self.skips.skipped:
            source.skip(item.what, item.why, item.count)
        for topic, fields in self.fields.items():
            info = source.topics[topic]
            info.fields.extend(f for f in fields if f not in info.fields)

    def time_source(self) -> str:
        """What the channel times are, when header stamps were asked for."""
        return time_source(self.decoded_topics, self.stamp_topics)

    def note_skipped(self, source: SourceInfo) -> None:
        """The topics no decoder takes, and (header stamps asked for) what the channel times are."""
        if self.undecodable:
            source.warnings.append("topics skipped (no decoder): " + ", ".join(sorted(self.undecodable)))
        if self.use_header_stamp:
            source.time_source = self.time_source()


def time_source(decoded_topics: set[str], stamp_topics: set[str]) -> str:
    """What the channel times are, when header stamps were asked for."""
    missing = sorted(decoded_topics - stamp_topics)
    if stamp_topics and not missing:
        return "header.stamp"
    if stamp_topics:
        return "header.stamp (log_time for " + ", ".join(missing) + ")"
    return "log_time (no header.stamp found)"


def header_stamps(columns: dict, log_times: np.ndarray) -> tuple[np.ndarray, bool, int]:
    """Per-message time: header.stamp where the message has it (and it is a time in range),
    else log_time; also whether any message had one, and how many were out of range."""
    for sec_name, nsec_name in _STAMP_FIELDS:
        if sec_name in columns and nsec_name in columns:
            sec_idx, sec = columns[sec_name]
            nsec_idx, nsec = columns[nsec_name]
            both, in_sec, in_nsec = np.intersect1d(sec_idx, nsec_idx, return_indices=True)
            sec, nsec = sec[in_sec], nsec[in_nsec]
            # a stamp int64 ns cannot hold (NaN, inf, 1e300 s) keeps the message's log_time
            fits = np.isfinite(sec) & np.isfinite(nsec) & (np.abs(sec) < MAX_STAMP_S) & (np.abs(nsec) < 1e12)
            times = log_times.copy()
            # t = sec * 1e9 + nanosec, in integer ns
            times[both[fits]] = sec[fits].astype(np.int64) * 1_000_000_000 + nsec[fits].astype(np.int64)
            return times, both.size > 0, int(both.size - np.count_nonzero(fits))
    return log_times, False, 0


def channels_in_time_order(
    pieces: dict[str, list[tuple[np.ndarray, np.ndarray]]], source: SourceInfo, unsorted_in: set[str]
) -> dict[str, Channel]:
    """One Channel per name, its pieces joined and sorted by time (stable); a warning names the
    channels ``unsorted_in`` the file (`TopicPieces.unsorted`): one whose streams merely interleave
    is sorted without it."""
    channels: dict[str, Channel] = {}
    unsorted_in_file: list[str] = []
    # pieces' times shared by a topic's fields: joined, checked and ordered once -> (t, order or None);
    # keyed by the ids of the pieces' times, all alive together when the loop starts
    joined: dict[tuple[int, ...], tuple[np.ndarray, np.ndarray | None]] = {}
    for name in list(pieces):
        parts = pieces.pop(name)  # each channel's pieces go as it is joined
        key = tuple(id(p[0]) for p in parts)
        if key not in joined:
            t = spill.joined([p[0] for p in parts])  # on disk within `spill.spilling` (a long bag held)
            unsorted = t.size > 1 and bool((t[1:] < t[:-1]).any())
            joined[key] = (t, np.argsort(t, kind="stable") if unsorted else None)
        t, order = joined[key]
        v = spill.joined([p[1] for p in parts])
        del parts
        if order is not None:
            t, v = t[order], v[order]
            if name in unsorted_in:
                unsorted_in_file.append(name)
        channels[name] = Channel(name, t, v)
    if unsorted_in_file:
        source.warnings.append(unsorted_text(sorted(unsorted_in_file)))
    return channels


def unsorted_text(names: list[str]) -> str:
    return (
        f"{len(names)} channel(s) not in time order in the file, sorted by time: "
        + ", ".join(names[:5])
        + (" ..." if len(names) > 5 else "")
    )


def channel_name(topic: str, path: str) -> str:
    if not path:
        return topic
    return topic.rstrip("/") + "/" + path
