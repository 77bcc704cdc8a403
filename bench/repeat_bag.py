"""A long ROS 1 bag made of one bag's messages repeated back to back (memory and time of a long
drive without driving one): copy k shifts every message's log time and header stamp (the first
field of the std_msgs/Header-led messages: seq, then stamp sec) by k x (the span rounded up + 1 s).

    python bench/repeat_bag.py ../shared/testdata/ros-robots/robot_localization_test1_husky.bag 9 husky_1h.bag
"""

from __future__ import annotations

import struct
import sys

from rosbags.rosbag1 import Reader, Writer


def repeat(source: str, copies: int, target: str) -> int:
    """Write ``copies`` of ``source`` into ``target``; returns one copy's period (s)."""
    with Reader(source) as reader, Writer(target) as writer:
        period_s = int(reader.duration // 1_000_000_000) + 2
        out = {
            c.id: writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest)
            for c in reader.connections
        }
        messages = list(reader.messages())
        for k in range(copies):
            for connection, timestamp, raw in messages:
                data = bytearray(raw)
                (sec,) = struct.unpack_from("<I", data, 4)  # header: seq (uint32), stamp.sec (uint32), ...
                struct.pack_into("<I", data, 4, sec + k * period_s)
                writer.write(out[connection.id], timestamp + k * period_s * 1_000_000_000, bytes(data))
    return period_s


if __name__ == "__main__":
    print(repeat(sys.argv[1], int(sys.argv[2]), sys.argv[3]), "s per copy")
