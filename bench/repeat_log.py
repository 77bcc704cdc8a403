"""A long MCAP log made of one shorter log repeated back to back: the memory figure of a 24-hour
analysis without a 24-hour simulation (`logscan simulate` holds every series in memory: a 24-hour
quadcopter log needs about 21 GB to write).

    python bench/repeat_log.py q1h.mcap 24 q24h.mcap     # 24 copies of a 1-hour log

Every message is written again with its log_time (and publish_time) shifted by k x (the log's span +
one grid step) in copy k; the payloads (and so the ROS header stamps inside them) are the original
ones, so analyse the result with the default `--log-time`. The embedded profile is kept and the
ground truth's events are repeated with the same shift. The vehicle jumps back to its start state
at every seam: the filter sees a jump there, so the verdict of the long log is not a flight's, only
its memory and time are (each copy has the work of the original).
"""

from __future__ import annotations

import json
import sys

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer


def repeat(source: str, copies: int, target: str) -> None:
    with open(source, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        if summary is None or summary.statistics is None:
            raise SystemExit(f"{source}: no summary section; repeat needs an indexed MCAP")
        metadata = {record.name: dict(record.metadata) for record in reader.iter_metadata()}
        messages = [(channel.id, message) for _, channel, message in reader.iter_messages(log_time_order=True)]
        channels, schemas = summary.channels, summary.schemas
    start, end = summary.statistics.message_start_time, summary.statistics.message_end_time
    times = sorted({message.log_time for _, message in messages})
    step = min((b - a for a, b in zip(times, times[1:])), default=1)  # the shortest sample period
    period = end - start + step
    with open(target, "wb") as out:
        writer = Writer(out, compression=CompressionType.ZSTD)
        writer.start()
        schema_ids = {sid: writer.register_schema(s.name, s.encoding, s.data) for sid, s in schemas.items()}
        channel_ids = {
            cid: writer.register_channel(c.topic, c.message_encoding, schema_ids.get(c.schema_id, 0), c.metadata)
            for cid, c in channels.items()
        }
        for name, values in metadata.items():
            if name == "logscan.truth":
                values = {"json": json.dumps(_repeated_truth(json.loads(values["json"]), copies, period / 1e9))}
            writer.add_metadata(name, values)
        for copy in range(copies):
            shift = copy * period
            for cid, message in messages:
                writer.add_message(
                    channel_ids[cid],
                    log_time=message.log_time + shift,
                    data=message.data,
                    publish_time=message.publish_time + shift,
                    sequence=message.sequence,
                )
        writer.finish()


def _repeated_truth(truth: dict, copies: int, period_s: float) -> dict:
    events = truth.get("events", [])
    repeated = []
    for copy in range(copies):
        for event in events:
            shifted = dict(event)
            for key in ("start", "end"):
                if isinstance(shifted.get(key), int | float):
                    shifted[key] = shifted[key] + copy * period_s
            repeated.append(shifted)
    return {**truth, "events": repeated}


if __name__ == "__main__":
    if len(sys.argv) != 4:
        print(__doc__)
        sys.exit(2)
    repeat(sys.argv[1], int(sys.argv[2]), sys.argv[3])
