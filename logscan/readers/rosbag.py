"""ROS bag reader: ROS 1 ``.bag`` files, rosbag2 ``.db3`` files and rosbag2 directories, as Logs.

Read through the pure-Python ``rosbags`` library (``rosbags.rosbag1.Reader``,
``rosbags.rosbag2.Reader``: sqlite3 and mcap storage). The channels are those the MCAP reader
gives for the same messages in a ROS 2 MCAP (``/imu/data/linear_acceleration.x``,
``/fix/position_covariance[0]``), so one profile serves all three containers:

 - ROS 1 types are read as their ROS 2 counterparts (``logscan.readers.rosbag_types``): the
   ``std_msgs/Header`` ``seq`` is dropped and ``stamp.secs``/``nsecs`` read as ``stamp.sec`` /
   ``nanosec``; a topic's schema is ``pkg/msg/Type`` and its encoding ``ros1`` (``cdr`` for rosbag2).
 - A rosbag2 directory whose storage is one MCAP file is read by logscan's MCAP reader (the
   same channels, faster); its source format is still ``rosbag2``.

Time is the bag's receive time (what MCAP calls log_time); with ``use_header_stamp`` the header
stamp where a message has one, as in the MCAP reader. Only wanted topics are read
(``common.topic_wanted``). rosbags walks the messages in Python; the bytes of each topic are
then decoded in bulk (the CDR layout kernel) where the type allows.

Bad input: a bag rosbags cannot open (truncated, unindexed, not a bag, a database that is not
rosbag2) is one InputError line; a bag that fails part way is returned with what was read,
``source.partial`` set and ``partial_reason`` saying where and how much.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import ExitStack
from pathlib import Path

import numpy as np

from logscan.errors import InputError
from logscan.log import Log, SourceInfo, TopicInfo
from logscan.readers import rosbag1_index, spill
from logscan.readers.common import UNDECODED_WHY, topic_wanted
from logscan.readers.flatten import MessageBytes
from logscan.readers.mcap import read_mcap
from logscan.readers.rosbag1_chunks import ROS1_HINT, read_chunks, ros1_layout
from logscan.readers.rosbag_types import TopicColumns, bag_typestore, ros1_to_cdr, ros2_type_name
from logscan.readers.topic_channels import TopicPieces, channels_in_time_order

_PROGRESS_MESSAGES = 4096  # messages read through rosbags between two progress calls
# a topic's raw messages read through rosbags are decoded each time they come to this many bytes: a
# long bag (a rosbag2 database) is then held as its decoded values (on disk when held), not its bytes
RAW_BATCH_BYTES = 16 << 20
ROS2_HINT = "check the copy; a rosbag2 database is read-only here, so repair it with `ros2 bag reindex` or sqlite3"


def read_rosbag(
    path: str | os.PathLike,
    wanted: set[str] | None,
    *,
    use_header_stamp: bool = False,
    progress: Callable[[int, int], None] | None = None,
    held: bool = False,
) -> Log:
    """Read the ROS 1 bag, rosbag2 ``.db3`` or rosbag2 directory ``path`` into a Log.

    ``progress(done, total)``: the bytes of the bag read (a directory: of its files), after each
    chunk of a ROS 1 bag, every `_PROGRESS_MESSAGES` messages read through rosbags, and at the end
    (``(total, total)``); a directory holding one MCAP reports as `read_mcap` does. ``held``: a log
    held for block mode's windows: a bag whose decoded values (read message by message: its file)
    come to `spill.HELD_FROM_BYTES` or more keeps them on disk (`readers.spill`), as a ULog does."""
    p = Path(path)
    mcap_file = single_mcap(p)
    if mcap_file is not None:
        log = read_mcap(mcap_file, wanted, use_header_stamp=use_header_stamp, progress=progress)
        log.source.path, log.source.format = str(p), "rosbag2"
        return log
    ros1 = not p.is_dir() and _is_ros1(p)
    fmt = "ros1bag" if ros1 else "rosbag2"
    with ExitStack() as stack:
        reader = stack.enter_context(_opened(p, ros1))
        source = SourceInfo(path=str(p), format=fmt)
        source.topics = _topic_infos(reader, ros1)
        store, bad, wire = bag_typestore(list(reader.connections), ros1)
        pieces = TopicPieces(str(p), fmt, use_header_stamp)
        chosen = []
        for connection in reader.connections:
            if not topic_wanted(connection.topic, wanted):
                continue
            if connection.msgtype in bad:
                pieces.skip_topic(connection.topic, bad[connection.msgtype], connection.msgcount)
                continue
            chosen.append(connection)
        decode = _BatchDecoder(ros1, TopicColumns(store), pieces, source)
        if ros1 and _chunk_walk_possible(reader, wire):
            layouts = {c.msgtype: ros1_layout(wire, store, c.msgtype) for c in chosen}
            values = _decoded_bytes(chosen, layouts)
            stack.enter_context(spill.spilling(held and values >= spill.HELD_FROM_BYTES, needs=2 * values))
            walked = read_chunks(str(p), reader, chosen, layouts, source, progress=progress)
            for topic, msgtype, flat, times in walked.decoded:
                pieces.add(topic, flat, times, stream=msgtype)
            batches = walked.raw
        else:  # message by message through rosbags, decoded a batch at a time (on disk when long and held)
            size = _bag_size(p)
            stack.enter_context(spill.spilling(held and size >= spill.HELD_FROM_BYTES, needs=2 * size))
            counted = None if progress is None else _MessageBytes(progress, size, chosen)
            batches = _read_messages(reader, chosen, source, counted, decode)
        for topic, msgtype in list(batches):
            decode(topic, msgtype, *batches.pop((topic, msgtype)))  # each topic's raw bytes go once decoded
        pieces.report_to(source)
        channels = channels_in_time_order(pieces.pieces, source, pieces.unsorted)  # joined on disk too, when spilling
    pieces.note_skipped(source)
    if progress is not None:
        size = _bag_size(p)
        progress(size, size)
    return Log(channels=channels, source=source)


def _decoded_bytes(connections: list, layouts: dict) -> int:
    """The bytes the chunk walk decodes ``connections`` into: 8 per field and message, and their times."""
    return sum(c.msgcount * 8 * (len(layouts[c.msgtype].paths) + 1) for c in connections if layouts.get(c.msgtype))


def _bag_size(path: Path) -> int:
    """The bytes of a bag file, or of the files of a rosbag2 directory."""
    if not path.is_dir():
        return path.stat().st_size
    return sum(entry.stat().st_size for entry in path.iterdir() if entry.is_file())


class _MessageBytes:
    """Byte progress of a read through rosbags, which gives messages, not file positions: the
    messages read so far out of the connections' total ``msgcount``, scaled to the bag's size (an
    estimate: messages are not all the same size, and the bag holds other records too)."""

    def __init__(self, progress: Callable[[int, int], None], size: int, connections: list) -> None:
        self.progress = progress
        self.size = size
        self.total = max(1, sum(int(c.msgcount) for c in connections))

    def __call__(self, count: int) -> None:
        self.progress(min(self.size, self.size * count // self.total), self.size)


def _chunk_walk_possible(reader, wire) -> bool:
    """Whether a ROS 1 bag can be read chunk by chunk (``rosbag1_chunks``): its types as written
    are known, and the rosbags reader has the index and chunk tables that walk reads."""
    return wire is not None and all(hasattr(reader, name) for name in ("index", "chunks", "connections"))


class _BatchDecoder:
    """Decodes one (topic, msgtype)'s raw messages at a time into ``pieces``; a topic's receive-time
    span is kept from its messages where the bag's index gave none (`_topic_infos`)."""

    def __init__(self, ros1: bool, columns: TopicColumns, pieces: TopicPieces, source: SourceInfo):
        self.ros1, self.columns, self.pieces, self.source = ros1, columns, pieces, source
        self.unspanned = {name for name, info in source.topics.items() if info.first_ns is None}

    def __call__(self, topic: str, msgtype: str, times: list[int], datas: list) -> None:
        t = np.asarray(times, dtype=np.int64)
        if topic in self.unspanned and t.size:
            info = self.source.topics[topic]
            first, last = int(t.min()), int(t.max())
            info.first_ns = first if info.first_ns is None else min(info.first_ns, first)
            info.last_ns = last if info.last_ns is None else max(info.last_ns, last)
        _decode_topic(topic, msgtype, t, datas, self.ros1, self.columns, self.pieces)


def _decode_topic(
    topic: str,
    msgtype: str,
    times: np.ndarray,
    datas: list,
    ros1: bool,
    columns: TopicColumns,
    pieces: TopicPieces,
) -> None:
    if ros1:
        cdrs, failed = ros1_to_cdr(columns.store, msgtype, datas)
        if failed:
            pieces.skips.skip(topic, UNDECODED_WHY, len(failed))
            times = np.delete(times, failed)
    else:
        cdrs = MessageBytes.from_list(datas)
    del datas
    flat, times = columns.columns(topic, msgtype, cdrs, times, pieces.skips)
    pieces.add(topic, flat, times, stream=msgtype)


def _read_messages(
    reader,
    connections: list,
    source: SourceInfo,
    counted: _MessageBytes | None = None,
    decode: Callable[[str, str, list, list], None] | None = None,
) -> dict[tuple[str, str], tuple[list, list]]:
    """(topic, msgtype) -> (receive times, raw message bytes) of ``connections``, in bag order: with
    ``decode``, those not yet given to it, which takes each (topic, msgtype)'s messages as their
    bytes reach `RAW_BATCH_BYTES` (so a long bag's raw bytes are not held whole). A bag that fails
    part way keeps what was read before, and the source says so. ``counted(messages read)`` every
    `_PROGRESS_MESSAGES` messages: a counter per message, not a call."""
    if isinstance(reader, rosbag1_index.TableIndexReader):
        reader.index_objects()  # rosbags' `messages` reads its own index
    batches: dict[tuple[str, str], tuple[list, list]] = {}
    sizes: dict[tuple[str, str], int] = {}  # the bytes of each batch
    for connection, timestamp, data in _messages(reader, connections, source, counted):
        key = (connection.topic, connection.msgtype)
        times, datas = batches.setdefault(key, ([], []))
        times.append(timestamp)
        datas.append(data)
        sizes[key] = sizes.get(key, 0) + len(data)
        if decode is not None and sizes[key] >= RAW_BATCH_BYTES:
            del sizes[key]
            decode(*key, *batches.pop(key))
    return batches


def _messages(reader, connections: list, source: SourceInfo, counted: _MessageBytes | None) -> Iterator[tuple]:
    """rosbags' (connection, receive time, bytes) of ``connections``, in bag order; a bag that fails
    part way ends them there, and the source says so (nothing read: InputError)."""
    if not connections:
        return
    count = 0
    last = None
    next_report = _PROGRESS_MESSAGES if counted is not None else -1  # -1: count never reaches it
    try:
        for message in reader.messages(connections=connections):
            yield message
            count += 1
            last = message[1]
            if count == next_report and counted is not None:
                counted(count)
                next_report += _PROGRESS_MESSAGES
    except Exception as exc:  # noqa: BLE001 - rosbags' errors on damaged data are many kinds
        if not count:
            raise InputError(
                f"cannot read the messages: {_why(exc)}",
                path=source.path,
                hint=ROS1_HINT if source.format == "ros1bag" else ROS2_HINT,
            ) from None
        source.partial = True
        source.partial_reason = (
            f"read stopped: {_why(exc)}; recovered {count} messages (up to receive time {last / 1e9:.6f} s)"
        )


def _topic_infos(reader, ros1: bool) -> dict[str, TopicInfo]:
    """Topic -> TopicInfo (count, ROS 2 schema name, encoding), and its time span where the bag
    indexes it without reading messages (ROS 1 indexes; rosbag2 sqlite per-topic times)."""
    topics: dict[str, TopicInfo] = {}
    spans = _ros1_spans(reader) if ros1 else _sqlite_spans(reader)
    for connection in reader.connections:
        info = topics.get(connection.topic)
        if info is None:
            encoding = "ros1" if ros1 else getattr(connection.ext, "serialization_format", "cdr")
            info = topics[connection.topic] = TopicInfo(
                name=connection.topic, encoding=encoding, schema=ros2_type_name(connection.msgtype)
            )
        info.message_count += int(connection.msgcount)
        first, last = spans.get((connection.topic, connection.id), (None, None))
        if first is not None:
            info.first_ns = first if info.first_ns is None else min(info.first_ns, first)
            info.last_ns = last if info.last_ns is None else max(info.last_ns, last)
    return topics


def _ros1_spans(reader) -> dict[tuple[str, int], tuple[int, int]]:
    """First and last receive time per connection, from the bag's index (`TableIndexReader.index`),
    in one pass over it: grouped by connection, each group's minimum and maximum."""
    if not reader.index.size:
        return {}
    by_id = np.argsort(reader.index[:, 0], kind="stable")
    ids, times = reader.index[by_id, 0], reader.index[by_id, 1]
    present, starts = np.unique(ids, return_index=True)
    first, last = np.minimum.reduceat(times, starts), np.maximum.reduceat(times, starts)
    spans = {int(i): (int(a), int(b)) for i, a, b in zip(present, first, last)}
    return {(c.topic, c.id): spans[c.id] for c in reader.connections if c.id in spans}


def _sqlite_spans(reader) -> dict[tuple[str, int], tuple[int, int]]:
    """First and last receive time per topic of a rosbag2 sqlite3 file, by one query; {} when the
    storage is another (the times of the topics read come from their messages)."""
    out: dict[tuple[str, int], tuple[int, int]] = {}
    storages = getattr(reader.storage, "storages", None) or [reader.storage]
    for storage in storages:
        dbconn = getattr(storage, "dbconn", None)
        if dbconn is None:
            continue
        try:
            rows = dbconn.cursor().execute(
                "SELECT topics.name, min(timestamp), max(timestamp) FROM messages "
                "JOIN topics ON topics.id == messages.topic_id GROUP BY topics.name"
            )
            by_name = {name: (int(first), int(last)) for name, first, last in rows if first is not None}
        except Exception:  # noqa: BLE001 - the spans are a nicety; the topics read are timed anyway
            continue
        for connection in reader.connections:
            if connection.topic in by_name:
                first, last = by_name[connection.topic]
                old = out.get((connection.topic, connection.id))
                if old is not None:
                    first, last = min(first, old[0]), max(last, old[1])
                out[(connection.topic, connection.id)] = (first, last)
    return out


class _opened:
    """The rosbags reader of ``path``, open; rosbags' errors become one InputError line."""

    def __init__(self, path: Path, ros1: bool):
        self.path, self.ros1 = path, ros1
        self.reader = None

    def __enter__(self):
        target = _for_rosbags(self.path)
        try:
            if self.ros1:
                self.reader = rosbag1_index.opened(target)
            else:
                from rosbags.rosbag2 import Reader

                self.reader = Reader(target)
                self.reader.open()
        except ImportError as exc:
            raise InputError(
                f"reading ROS bags needs the rosbags library ({exc})", path=str(self.path), hint="pip install rosbags"
            ) from None
        except Exception as exc:  # noqa: BLE001 - rosbags raises many kinds on damaged files
            kind = "ROS 1 bag (truncated, or its index damaged?)" if self.ros1 else "rosbag2"
            raise InputError(
                f"{kind} cannot be opened: {_why(exc)}", path=str(self.path), hint=ROS1_HINT if self.ros1 else ROS2_HINT
            ) from None
        return self.reader

    def __exit__(self, *exc_info) -> bool:
        try:
            self.reader.close()
        except Exception:  # noqa: BLE001, S110 - closing a damaged bag must not hide what was read
            pass
        return False


def _for_rosbags(path: Path) -> Path:
    """The path rosbags chooses its storage by: rosbag2.Reader goes by suffix (``.db3``, ``.mcap``)
    and logscan by content, so a SQLite bag with another name is given through a ``.db3`` link."""
    if path.is_dir() or path.suffix == ".db3" or _is_ros1(path):
        return path
    raise InputError(
        "an SQLite file not named .db3: rosbags reads rosbag2 databases by their suffix",
        path=str(path),
        hint="name it <bag>.db3, or give its rosbag2 directory",
    )


def _is_ros1(path: Path) -> bool:
    try:
        with open(path, "rb") as fh:
            return fh.read(13) == b"#ROSBAG V2.0\n"
    except OSError:
        return False


def single_mcap(path: Path) -> Path | None:
    """The one MCAP file of a rosbag2 directory whose storage is mcap (uncompressed), else None."""
    if not path.is_dir():
        return None
    try:
        text = (path / "metadata.yaml").read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    try:
        from ruamel.yaml import YAML  # what rosbags reads metadata.yaml with

        info = YAML(typ="safe").load(text)["rosbag2_bagfile_information"]
        files = info["relative_file_paths"]
        storage = info["storage_identifier"]
        compressed = str(info.get("compression_mode") or "").lower() not in ("", "none")
    except Exception:  # noqa: BLE001 - rosbags says what is wrong with the metadata
        return None
    if storage != "mcap" or compressed or len(files) != 1:
        return None
    candidate = path / Path(str(files[0])).name
    return candidate if candidate.is_file() else None


def _why(exc: BaseException) -> str:
    text = " ".join(str(part) for part in exc.args) if exc.args else ""
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__
