"""Edit a real ROS 1 bag (for tests): copy it with rosbags, changing one topic's messages in a window.

`shift_fix` moves a NavSatFix's reported position north by a distance over a time window (a
spoofed or multipath-jumped GNSS), `hold_fix` freezes it (a stuck receiver), `drop_topics` leaves
topics out: a real robot's drive, everything else byte-for-byte as driven.
"""

from __future__ import annotations

import math
from pathlib import Path

METRES_PER_DEG_LAT = 111_132.954  # WGS-84 meridian degree near 45 deg (to 0.1 %: the test's jump is 10 m)


def shift_fix(src: Path, dst: Path, topic: str, start_s: float, end_s: float, north_m: float) -> int:
    """Copy the ROS 1 bag ``src`` to ``dst`` with ``topic``'s latitude moved ``north_m`` metres north
    for the messages ``start_s`` to ``end_s`` seconds after the bag's start. Returns how many moved."""

    def move(msg, first):
        msg.latitude += north_m / METRES_PER_DEG_LAT

    return edit_messages(src, dst, topic, start_s, end_s, move)


def hold_fix(src: Path, dst: Path, topic: str, start_s: float, end_s: float) -> int:
    """Copy the bag with ``topic``'s fix frozen at its first value in the window (a stuck receiver)."""

    def hold(msg, first):
        msg.latitude, msg.longitude, msg.altitude = first.latitude, first.longitude, first.altitude

    return edit_messages(src, dst, topic, start_s, end_s, hold)


def edit_messages(src: Path, dst: Path, topic: str, start_s: float, end_s: float, change) -> int:
    """Copy the ROS 1 bag ``src`` to ``dst``, calling ``change(message, first message of the window)``
    on each ``topic`` message ``start_s`` to ``end_s`` seconds after the bag's start. Returns how many."""
    from rosbags.rosbag1 import Reader, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    moved = 0
    first = None
    with Reader(src) as reader, Writer(dst) as writer:
        t0 = reader.start_time
        out = {}
        for conn in reader.connections:
            out[conn.id] = writer.add_connection(
                conn.topic, conn.msgtype, msgdef=conn.msgdef.data, md5sum=conn.digest, callerid=conn.ext.callerid
            )
        for conn, stamp, raw in reader.messages():
            since = (stamp - t0) / 1e9
            if conn.topic == topic and start_s <= since <= end_s:
                msg = store.deserialize_ros1(raw, conn.msgtype)
                first = first if first is not None else store.deserialize_ros1(raw, conn.msgtype)
                change(msg, first)
                raw = store.serialize_ros1(msg, conn.msgtype)
                moved += 1
            writer.write(out[conn.id], stamp, raw)
    assert math.isfinite(moved)
    return moved


def drop_topics(src: Path, dst: Path, topics: tuple[str, ...]) -> None:
    """Copy the ROS 1 bag ``src`` to ``dst`` without ``topics`` (a robot that did not record them)."""
    copy_bag(src, dst, drop=topics)


def drop_window(src: Path, dst: Path, topic: str, start_s: float, end_s: float) -> Path:
    """Copy the bag without ``topic``'s messages ``start_s`` to ``end_s`` seconds after its start (a
    sensor that dropped out)."""
    return copy_bag(src, dst, drop_in=(topic, start_s, end_s))


def copy_bag(
    src: Path, dst: Path, *, drop: tuple[str, ...] = (), lz4: bool = False, drop_in: tuple | None = None
) -> Path:
    """Copy the ROS 1 bag ``src`` to ``dst`` message for message, without the topics in ``drop``
    (and ``drop_in``'s topic from its start to its end, s after the bag's start); ``lz4``: with lz4
    chunks (the Husky bag's are bz2)."""
    from rosbags.rosbag1 import Reader, Writer

    writer = Writer(dst)
    if lz4:
        writer.set_compression(Writer.CompressionFormat.LZ4)
    with Reader(src) as reader, writer:
        out = {
            conn.id: writer.add_connection(
                conn.topic, conn.msgtype, msgdef=conn.msgdef.data, md5sum=conn.digest, callerid=conn.ext.callerid
            )
            for conn in reader.connections
            if conn.topic not in drop
        }
        for conn, stamp, raw in reader.messages():
            since = (stamp - reader.start_time) / 1e9
            if drop_in is not None and conn.topic == drop_in[0] and drop_in[1] <= since <= drop_in[2]:
                continue
            if conn.id in out:
                writer.write(out[conn.id], stamp, raw)
    return dst


def to_db3(bag: Path, out: Path) -> Path:
    """The ROS 1 bag ``bag`` converted by rosbags itself to a rosbag2 directory ``out`` with sqlite3
    storage (a .db3, the rosbag2 default before Iron); returns the directory."""
    from rosbags.convert import convert

    convert(
        srcs=[bag],
        dst=out,
        dst_storage="sqlite3",
        dst_version=9,
        compress=None,
        compress_mode="file",
        default_typestore=None,
        typestore=None,
        exclude_topics=[],
        include_topics=[],
        exclude_msgtypes=[],
        include_msgtypes=[],
    )
    return out
