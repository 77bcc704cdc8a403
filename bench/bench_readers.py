"""Benchmark of the readers: MCAP, ULog and CSV against mcap, pyulog and pandas, ratios in one run.

Generates (in a temporary directory, deleted afterwards) a JSON MCAP and a ROS 2 MCAP of IMU-like
messages on several topics with ``logscan.readers.mcap.writer``, then times, in one run:

 - logscan: ``read_mcap(path, None)`` -> every numeric field as a numpy channel;
 - plain mcap: ``make_reader(f, decoder_factories=[...]).iter_decoded_messages()``, touching
   one field of every decoded message (it builds no arrays, so it does less work than logscan).

Then:

 - ULog: ``read_ulog(path, None)`` against pyulog's ``ULog(path)`` (every topic), and
   ``read_ulog(path, <the PX4 profile's topics>)`` against ``ULog(path, <their message names>)``,
   summed over the PX4 sample logs of ``../shared/testdata/px4-ulog`` and, as rows of their own,
   ``px4-ulog-extra`` (each skipped when absent), with each file's every-topic ratio printed;
 - CSV: ``read_csv(path, None)`` against ``pandas.read_csv(path)`` of a generated wide CSV
   (``--csv`` rows: a time column in seconds and 6 float columns, ``repr`` floats).

Every figure is the best of ``--mcap-reps`` (MCAP) or ``--reps`` (ULog, CSV) rounds that run the
two readers in turn, in wall seconds and in CPU seconds of this process (on a shared machine the
CPU ratio is the steadier one). Prints one table row per case. Usage:

    python bench/bench_readers.py                      # 1,000,000 JSON + 200,000 ROS 2 messages
    python bench/bench_readers.py --json 100000 --ros2 20000   # quick run
    python bench/bench_readers.py --json 0 --ros2 0    # ULog and CSV only
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from logscan.readers.mcap.reader import decoder_factories, read_mcap
from logscan.readers.mcap.writer import TopicData, write_mcap

# topic -> (share of the messages, schema name, field names)
_TOPICS = {
    "/imu": (
        0.5,
        "sensor_msgs/msg/Imu",
        [
            "linear_acceleration.x",
            "linear_acceleration.y",
            "linear_acceleration.z",
            "angular_velocity.x",
            "angular_velocity.y",
            "angular_velocity.z",
            "orientation.x",
            "orientation.y",
            "orientation.z",
            "orientation.w",
        ],
    ),
    "/imu2": (
        0.3,
        "sensor_msgs/msg/Imu",
        [
            "linear_acceleration.x",
            "linear_acceleration.y",
            "linear_acceleration.z",
            "angular_velocity.x",
            "angular_velocity.y",
            "angular_velocity.z",
        ],
    ),
    "/baro": (0.1, "logscan_msgs/msg/Baro", ["pressure", "temperature", "altitude"]),
    "/gps": (0.1, "logscan_msgs/msg/Gps", ["position.x", "position.y", "position.z", "speed"]),
}


def make_topics(n_messages: int, seed: int = 0) -> dict[str, TopicData]:
    """IMU-like topics totalling ``n_messages`` messages over the same time span."""
    rng = np.random.default_rng(seed)
    topics = {}
    duration_ns = 1_000_000_000_000  # 1000 s
    for topic, (share, schema, fields) in _TOPICS.items():
        n = int(round(n_messages * share))
        t = np.linspace(0, duration_ns, n, endpoint=False).astype(np.int64) + 1_700_000_000_000_000_000
        topics[topic] = TopicData(schema, t, {name: rng.normal(size=n) for name in fields})
    return topics


def best_wall_cpu(reps: int, runs: dict) -> dict:
    """name -> (best wall s, best CPU s) of ``reps`` rounds, each calling every run once in turn."""
    best = {name: (float("inf"), float("inf")) for name in runs}
    for _ in range(reps):
        for name, run in runs.items():
            wall, cpu = time.perf_counter(), time.process_time()
            run()
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            best[name] = (min(best[name][0], wall), min(best[name][1], cpu))
    return best


def read_logscan(path: Path) -> int:
    log = read_mcap(path, None)
    assert not log.source.partial and not log.source.skipped
    return sum(info.message_count for info in log.source.topics.values())


def _touch(decoded) -> object:
    if isinstance(decoded, dict):
        return next(iter(decoded.values()))
    return getattr(decoded, decoded.__slots__[0])


def read_plain_mcap(path: Path) -> int:
    from mcap.reader import make_reader

    count = 0
    with open(path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=decoder_factories())
        for _schema, _channel, _message, decoded in reader.iter_decoded_messages():
            _touch(decoded)
            count += 1
    return count


_ULOG_DIR = Path(__file__).resolve().parents[2] / "shared" / "testdata" / "px4-ulog"
_ULOG_DIRS = (("ulog", _ULOG_DIR), ("ulog extra", _ULOG_DIR.parent / "px4-ulog-extra"))


def ulog_rows(reps: int) -> list[tuple[str, str, tuple, tuple]]:
    """(case, size, logscan (wall, CPU) s, pyulog (wall, CPU) s) over the PX4 sample logs, best of
    ``reps`` per file, summed; one pair of rows per folder of ``_ULOG_DIRS`` that holds ULogs. Prints
    each file's CPU ratio of the every-topic read."""
    from pyulog import ULog

    from logscan.profiles.builtin import PX4_TOPICS
    from logscan.readers.ulog_reader import message_filter, read_ulog

    wanted = set(PX4_TOPICS)
    names = message_filter(wanted)
    rows = []
    for label, folder in _ULOG_DIRS:
        files = sorted(folder.glob("*.ulg"))
        if not files:
            print(f"{label}: no sample logs in {folder}: skipped")
            continue
        size = f"{len(files)} files, {sum(f.stat().st_size for f in files) / 1e6:.1f} MB"
        read_ulog(files[0], None)  # warm-up: imports
        for case, ours_wanted, theirs_names in (("every topic", None, None), ("PX4 profile topics", wanted, names)):
            ours, theirs = np.zeros(2), np.zeros(2)
            for f in files:
                best = best_wall_cpu(
                    reps,
                    {
                        "ours": lambda f=f, w=ours_wanted: read_ulog(f, w),
                        "theirs": lambda f=f, n=theirs_names: ULog(str(f), n),
                    },
                )
                ours, theirs = ours + best["ours"], theirs + best["theirs"]
                if ours_wanted is None:
                    ratio = best["theirs"][1] / best["ours"][1]
                    print(f"{label}, every topic, {f.name}: pyulog / logscan CPU {ratio:.2f}x")
            rows.append((f"{label}, {case}", size, tuple(ours), tuple(theirs)))
    return rows


def csv_rows(n_rows: int, tmp: str, reps: int) -> list[tuple[str, str, tuple, tuple]]:
    """(case, size, logscan (wall, CPU) s, pandas (wall, CPU) s) of a generated wide CSV, best of ``reps``."""
    import pandas as pd

    from logscan.readers.csv_reader import read_csv

    rng = np.random.default_rng(1)
    path = Path(tmp) / "bench.csv"
    columns = {"time_s": np.arange(n_rows) * 0.01}
    columns.update({f"c{i}": rng.normal(size=n_rows) for i in range(6)})
    pd.DataFrame(columns).to_csv(path, index=False)
    read_csv(path, None)  # warm-up
    best = best_wall_cpu(reps, {"ours": lambda: read_csv(path, None), "theirs": lambda: pd.read_csv(path)})
    return [("csv", f"{n_rows:,} rows x 7, {path.stat().st_size / 1e6:.0f} MB", best["ours"], best["theirs"])]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=int, default=1_000_000, help="messages in the JSON file")
    parser.add_argument("--ros2", type=int, default=200_000, help="messages in the ROS 2 file")
    parser.add_argument("--csv", type=int, default=1_000_000, help="rows of the CSV file (0: none)")
    parser.add_argument("--reps", type=int, default=5, help="ULog and CSV: best of this many reads")
    parser.add_argument("--mcap-reps", type=int, default=3, help="MCAP: best of this many reads")
    args = parser.parse_args()
    print(f"python {platform.python_version()}, {os.cpu_count()} cpu(s), {platform.machine()}")
    rows = []
    with tempfile.TemporaryDirectory(prefix="logscan-bench-") as tmp:
        for encoding, n in (("json", args.json), ("ros2", args.ros2)):
            if not n:
                continue
            path = Path(tmp) / f"bench_{encoding}.mcap"
            start = time.perf_counter()
            write_mcap(path, make_topics(n), encoding=encoding)
            written = time.perf_counter() - start
            size_mb = path.stat().st_size / 1e6
            print(f"{encoding}: wrote {n} messages ({size_mb:.1f} MB) in {written:.1f} s")
            read_mcap(path, {"/baro"})  # warm-up: numba kernels and imports, off the clock
            assert read_logscan(path) == read_plain_mcap(path) == n
            best = best_wall_cpu(
                args.mcap_reps, {"ours": lambda p=path: read_logscan(p), "theirs": lambda p=path: read_plain_mcap(p)}
            )
            rows.append((encoding, f"{n:,} messages, {size_mb:.0f} MB", best["ours"], best["theirs"]))
        other = ulog_rows(args.reps) + (csv_rows(args.csv, tmp, args.reps) if args.csv else [])
    print()
    print("| reader | input | logscan s (wall / CPU) | library s (wall / CPU) | library / logscan (wall / CPU) |")
    print("|---|---|---:|---:|---:|")
    for case, size, ours, theirs in [(f"mcap {e}", n, o, t) for e, n, o, t in rows] + other:
        print(
            f"| {case} | {size} | {ours[0]:.3f} / {ours[1]:.3f} | {theirs[0]:.3f} / {theirs[1]:.3f} "
            f"| {theirs[0] / ours[0]:.2f}x / {theirs[1] / ours[1]:.2f}x |"
        )


if __name__ == "__main__":
    main()
