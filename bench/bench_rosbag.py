"""Benchmark of the ROS bag reader: logscan's read_log against rosbags' own reading of the same bags.

Reads the Husky drive of ../shared/testdata (a ROS 1 bag: /imu/data, /fix and the wheel odometry,
16,806 messages, bz2 chunks), a copy of it with lz4 chunks and a rosbag2 ``.db3`` converted from
it with ``rosbags.convert`` (both in a temporary directory, deleted afterwards) and, when present,
the same drive as a rosbag2 directory with MCAP storage, and times in one run, best of ``--repeat``:

 - logscan: ``read_log(path)`` -> every numeric field of every topic as a numpy channel;
 - rosbags: ``AnyReader([path])``, ``messages()`` of the same topics and ``deserialize`` of each,
   touching one field of every message (it builds no arrays, so it does less work than logscan).

Prints messages/s of both and the ratio. Usage:

    python bench/bench_rosbag.py                     # best of 5
    python bench/bench_rosbag.py --repeat 2 --bag other.bag
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
from pathlib import Path

from benchlib import best_of

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # the tests' bag helpers
from ros_edit import copy_bag, to_db3  # noqa: E402

from logscan.readers import read_log

TESTDATA = Path(__file__).resolve().parents[2] / "shared" / "testdata" / "ros-robots"
HUSKY = TESTDATA / "robot_localization_test1_husky.bag"
HUSKY_MCAP_DIR = TESTDATA / "robot_localization_test1_husky_ros2"


def read_logscan(path: Path) -> int:
    log = read_log(path)
    assert not log.source.partial and log.channels
    return sum(info.message_count for info in log.source.topics.values())


def read_rosbags(path: Path) -> int:
    from rosbags.highlevel import AnyReader

    count = 0
    with AnyReader([path]) as reader:
        for connection, _timestamp, data in reader.messages(connections=reader.connections):
            message = reader.deserialize(data, connection.msgtype)
            _ = message.header  # every topic of the Husky bag is stamped
            count += 1
    return count


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bag", type=Path, default=HUSKY, help="ROS 1 bag (default: the Husky drive)")
    parser.add_argument("--repeat", type=int, default=5, help="runs of each reader; the best counts")
    args = parser.parse_args()
    if not args.bag.exists():
        raise SystemExit(f"{args.bag}: missing (the shared test data, or give --bag)")
    import rosbags

    version = getattr(rosbags, "__version__", None)
    if version is None:
        from importlib.metadata import version as dist_version

        version = dist_version("rosbags")
    print(f"python {platform.python_version()}, {os.cpu_count()} cpu(s), {platform.machine()}, rosbags {version}")
    rows = []
    with tempfile.TemporaryDirectory(prefix="logscan-bench-") as tmp:
        db3 = next(to_db3(args.bag, Path(tmp) / "bag_ros2").glob("*.db3"))
        lz4 = copy_bag(args.bag, Path(tmp) / "lz4.bag", lz4=True)
        inputs = [("ROS 1 .bag", args.bag), ("ROS 1 .bag, lz4 chunks", lz4), ("rosbag2 .db3", db3)]
        if args.bag == HUSKY and HUSKY_MCAP_DIR.is_dir():
            inputs.append(("rosbag2 dir (mcap)", HUSKY_MCAP_DIR))
        for label, path in inputs:
            n = read_logscan(path)  # warm-up: numba kernels, imports and the page cache, off the clock
            assert read_rosbags(path) == n, label
            ours = best_of(args.repeat, lambda path=path: read_logscan(path))
            theirs = best_of(args.repeat, lambda path=path: read_rosbags(path))
            rows.append((label, n, ours, theirs))
    load = " / ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"load average (1 / 5 / 15 min): {load}")
    print()
    print("| input | messages | logscan read_log msg/s | rosbags AnyReader + deserialize msg/s | ratio |")
    print("|---|---:|---:|---:|---:|")
    for label, n, ours, theirs in rows:
        print(
            f"| {label} | {n:,} | {n / ours:,.0f} ({ours:.3f} s) | {n / theirs:,.0f} ({theirs:.3f} s) "
            f"| {theirs / ours:.2f}x |"
        )


if __name__ == "__main__":
    main()
