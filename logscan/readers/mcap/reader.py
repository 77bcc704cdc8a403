"""MCAP reader: the scan's message batches decoded per channel and flattened into time-sorted channels.

How a file is read
------------------
The whole file is walked linearly, record by record (``records``: a numba kernel finds the record
boundaries, another groups each chunk's messages by channel; ``scan``: Python works per chunk and channel,
not per message). This is what the mcap library's streaming reader does too, but it is far faster,
and it does not depend on the summary section, so it reads every conformance file, including the
ones whose summary lacks channel or schema records (where ``mcap.reader.SeekingReader`` raises
KeyError).

Decoding: per channel, the first factory of [JSON (``logscan.readers.json_decoder``), ROS 2 CDR
(``mcap_ros2``), ROS 1 (``mcap_ros1``), protobuf (``mcap_protobuf``)] whose ``decoder_for``
returns a decoder is used for all of that channel's messages. Only messages of wanted topics are
decoded. Their bytes are never sliced per message on the way: each channel keeps (decompressed
chunk buffer, starts, ends) segments (``flatten.MessageBytes``) that the bulk paths below read in
place; per-message ``bytes`` are made only for the generic decoders. A channel no factory decodes
(unknown encoding, schemaless non-JSON, a schema that does not parse) is skipped and listed in
``source.skipped`` with the reason and a warning naming the topics. Two bulk paths give the same
columns without a Python object per message (tests check they match the decoders exactly): ROS 2
definitions made of primitives, strings and fixed-size arrays are run as a layout program by a
numba kernel (``cdr``), and JSON messages laid out like their topic's first message are matched
and their numbers parsed in bulk (``json_decoder.json_columns``). Everything else goes through the
decoder and ``flatten.flatten_messages``.

Channel names: ``<topic>/<field path>``, where the topic's trailing "/" is dropped before joining,
so ``/imu`` + ``linear_acceleration.x`` -> ``/imu/linear_acceleration.x`` and ``imu`` + ``accel.x``
-> ``imu/accel.x``; arrays index as ``position[2]``. A message that is itself a number gives a
channel named by the topic alone. Each channel has its own timestamps: a variable-length array
index only gets samples from the messages that had it. Channels are sorted by time (stable); a
topic logged out of log_time order gives a warning. (Naming, timing and ordering are
``logscan.readers.topic_channels``, shared with the ROS bag reader.)

Time: ``log_time`` (int ns). With ``use_header_stamp=True``, messages that have ``header.stamp``
(``sec``/``nanosec`` in ROS 2 and JSON, ``secs``/``nsecs`` in ROS 1) use it instead.

Metadata records become ``source.metadata``; logscan's truth and profile records become
``Log.truth`` and ``Log.profile_text`` (``metadata``).

Corrupt files: the walk stops at the first record that is truncated, fails its CRC, fails to
decompress or does not parse. If messages were read before that point the Log is returned with
``source.partial = True`` and ``partial_reason`` saying where it stopped and how many messages
(and what time span) were recovered; otherwise CorruptLogError names the file and the problem.
Damage the walk finds without stopping (a data-section CRC mismatch, summary statistics that
count other numbers of messages or chunks: ``scan.Scan.damage``) makes the Log partial the same way.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import numpy as np

from logscan.log import Log, SourceInfo, TopicInfo, WholeTimes
from logscan.readers.common import UNDECODED_WHY, ReadWindow, topic_wanted, undecoded_as_partial
from logscan.readers.flatten import FlatColumns, MessageBytes, flatten_messages
from logscan.readers.json_decoder import JsonDecoder, JsonDecoderFactory, json_columns
from logscan.readers.json_template import JsonTier, tally_file
from logscan.readers.mcap.cdr import CdrLayout, cdr_fast, cdr_layout
from logscan.readers.mcap.file_plan import FilePlan, file_plan, known_top
from logscan.readers.mcap.metadata import attach_logscan_records
from logscan.readers.mcap.scan import Scan, scan_file
from logscan.readers.mcap.scan_damage import problem_text, raise_if_unrecoverable
from logscan.readers.mcap.scan_records import ChannelRec, SchemaRec
from logscan.readers.mcap.window import WindowPlan, plan_window
from logscan.readers.topic_channels import TopicPieces, channel_name, channels_in_time_order, unsorted_text


def read_mcap(
    path: str | os.PathLike,
    wanted: set[str] | None,
    *,
    use_header_stamp: bool = False,
    progress: Callable[[int, int], None] | None = None,
    window: ReadWindow | None = None,
) -> Log:
    """Read the MCAP file ``path`` into a Log, decoding only topics ``topic_wanted`` keeps;
    ``progress(bytes passed, file size)`` is called a chunk or window of the file at a time, and
    with (file size, file size) at the end. ``window``: decode only the chunks a window of the log
    needs, when the file is indexed (`logscan.readers.mcap.window`; header stamps read it whole)."""
    path = str(path)
    decoding = _Decoding(path, use_header_stamp)
    scan = Scan(path, wanted)
    scan.on_flush = decoding  # batches decoded as the scan goes: memory follows the columns
    planner = _WindowPlanner(window, decoding) if window is not None and not use_header_stamp else None
    progress = _onward(progress) if planner is not None else progress
    scan.plan = planner
    if planner is not None:  # a window of this file read before: its top-level records are known
        scan.known_top = known_top(planner.window.plans, path)
    if progress is not None:
        scan.on_position = _bytes_of(path, progress)
    source = _scanned(scan, decoding)
    channels = channels_in_time_order(decoding.pieces, source, decoding.unsorted)
    decoding.note_skipped(source)
    log = Log(channels=channels, source=source)
    if planner is not None and planner.plan is not None and not planner.mark(log, scan, decoding):
        return read_mcap(path, wanted, use_header_stamp=use_header_stamp, progress=progress)
    attach_logscan_records(log)
    if progress is not None:
        size = os.path.getsize(path)
        progress(size, size)
    return log


def _onward(progress: Callable[[int, int], None] | None) -> Callable[[int, int], None] | None:
    """``progress`` that hears only bytes past the most it heard: a window's read that must then
    read the file whole reports the second pass once it passes the first."""
    if progress is None:
        return None
    heard = [-1]

    def onward(done: int, total: int) -> None:
        if done > heard[0]:
            heard[0] = done
            progress(done, total)

    return onward


def _bytes_of(path: str, progress: Callable[[int, int], None]) -> Callable[[int], None]:
    """``progress`` as the scan's ``on_position``: the offset and the file's size (looked up at
    the first call, when the scan has opened the file)."""
    size: list[int] = []

    def position(offset: int) -> None:
        if not size:
            size.append(os.path.getsize(path))
        progress(offset, size[0])

    return position


def _scanned(scan: Scan, decoding: _Decoding) -> SourceInfo:
    """Scan the file with ``decoding`` hearing each batch (refusing damage it cannot read past),
    decode the last batch, keep the JSON tally, and say what the scan and the decoding found."""
    scan_file(scan)
    raise_if_unrecoverable(scan)
    scan.flush()
    decoding.json_tier.save()
    source = _source_of(scan)
    decoding.report_to(source)
    return source


def inspect_mcap(
    path: str | os.PathLike, wanted: set[str] | None, *, use_header_stamp: bool = False
) -> tuple[Log, dict[str, dict]]:
    """What `read_mcap` finds, in memory bounded by a few chunks instead of the log: each batch's
    columns are folded into per-channel statistics and dropped. Returns the log (its channels
    counted, their samples not kept, as `Log.release_samples` leaves them) and channel name ->
    {rate_hz, nonfinite, min, max}."""
    path = str(path)
    decoding = _Decoding(path, use_header_stamp)
    stats: dict[str, ChannelStats] = {}

    def flush(scan: Scan) -> None:
        decoding(scan)
        decoding.fold_into(stats)

    scan = Scan(path, wanted)
    scan.on_flush = flush
    source = _scanned(scan, decoding)
    if decoding.unsorted:
        source.warnings.append(unsorted_text(sorted(decoding.unsorted)))
    decoding.note_skipped(source)
    undecoded_as_partial(source)  # as `read_log` says of the same file
    log = Log.without_samples({name: entry.span() for name, entry in stats.items()}, source)
    attach_logscan_records(log)
    return log, {name: entry.to_dict() for name, entry in stats.items()}


class ChannelStats:
    """Running facts of one channel over the pieces it is read in."""

    def __init__(self) -> None:
        self.samples = self.nonfinite = 0
        self.first = self.last = None  # ns
        self.low = self.high = None

    def add(self, t: np.ndarray, values: np.ndarray) -> None:
        if t.size == 0:
            return
        self.samples += int(t.size)
        low_t, high_t = int(t.min()), int(t.max())
        self.first = low_t if self.first is None else min(self.first, low_t)
        self.last = high_t if self.last is None else max(self.last, high_t)
        finite = values[np.isfinite(values)]
        self.nonfinite += int(values.size - finite.size)
        if finite.size:
            low, high = float(finite.min()), float(finite.max())
            self.low = low if self.low is None else min(self.low, low)
            self.high = high if self.high is None else max(self.high, high)

    def span(self) -> tuple[int, int | None, int | None]:
        return self.samples, self.first, self.last

    def to_dict(self) -> dict:
        span = (self.last - self.first) / 1e9 if self.samples else 0.0
        return {
            "rate_hz": round((self.samples - 1) / span, 6) if self.samples > 1 and span > 0 else 0.0,
            "nonfinite": self.nonfinite,
            "min": self.low,
            "max": self.high,
        }


class _WindowPlanner:
    """`Scan.plan` for a window (`window.plan_window`): the wanted channels a decoder takes, planned
    from the file's plan (`file_plan`: found once, kept in the window's ``plans``); then the log
    marked as a window of it (`mark`)."""

    def __init__(self, window: ReadWindow, decoding: _Decoding):
        self.window = window
        self.decoding = decoding
        self.plan: WindowPlan | None = None
        self.file: FilePlan | None = None

    def __call__(self, scan: Scan, u8: np.ndarray, top) -> set[int] | None:
        decoders = self.decoding.decoders
        for cid, channel in scan.channels.items():  # the summary's channels: every channel of an indexed file
            if cid not in decoders and topic_wanted(channel.topic, scan.wanted):
                decoders[cid] = _choose_decoder(self.decoding.factories, channel, scan.schemas.get(channel.schema_id))
        wanted = {cid for cid, (decoder, _) in decoders.items() if decoder is not None}
        topics = {cid: channel.topic for cid, channel in scan.channels.items()}
        self.file = file_plan(scan.path, self.window.plans, u8, top, wanted, topics, scan.give_back)
        index = self.file.index
        self.plan = plan_window(index, self.window, u8) if index is not None else None
        if self.plan is None or index is None:
            return None
        # every channel's count and span as the whole read counts them (`Scan.window_totals`)
        scan.window_totals = {cid: (entry.count, entry.first, entry.last) for cid, entry in index.items()}
        for cid, (decoder, why) in decoders.items():  # a wanted topic no decoder takes: all its messages
            if decoder is None and cid in index:
                scan.leave(cid)
                self.decoding.skip_topic(scan.channels[cid].topic, str(why), index[cid].count)
        return self.plan.chunks

    def mark(self, log: Log, scan: Scan, decoding: _Decoding) -> bool:
        """The log's span and its channels' times across the whole file (as runs), from the plan;
        False (the log is to be read whole) when the chunks read cannot stand for the whole read:
        the first message gave no sample (time zero moves), a field is missing from some messages,
        or a channel has no finite sample from its topic's last message before the window (a hold
        could reach further back)."""
        plan, file = self.plan, self.file
        assert plan is not None and file is not None and file.index is not None
        firsts = [int(channel.t[0]) for channel in log.channels.values() if len(channel)]
        if not firsts or min(firsts) != plan.origin_ns:
            return False
        by_topic: dict[str, list[int]] = {}
        for cid, entry in file.index.items():
            if entry.at is not None:
                by_topic.setdefault(scan.channels[cid].topic, []).append(cid)
        whole: dict[str, WholeTimes] = {}
        for topic, cids in by_topic.items():
            names = [channel_name(topic, field_path) for field_path in decoding.fields.get(topic, ())]
            if len({len(log.channels[name]) for name in names}) > 1:  # fields that come and go
                return False
            before = [plan.before[cid] for cid in cids if cid in plan.before]
            if before and not all(_held_from(log.channels[name], max(before), plan.lo_ns) for name in names):
                return False
            read = sum(scan.counts_read.get(cid, 0) for cid in cids)
            messages = sum(file.index[cid].count for cid in cids)
            if not _whole_skips(log.source.skipped, decoding.skipped_fields.get(topic, set()), read, messages):
                return False
            whole.update(dict.fromkeys(names, file.times[topic]))
        log.read_as_window((plan.origin_ns, plan.end_ns), whole)
        return True


def _whole_skips(skipped: list, fields: set[str], read: int, whole: int) -> bool:
    """A topic's ``fields`` skipped in every one of its ``read`` messages decoded (a string field)
    counted for its ``whole`` messages, as the whole read counts them; False when one was skipped
    in some messages only (fields that come and go)."""
    mine = [item for item in skipped if item.what in fields]
    if any(item.count != read for item in mine):
        return False
    for item in mine:
        item.count = whole
    return True


def _held_from(channel, before_ns: int, lo_ns: int | None) -> bool:
    """Whether ``channel`` has a finite sample from ``before_ns`` (its topic's last message before
    the chunks read hold every message) to ``lo_ns``: a hold into the window starts there."""
    inside = (channel.t >= before_ns) & (channel.t < lo_ns)
    return bool(np.isfinite(channel.values[inside]).any())


def _source_of(scan: Scan) -> SourceInfo:
    """What the scan found besides the messages: metadata, warnings, damage, topics and their counts."""
    source = SourceInfo(path=scan.path, format="mcap")
    source.metadata = dict(scan.metadata)
    source.warnings.extend(scan.warnings)
    reasons = ([f"read stopped: {problem_text(scan)}"] if scan.problem is not None else []) + scan.damage
    if reasons:  # damage found after a complete walk is partial too: messages may be missing
        firsts = [t for t in scan.first.values()]
        lasts = [t for t in scan.last.values()]
        source.partial = True
        source.partial_reason = (
            f"{'; '.join(reasons)}; recovered {scan.messages_read} messages "
            f"({_span_text(min(firsts) if firsts else None, max(lasts) if lasts else None)})"
        )
    if scan.unknown_channel_messages:
        source.skip(
            "(messages of undefined channels)", "no channel record with their channel id", scan.unknown_channel_messages
        )

    topics: dict[str, TopicInfo] = {}
    for cid, channel in scan.channels.items():
        schema = scan.schemas.get(channel.schema_id)
        info = topics.get(channel.topic)
        if info is None:
            info = topics[channel.topic] = TopicInfo(
                name=channel.topic,
                encoding=channel.message_encoding,
                schema=schema.name if schema else "",
            )
        count = scan.counts.get(cid, 0)
        if count:
            info.message_count += count
            first, last = scan.first[cid], scan.last[cid]
            info.first_ns = first if info.first_ns is None else min(info.first_ns, first)
            info.last_ns = last if info.last_ns is None else max(info.last_ns, last)
    source.topics = topics
    return source


class _Decoding(TopicPieces):
    """Decodes the scan's batches each time it is called (`Scan.on_flush`) into channel pieces
    (name -> [(t, values)]); what it skips and the fields it finds go to the log's source at the end
    (`report_to`), since the source is made once the scan is through."""

    def __init__(self, path: str, use_header_stamp: bool):
        super().__init__(path, "mcap", use_header_stamp)
        self.factories = decoder_factories()
        self.decoders: dict[int, tuple[Any, str | None]] = {}  # channel id -> (decoder, why none)
        self.layouts: dict[int, CdrLayout | None] = {}
        # the bulk JSON kernel, or not yet (`logscan.readers.json_template`)
        self.json_tier = JsonTier(tally_file())

    def __call__(self, scan: Scan) -> None:
        batches, scan.batches = scan.batches, {}
        for cid, batch in batches.items():
            channel = scan.channels[cid]
            topic = channel.topic
            schema = scan.schemas.get(channel.schema_id)
            if cid not in self.decoders:
                self.decoders[cid] = _choose_decoder(self.factories, channel, schema)
            decoder, why = self.decoders[cid]
            if decoder is None:
                self.skip_topic(topic, why, batch.count())
                continue
            log_times = np.concatenate(batch.times)
            datas = batch.messages()
            batch.segments = []
            flat, log_times = _columns_of(decoder, channel, schema, datas, log_times, self, self.skips)
            self.add(topic, flat, log_times, stream=cid)

    def fold_into(self, stats: dict[str, ChannelStats]) -> None:
        """Fold the pieces decoded so far into per-channel statistics, and drop them."""
        for name, parts in self.pieces.items():
            entry = stats.setdefault(name, ChannelStats())
            for t, values in parts:
                entry.add(t, values)
        self.pieces = {}


def _columns_of(
    decoder,
    channel: ChannelRec,
    schema: SchemaRec | None,
    datas: MessageBytes,
    log_times: np.ndarray,
    decoding: _Decoding,
    source: SourceInfo,
) -> tuple[FlatColumns, np.ndarray]:
    """Columns of one channel's messages by the fastest path that fits them (CDR layout, bulk JSON,
    the decoder), and the log times of the messages they index (undecodable messages dropped).
    ``decoding``: the read's CDR layouts per schema and its choice of the bulk JSON kernel."""
    topic = channel.topic
    flat = None
    if channel.message_encoding == "cdr" and schema is not None and schema.encoding == "ros2msg":
        layouts = decoding.layouts
        if schema.id not in layouts:
            layouts[schema.id] = cdr_layout(schema)
        if layouts[schema.id] is not None:
            flat = cdr_fast(layouts[schema.id], datas)
    if flat is None and isinstance(decoder, JsonDecoder):
        flat, failed = json_columns(datas, decoding.json_tier)
        if failed:  # message numbers in flat index all messages, so log_times stay aligned
            source.skip(topic, UNDECODED_WHY, len(failed))
    if flat is None:
        messages, failed = _decode_all(decoder, datas.to_list())
        if failed:
            source.skip(topic, UNDECODED_WHY, len(failed))
            keep = np.ones(len(messages), dtype=bool)
            keep[failed] = False
            messages = [m for m, k in zip(messages, keep.tolist()) if k]
            log_times = log_times[keep]
        flat = flatten_messages(messages)
    return flat, log_times


def decoder_factories() -> list:
    """JSON, ROS 2, ROS 1 and protobuf decoder factories, in the order they are tried."""
    from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
    from mcap_ros1.decoder import DecoderFactory as Ros1DecoderFactory
    from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory

    return [JsonDecoderFactory(), Ros2DecoderFactory(), Ros1DecoderFactory(), ProtobufDecoderFactory()]


def _mcap_schema(rec: SchemaRec | None):
    from mcap.records import Schema

    if rec is None:
        return None
    return Schema(id=rec.id, name=rec.name, encoding=rec.encoding, data=rec.data)


def _choose_decoder(factories: list, channel: ChannelRec, schema: SchemaRec | None) -> tuple[Any, str | None]:
    """(decoder, None) or (None, why not)."""
    mcap_schema = _mcap_schema(schema)
    for factory in factories:
        try:
            decoder = factory.decoder_for(channel.message_encoding, mcap_schema)
        except Exception as exc:  # a factory failing on a bad schema is data, not a logscan bug
            return None, f"schema {schema.name if schema else ''!r} cannot be parsed ({type(exc).__name__}: {exc})"
        if decoder is not None:
            return decoder, None
    schema_text = f"schema encoding {schema.encoding!r}" if schema else "no schema"
    return None, f"no decoder for message encoding {channel.message_encoding!r} ({schema_text})"


def _decode_all(decoder, datas: list) -> tuple[list[Any], list[int]]:
    many = getattr(decoder, "decode_many", None)
    if many is not None:
        return many(datas)
    try:
        return [decoder(d) for d in datas], []
    except Exception:  # noqa: BLE001 - retry one by one to find and count the bad messages
        pass
    out: list[Any] = []
    failed: list[int] = []
    for index, data in enumerate(datas):
        try:
            out.append(decoder(data))
        except Exception:  # noqa: BLE001 - undecodable message bytes, counted below
            out.append(None)
            failed.append(index)
    return out, failed


def _span_text(first: int | None, last: int | None) -> str:
    if first is None or last is None:
        return "no time span"
    return f"log_time {first / 1e9:.6f} s .. {last / 1e9:.6f} s"
