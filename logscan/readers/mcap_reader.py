"""MCAP reader: raw records to per-topic message batches, decoded and flattened into channels.

How a file is read
------------------
The whole file is walked linearly, record by record (a numba kernel finds the record boundaries,
numpy gathers channel ids and log times; Python works per chunk and channel, not per message).
This is what the mcap library's streaming reader does too, but it is far faster, and it does not
depend on the summary section, so it reads every conformance file, including the ones whose
summary lacks channel or schema records (where ``mcap.reader.SeekingReader`` raises KeyError).
Chunks are decompressed (lz4, zstd when ``zstandard`` is installed) and their CRC is checked when
it is non-zero; the data-section CRC in the DataEnd record is checked when non-zero.

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
numba kernel (``_cdr_layout``), and JSON messages laid out like their topic's first message are
matched and their numbers parsed in bulk (``json_decoder.json_columns``). Everything else goes through the decoder and
``flatten.flatten_messages``.

Channel names: ``<topic>/<field path>``, where the topic's trailing "/" is dropped before joining,
so ``/imu`` + ``linear_acceleration.x`` -> ``/imu/linear_acceleration.x`` and ``imu`` + ``accel.x``
-> ``imu/accel.x``; arrays index as ``position[2]``. A message that is itself a number gives a
channel named by the topic alone. Each channel has its own timestamps: a variable-length array
index only gets samples from the messages that had it. Channels are sorted by time (stable); a
topic logged out of log_time order gives a warning.

Time: ``log_time`` (int ns). With ``use_header_stamp=True``, messages that have ``header.stamp``
(``sec``/``nanosec`` in ROS 2 and JSON, ``secs``/``nsecs`` in ROS 1) use it instead.

Metadata records logscan writes and reads back (``source.metadata[name]`` holds every record):
 - ``logscan.truth``: key ``json`` -> a JSON document, the ground truth
   (``{"events": [{"start": s, "end": s, "kind": str, "target": str, ...}], ...}``) -> ``Log.truth``.
 - ``logscan.profile``: key ``toml`` -> the profile's TOML text -> ``Log.profile_text``.

``read_mcap_metadata`` gets the metadata records alone: through the summary's MetadataIndex
records when the file has a summary that indexes them all (a few reads at the end of the file),
else by the same walk.

Corrupt files: the walk stops at the first record that is truncated, fails its CRC, fails to
decompress or does not parse. If messages were read before that point the Log is returned with
``source.partial = True`` and ``partial_reason`` saying where it stopped and how many messages
(and what time span) were recovered; otherwise CorruptLogError names the file and the problem.
"""

from __future__ import annotations

import json
import os
import struct
import zlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from logscan.errors import CorruptLogError, InputError
from logscan.log import Channel, Log, SourceInfo, TopicInfo
from logscan.readers import MCAP_MAGIC, topic_wanted
from logscan.readers.flatten import FlatColumns, MessageBytes, flatten_messages
from logscan.readers.json_decoder import JsonDecoder, JsonDecoderFactory, json_columns

TRUTH_RECORD = "logscan.truth"
PROFILE_RECORD = "logscan.profile"

_OP_HEADER = 0x01
_OP_FOOTER = 0x02
_OP_SCHEMA = 0x03
_OP_CHANNEL = 0x04
_OP_MESSAGE = 0x05
_OP_CHUNK = 0x06
_OP_STATISTICS = 0x0B
_OP_METADATA = 0x0C
_OP_METADATA_INDEX = 0x0D
_OP_DATA_END = 0x0F
_MESSAGE_HEADER = 22  # channel_id u16, sequence u32, log_time u64, publish_time u64

# What a corrupt byte stream can make the parsing code raise; anything else is a bug and propagates.
_PARSE_ERRORS = (struct.error, ValueError, UnicodeDecodeError, IndexError, OverflowError, MemoryError)


class _Corrupt(Exception):
    """Internal: the record at ``offset`` is broken; ``reason`` says how.

    ``fatal``: nothing read can be trusted (a data-section CRC mismatch over records that have no
    CRC of their own), so no partial result may be returned.
    """

    def __init__(self, reason: str, offset: int, fatal: bool = False):
        super().__init__(reason)
        self.reason = reason
        self.offset = offset
        self.fatal = fatal


# ---------------------------------------------------------------------------------------------
# record walking


# how a record walk ended
WALK_END = 0  # reached the end of the buffer exactly
WALK_FOOTER = 1  # stopped after a Footer record
WALK_TRUNCATED = 2  # a record header or body runs past the end of the buffer
WALK_BAD_OPCODE = 3  # an opcode the MCAP specification reserves (0x00, 0x10-0x7f): misaligned or corrupt


@njit(cache=True)
def _count_records(buf, start, stop):  # pragma: no cover - compiled
    """Number of whole records in buf[start:stop], the offset where the walk ended, and why."""
    n = 0
    pos = start
    while pos < stop:
        if pos + 9 > stop:
            return n, pos, WALK_TRUNCATED
        op = buf[pos]
        if op == 0 or (op >= 0x10 and op < 0x80):
            return n, pos, WALK_BAD_OPCODE
        if buf[pos + 7] != 0 or buf[pos + 8] != 0:  # length >= 2**48: no real record is that long
            return n, pos, WALK_TRUNCATED
        length = np.int64(0)
        for i in range(6):
            length |= np.int64(buf[pos + 1 + i]) << (8 * i)
        if length > stop - pos - 9:
            return n, pos, WALK_TRUNCATED
        n += 1
        pos += 9 + length
        if op == 2:
            return n, pos, WALK_FOOTER
    return n, pos, WALK_END


@njit(cache=True)
def _fill_records(buf, start, n, ops, offsets, lengths):  # pragma: no cover - compiled
    """Opcode, body offset and body length of the first ``n`` records from ``start``."""
    pos = start
    for k in range(n):
        length = np.int64(0)
        for i in range(6):
            length |= np.int64(buf[pos + 1 + i]) << (8 * i)
        ops[k] = buf[pos]
        offsets[k] = pos + 9
        lengths[k] = length
        pos += 9 + length


_WALK_TEXT = {
    WALK_END: "file ends without a footer (truncated?)",
    WALK_TRUNCATED: "record runs past the end of the file (truncated, or a corrupt record length)",
    WALK_BAD_OPCODE: "invalid record opcode (corrupt bytes)",
}


class _Records(NamedTuple):
    ops: np.ndarray  # uint8
    offsets: np.ndarray  # int64, offset of the record body
    lengths: np.ndarray  # int64, body length
    end: int  # where the walk stopped
    status: int  # WALK_* code


def _walk_records(u8: np.ndarray, start: int, stop: int) -> _Records:
    n, end, status = _count_records(u8, start, stop)
    ops = np.empty(n, dtype=np.uint8)
    offsets = np.empty(n, dtype=np.int64)
    lengths = np.empty(n, dtype=np.int64)
    _fill_records(u8, start, n, ops, offsets, lengths)
    return _Records(ops, offsets, lengths, int(end), int(status))


def _gather_u64(u8: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Little-endian uint64 at each of ``offsets`` in ``u8`` (vectorised)."""
    if offsets.size == 0:
        return np.empty(0, dtype=np.uint64)
    idx = offsets[:, None] + np.arange(8, dtype=np.int64)[None, :]
    return np.ascontiguousarray(u8[idx]).view("<u8").reshape(-1)


def _gather_u16(u8: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    return u8[offsets].astype(np.int64) | (u8[offsets + 1].astype(np.int64) << 8)


def _gather_u32(u8: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    out = np.zeros(offsets.size, dtype=np.int64)
    for i in range(4):
        out |= u8[offsets + i].astype(np.int64) << (8 * i)
    return out


class _Cursor:
    """Field reader over one record body (bounds-checked: a short body raises struct.error)."""

    def __init__(self, data: bytes | memoryview, pos: int, end: int):
        self.data = data
        self.pos = pos
        self.end = end

    def take(self, fmt: str) -> tuple:
        size = struct.calcsize(fmt)
        if self.pos + size > self.end:
            raise struct.error("record shorter than its fields")
        values = struct.unpack_from(fmt, self.data, self.pos)
        self.pos += size
        return values

    def raw(self, size: int) -> bytes:
        if size < 0 or self.pos + size > self.end:
            raise struct.error("record shorter than its fields")
        out = bytes(self.data[self.pos : self.pos + size])
        self.pos += size
        return out

    def string(self) -> str:
        (size,) = self.take("<I")
        return self.raw(size).decode("utf-8")

    def string_map(self) -> dict[str, str]:
        (size,) = self.take("<I")
        stop = self.pos + size
        if stop > self.end:
            raise struct.error("map longer than its record")
        out: dict[str, str] = {}
        while self.pos < stop:
            key = self.string()
            out[key] = self.string()
        if self.pos != stop:
            raise ValueError("map entries overrun the map length")
        return out


@dataclass
class _SchemaRec:
    id: int
    name: str
    encoding: str
    data: bytes


@dataclass
class _ChannelRec:
    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: dict[str, str]


class RawMessage(NamedTuple):
    """One message as stored: topic, channel id, sequence, log and publish time (ns), data bytes."""

    topic: str
    channel_id: int
    sequence: int
    log_time: int
    publish_time: int
    data: bytes


@dataclass
class _Batch:
    """Messages of one channel, per container: log times (int64) and (buffer, starts, ends) segments.

    No Python object per message: the segments point into the decompressed chunk (or the file) and
    ``messages()`` packs them into one ``MessageBytes`` for decoding.
    """

    times: list[np.ndarray] = field(default_factory=list)
    segments: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=list)

    def count(self) -> int:
        return sum(int(seg[1].size) for seg in self.segments)

    def messages(self) -> MessageBytes:
        return MessageBytes(self.segments)


class _Scan:
    """One linear pass over an MCAP file; fills channels, schemas, metadata and message batches."""

    def __init__(self, path: str, wanted: set[str] | None, keep_raw: bool = False):
        self.path = path
        self.wanted = wanted
        self.keep_raw = keep_raw
        self.schemas: dict[int, _SchemaRec] = {}
        self.channels: dict[int, _ChannelRec] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.batches: dict[int, _Batch] = {}
        self.counts: dict[int, int] = {}
        self.first: dict[int, int] = {}
        self.last: dict[int, int] = {}
        self.raw: list[RawMessage] = []
        self.unknown_channel_messages = 0
        self.messages_read = 0
        self.unchecked_records = 0  # schema/channel/message records outside CRC-checked chunks
        self.problem: _Corrupt | None = None
        self.warnings: list[str] = []
        self._wanted_ids: dict[int, bool] = {}

    # -- the pass -------------------------------------------------------------------------------

    def run(self) -> None:
        try:
            with open(self.path, "rb") as fh:
                raw = fh.read()
        except OSError as exc:
            raise InputError(f"cannot read: {exc.strerror}", path=self.path) from None
        if not raw.startswith(MCAP_MAGIC):
            raise CorruptLogError(
                "not an MCAP file (bad magic bytes at offset 0)", path=self.path,
                hint="the file is damaged or not an MCAP log",
            )
        u8 = np.frombuffer(raw, dtype=np.uint8)
        top = _walk_records(u8, len(MCAP_MAGIC), len(raw))
        try:
            self._top_level(raw, u8, top)
        except _PARSE_ERRORS as exc:  # a field inside a record did not parse
            self.problem = _Corrupt(f"malformed record ({type(exc).__name__}: {exc})", -1)
        if self.problem is None and top.status != WALK_FOOTER:
            self.problem = _Corrupt(_WALK_TEXT[top.status], top.end)
        elif self.problem is None and raw[top.end : top.end + 8] != MCAP_MAGIC:
            self.problem = _Corrupt("no closing magic bytes after the footer (truncated?)", top.end)

    def _top_level(self, raw: bytes, u8: np.ndarray, top: _Records) -> None:
        ops = top.ops
        special = np.flatnonzero(np.isin(ops, (_OP_CHUNK, _OP_DATA_END, _OP_FOOTER, _OP_METADATA)))
        # running count of schema / channel / message records, to skip runs without any
        content = np.concatenate([[0], np.cumsum(np.isin(ops, (_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE)))])
        run_start = 0
        for i in special.tolist() + [ops.size]:
            if content[i] > content[run_start]:  # top-level schema / channel / message records
                self._container(raw, u8, ops[run_start:i], top.offsets[run_start:i],
                                top.lengths[run_start:i], checked=False)
            run_start = i + 1
            if i == ops.size:
                return
            op, start, length = int(ops[i]), int(top.offsets[i]), int(top.lengths[i])
            if op == _OP_CHUNK:
                self._chunk(raw, start, length)
            elif op == _OP_METADATA:
                cur = _Cursor(raw, start, start + length)
                name = cur.string()
                self.metadata[name] = cur.string_map()
                self.unchecked_records += 1
            elif op == _OP_DATA_END:
                self._data_end(raw, start, length)
                return
            else:  # footer
                return

    def _chunk(self, raw: bytes, start: int, length: int) -> None:
        cur = _Cursor(raw, start, start + length)
        try:
            _t0, _t1, uncompressed_size, uncompressed_crc = cur.take("<QQQI")
            compression = cur.string()
            (size,) = cur.take("<Q")
            if size > cur.end - cur.pos:
                raise struct.error("chunk records longer than the chunk")
            payload = raw[cur.pos : cur.pos + size]
        except _PARSE_ERRORS as exc:
            raise_corrupt(f"chunk header does not parse ({exc})", start)
        if compression == "":
            data = payload
        else:
            data = _decompress(compression, payload, uncompressed_size, start)
        if len(data) != uncompressed_size:
            raise_corrupt(
                f"chunk holds {len(data)} bytes, its header says {uncompressed_size}", start
            )
        if uncompressed_crc != 0 and zlib.crc32(data) != uncompressed_crc:
            raise_corrupt("chunk CRC mismatch", start)
        u8 = np.frombuffer(data, dtype=np.uint8)
        inner = _walk_records(u8, 0, len(data))
        if inner.status != WALK_END:
            raise_corrupt("records inside a chunk do not fill it (corrupt chunk)", start)
        self._container(data, u8, inner.ops, inner.offsets, inner.lengths, checked=uncompressed_crc != 0)

    def _data_end(self, raw: bytes, start: int, length: int) -> None:
        (expected,) = _Cursor(raw, start, start + length).take("<I")
        if expected == 0:
            return
        actual = zlib.crc32(memoryview(raw)[: start - 9])
        if actual == expected:
            return
        if self.unchecked_records == 0:
            # every schema, channel and message came from a chunk whose own CRC matched: the
            # damage is in chunk headers or message indexes, which the messages do not depend on.
            self.warnings.append(
                "data section CRC mismatch outside the message chunks; every message comes from "
                "a chunk whose own CRC matches"
            )
            return
        raise _Corrupt("data section CRC mismatch (the data section is corrupt)", start - 9, fatal=True)

    def _container(self, data, u8, ops, offsets, lengths, *, checked: bool) -> None:
        """Schema, channel and message records of one chunk (or one run of top-level records)."""
        is_message = ops == _OP_MESSAGE
        if not checked:
            self.unchecked_records += int(np.count_nonzero(np.isin(ops, (_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE))))
        # schema and channel records are few: register them in order before the messages
        for k in np.flatnonzero((ops == _OP_SCHEMA) | (ops == _OP_CHANNEL)).tolist():
            start, length = int(offsets[k]), int(lengths[k])
            cur = _Cursor(data, start, start + length)
            try:
                if ops[k] == _OP_SCHEMA:
                    (sid,) = cur.take("<H")
                    name = cur.string()
                    encoding = cur.string()
                    (size,) = cur.take("<I")
                    self.schemas[sid] = _SchemaRec(sid, name, encoding, cur.raw(size))
                else:
                    cid, sid = cur.take("<HH")
                    topic = cur.string()
                    encoding = cur.string()
                    meta = cur.string_map()
                    self.channels[cid] = _ChannelRec(cid, sid, topic, encoding, meta)
                    self._wanted_ids.pop(cid, None)
            except _PARSE_ERRORS as exc:
                raise_corrupt(f"schema/channel record does not parse ({exc})", start)
        if not is_message.any():
            return
        m_off = offsets[is_message]
        m_len = lengths[is_message]
        if (m_len < _MESSAGE_HEADER).any():
            raise_corrupt("message record shorter than its header", int(m_off[m_len < _MESSAGE_HEADER][0]))
        channel_ids = _gather_u16(u8, m_off)
        log_times = _gather_u64(u8, m_off + 6).astype(np.int64)
        self.messages_read += int(m_off.size)
        for cid in np.unique(channel_ids).tolist():
            select = channel_ids == cid
            channel = self.channels.get(cid)
            if channel is None:
                self.unknown_channel_messages += int(np.count_nonzero(select))
                continue
            times = log_times[select]
            self.counts[cid] = self.counts.get(cid, 0) + int(times.size)
            low, high = int(times.min()), int(times.max())
            self.first[cid] = min(self.first.get(cid, low), low)
            self.last[cid] = max(self.last.get(cid, high), high)
            if not self._is_wanted(cid):
                continue
            batch = self.batches.setdefault(cid, _Batch())
            batch.times.append(times)
            batch.segments.append((u8, m_off[select] + _MESSAGE_HEADER, m_off[select] + m_len[select]))
        if self.keep_raw:
            sequences = _gather_u32(u8, m_off + 2).tolist()
            publish = _gather_u64(u8, m_off + 14).astype(np.int64).tolist()
            for k, cid in enumerate(channel_ids.tolist()):
                channel = self.channels.get(cid)
                start, stop = int(m_off[k]) + _MESSAGE_HEADER, int(m_off[k] + m_len[k])
                self.raw.append(RawMessage(
                    channel.topic if channel else "", cid, sequences[k],
                    int(log_times[k]), publish[k], bytes(data[start:stop]),
                ))

    def _is_wanted(self, cid: int) -> bool:
        known = self._wanted_ids.get(cid)
        if known is None:
            known = self._wanted_ids[cid] = topic_wanted(self.channels[cid].topic, self.wanted)
        return known


def raise_corrupt(reason: str, offset: int) -> None:
    raise _Corrupt(reason, offset)


def _decompress(compression: str, payload: bytes, size: int, offset: int) -> bytes:
    if compression == "lz4":
        import lz4.frame

        try:
            return lz4.frame.decompress(payload)
        except RuntimeError as exc:  # lz4 raises RuntimeError on bad frames
            raise_corrupt(f"lz4 chunk does not decompress ({exc})", offset)
    if compression == "zstd":
        try:
            import zstandard
        except ImportError:
            raise_corrupt("zstd-compressed chunk and the zstandard package is not installed", offset)
        try:
            return zstandard.ZstdDecompressor().decompress(payload, max_output_size=size)
        except zstandard.ZstdError as exc:
            raise_corrupt(f"zstd chunk does not decompress ({exc})", offset)
    raise_corrupt(f"unsupported chunk compression {compression[:40]!r}", offset)
    raise AssertionError("unreachable")


def _scan(path: str, wanted: set[str] | None, keep_raw: bool) -> _Scan:
    scan = _Scan(path, wanted, keep_raw)
    try:
        scan.run()
    except _Corrupt as exc:
        scan.problem = exc
    return scan


def _problem_text(scan: _Scan) -> str:
    problem = scan.problem
    assert problem is not None
    where = f" at byte {problem.offset}" if problem.offset >= 0 else ""
    return f"{problem.reason}{where}"


def iter_raw_messages(path: str | os.PathLike) -> Iterator[RawMessage]:
    """Every message of the file in file order, undecoded (the layer ``read_mcap`` is built on).

    Raises CorruptLogError when the file is corrupt anywhere (this strict view is for checking
    files; ``read_mcap`` instead keeps what precedes the damage).
    """
    scan = _scan(str(path), None, keep_raw=True)
    if scan.problem is not None:
        raise CorruptLogError(_problem_text(scan), path=str(path))
    yield from scan.raw


# ---------------------------------------------------------------------------------------------
# decoding


def decoder_factories() -> list:
    """JSON, ROS 2, ROS 1 and protobuf decoder factories, in the order they are tried."""
    from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
    from mcap_ros1.decoder import DecoderFactory as Ros1DecoderFactory
    from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory

    return [JsonDecoderFactory(), Ros2DecoderFactory(), Ros1DecoderFactory(), ProtobufDecoderFactory()]


def _mcap_schema(rec: _SchemaRec | None):
    from mcap.records import Schema

    if rec is None:
        return None
    return Schema(id=rec.id, name=rec.name, encoding=rec.encoding, data=rec.data)


def _choose_decoder(factories: list, channel: _ChannelRec, schema: _SchemaRec | None):
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


_STAMP_FIELDS = (
    ("header.stamp.sec", "header.stamp.nanosec"),
    ("header.stamp.secs", "header.stamp.nsecs"),
)


def _header_stamps(columns: dict, log_times: np.ndarray) -> tuple[np.ndarray, bool]:
    """Per-message time: header.stamp where the message has it, else log_time."""
    for sec_name, nsec_name in _STAMP_FIELDS:
        if sec_name in columns and nsec_name in columns:
            sec_idx, sec = columns[sec_name]
            nsec_idx, nsec = columns[nsec_name]
            both, in_sec, in_nsec = np.intersect1d(sec_idx, nsec_idx, return_indices=True)
            times = log_times.copy()
            # t = sec * 1e9 + nanosec, in integer ns
            times[both] = sec[in_sec].astype(np.int64) * 1_000_000_000 + nsec[in_nsec].astype(np.int64)
            return times, both.size > 0
    return log_times, False


def _channel_name(topic: str, path: str) -> str:
    if not path:
        return topic
    return topic.rstrip("/") + "/" + path


def _span_text(first: int | None, last: int | None) -> str:
    if first is None or last is None:
        return "no time span"
    return f"log_time {first / 1e9:.6f} s .. {last / 1e9:.6f} s"


# ---------------------------------------------------------------------------------------------
# ROS 2 CDR without per-message Python: a layout program run by a numba kernel


class _Unsupported(Exception):
    """The ROS 2 definition has something the fast CDR path does not handle (it falls back)."""


# primitive -> (size in bytes, type code for the kernel); uint8/byte arrays decode as bytes
_CDR_PRIMITIVES = {
    "bool": (1, 1), "byte": (1, 1), "uint8": (1, 1), "char": (1, 2), "int8": (1, 2),
    "uint16": (2, 3), "int16": (2, 4), "uint32": (4, 5), "int32": (4, 6),
    "uint64": (8, 7), "int64": (8, 8), "float32": (4, 9), "float64": (8, 10),
}
_OP_VALUE, _OP_STRING, _OP_SKIP = 0, 1, 2


class _CdrLayout(NamedTuple):
    kinds: np.ndarray
    sizes: np.ndarray
    codes: np.ndarray
    columns: np.ndarray
    paths: list[str]
    skipped: list[str]


def _cdr_layout(schema: _SchemaRec) -> _CdrLayout | None:
    """Program for messages whose fields are primitives, strings and fixed-size arrays, else None."""
    try:
        from mcap_ros2._dynamic import TimeDefinition, _for_each_msgdef
    except ImportError:  # the private helpers moved: the decoder path still works
        return None
    msgdefs: dict[str, Any] = {"builtin_interfaces/Time": TimeDefinition,
                               "builtin_interfaces/Duration": TimeDefinition}

    def keep(full_name: str, short_name: str, msgdef: Any) -> None:
        msgdefs[full_name] = msgdef
        msgdefs[short_name] = msgdef

    try:
        _for_each_msgdef(schema.name, schema.data.decode("utf-8"), keep)
    except Exception:  # noqa: BLE001 - an unparsable schema is reported by the decoder path
        return None
    program: list[tuple[int, int, int, int]] = []
    paths: list[str] = []
    skipped: list[str] = []

    def build(msgdef: Any, prefix: str, depth: int) -> None:
        if depth > 32:
            raise _Unsupported("nesting too deep")
        if not msgdef.fields:
            program.append((_OP_VALUE, 1, 1, -1))  # the placeholder uint8 of an empty message
        for fld in msgdef.fields:
            ftype = fld.type
            name = prefix + fld.name
            if ftype.is_array and not ftype.is_fixed_size_array():
                raise _Unsupported("variable-length array")
            count = ftype.array_size if ftype.is_array else None
            names = [name] if count is None else [f"{name}[{i}]" for i in range(count)]
            if not ftype.is_primitive_type():
                sub = msgdefs.get(f"{ftype.pkg_name}/{ftype.type}")
                if sub is None:
                    raise _Unsupported("unknown nested type")
                for item in names:
                    build(sub, item + ".", depth + 1)
            elif ftype.type == "string":
                for item in names:
                    program.append((_OP_STRING, 4, 0, -1))
                    skipped.append(item)
            elif ftype.type in ("uint8", "byte") and count is not None:
                program.append((_OP_SKIP, count, 0, -1))
                skipped.append(name)
            elif ftype.type in _CDR_PRIMITIVES:
                size, code = _CDR_PRIMITIVES[ftype.type]
                for item in names:
                    program.append((_OP_VALUE, size, code, len(paths)))
                    paths.append(item)
            else:
                raise _Unsupported(f"type {ftype.type}")

    root = msgdefs.get(schema.name)
    if root is None:
        return None
    try:
        build(root, "", 0)
    except _Unsupported:
        return None
    table = np.array(program, dtype=np.int64).reshape(-1, 4)
    return _CdrLayout(table[:, 0].copy(), table[:, 1].copy(), table[:, 2].copy(), table[:, 3].copy(),
                      paths, skipped)


@njit(cache=True)
def _cdr_run(buf, starts, ends, kinds, sizes, codes, columns, out):  # pragma: no cover - compiled
    """Run the layout program over each message; False when a message does not fit it."""
    word = np.zeros(1, dtype=np.uint64)
    as_f64 = word.view(np.float64)
    half = np.zeros(1, dtype=np.uint32)
    as_f32 = half.view(np.float32)
    for m in range(starts.size):
        start = starts[m]
        end = ends[m]
        if end - start < 4 or buf[start] != 0 or buf[start + 1] != 1:  # CDR little endian only
            return False
        base = start + 4
        pos = base
        for k in range(kinds.size):
            kind = kinds[k]
            size = sizes[k]
            if kind == 0:
                if size > 1 and (pos - base) % size != 0:  # align to the value's own size
                    pos += size - (pos - base) % size
                if pos + size > end:
                    return False
                raw = np.uint64(0)
                for i in range(size):
                    raw |= np.uint64(buf[pos + i]) << np.uint64(8 * i)
                code = codes[k]
                if code == 10:
                    word[0] = raw
                    value = as_f64[0]
                elif code == 9:
                    half[0] = np.uint32(raw)
                    value = np.float64(as_f32[0])
                elif code == 1 or code == 3 or code == 5:
                    value = np.float64(raw)
                elif code == 7:
                    value = np.float64(raw)
                elif code == 8:
                    value = np.float64(np.int64(raw))
                else:  # signed 1, 2 or 4 bytes: two's complement
                    bits = 8 * size
                    signed = np.int64(raw)
                    if signed >= (np.int64(1) << (bits - 1)):
                        signed -= np.int64(1) << bits
                    value = np.float64(signed)
                if columns[k] >= 0:
                    out[m, columns[k]] = value
                pos += size
            elif kind == 1:
                if (pos - base) % 4 != 0:
                    pos += 4 - (pos - base) % 4
                if pos + 4 > end:
                    return False
                length = np.int64(buf[pos]) | (np.int64(buf[pos + 1]) << 8) | (np.int64(buf[pos + 2]) << 16) | (np.int64(buf[pos + 3]) << 24)
                pos += 4 + length
                if pos > end:
                    return False
            else:
                pos += size
                if pos > end:
                    return False
    return True


def _cdr_fast(layout: _CdrLayout, datas: MessageBytes | Sequence[bytes]) -> FlatColumns | None:
    """Columns of CDR messages decoded by the layout program, or None if one does not fit."""
    packed = datas if isinstance(datas, MessageBytes) else MessageBytes.from_list(datas)
    n = len(packed)
    out = np.empty((n, len(layout.paths)), dtype=np.float64)
    for (buf, starts, ends), row in zip(packed.parts, packed.first.tolist()):
        if not _cdr_run(buf, starts, ends, layout.kinds, layout.sizes, layout.codes, layout.columns,
                        out[row : row + starts.size]):
            return None
    flat = FlatColumns()
    every = np.arange(n, dtype=np.int64)
    for column, path in enumerate(layout.paths):
        flat.columns[path] = (every, np.ascontiguousarray(out[:, column]))
        flat.fields.append(path)
    for path in layout.skipped:
        flat.skipped[(path, "non-numeric")] = n
    return flat


# ---------------------------------------------------------------------------------------------
# the reader


def read_mcap(path: str | os.PathLike, wanted: set[str] | None, *, use_header_stamp: bool = False) -> Log:
    """Read the MCAP file ``path`` into a Log, decoding only topics ``topic_wanted`` keeps."""
    path = str(path)
    scan = _scan(path, wanted, keep_raw=False)
    _raise_if_unrecoverable(scan)
    source = SourceInfo(path=path, format="mcap")
    source.metadata = dict(scan.metadata)
    source.warnings.extend(scan.warnings)
    if scan.problem is not None:
        firsts = [t for t in scan.first.values()]
        lasts = [t for t in scan.last.values()]
        source.partial = True
        source.partial_reason = (
            f"read stopped: {_problem_text(scan)}; recovered {scan.messages_read} messages "
            f"({_span_text(min(firsts) if firsts else None, max(lasts) if lasts else None)})"
        )
    if scan.unknown_channel_messages:
        source.skip("(messages of undefined channels)", "no channel record with their channel id",
                    scan.unknown_channel_messages)

    topics: dict[str, TopicInfo] = {}
    for cid, channel in scan.channels.items():
        schema = scan.schemas.get(channel.schema_id)
        info = topics.get(channel.topic)
        if info is None:
            info = topics[channel.topic] = TopicInfo(
                name=channel.topic, encoding=channel.message_encoding,
                schema=schema.name if schema else "",
            )
        count = scan.counts.get(cid, 0)
        if count:
            info.message_count += count
            first, last = scan.first[cid], scan.last[cid]
            info.first_ns = first if info.first_ns is None else min(info.first_ns, first)
            info.last_ns = last if info.last_ns is None else max(info.last_ns, last)
    source.topics = topics

    factories = decoder_factories()
    layouts: dict[int, _CdrLayout | None] = {}
    pieces: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    undecodable: list[str] = []
    stamp_topics: set[str] = set()
    decoded_topics: set[str] = set()
    for cid, batch in scan.batches.items():
        channel = scan.channels[cid]
        topic = channel.topic
        decoder, why = _choose_decoder(factories, channel, scan.schemas.get(channel.schema_id))
        if decoder is None:
            source.skip(topic, why, batch.count())
            undecodable.append(topic)
            continue
        log_times = np.concatenate(batch.times)
        datas = batch.messages()
        batch.segments = []
        flat = None
        schema = scan.schemas.get(channel.schema_id)
        if channel.message_encoding == "cdr" and schema is not None and schema.encoding == "ros2msg":
            if schema.id not in layouts:
                layouts[schema.id] = _cdr_layout(schema)
            if layouts[schema.id] is not None:
                flat = _cdr_fast(layouts[schema.id], datas)
        if flat is None and isinstance(decoder, JsonDecoder):
            flat, failed = json_columns(datas)
            if failed:  # message numbers in flat index all messages, so log_times stay aligned
                source.skip(topic, "message bytes do not decode", len(failed))
        if flat is None:
            messages, failed = _decode_all(decoder, datas.to_list())
            if failed:
                source.skip(topic, "message bytes do not decode", len(failed))
                keep = np.ones(len(messages), dtype=bool)
                keep[failed] = False
                messages = [m for m, k in zip(messages, keep.tolist()) if k]
                log_times = log_times[keep]
            flat = flatten_messages(messages)
        decoded_topics.add(topic)
        for (field_path, why_skipped), count in flat.skipped.items():
            source.skip(_channel_name(topic, field_path), why_skipped, count)
        times = log_times
        if use_header_stamp:
            times, used = _header_stamps(flat.columns, log_times)
            if used:
                stamp_topics.add(topic)
        info = topics[topic]
        for field_path in flat.fields:
            if field_path not in info.fields:
                info.fields.append(field_path)
            index, values = flat.columns[field_path]
            pieces.setdefault(_channel_name(topic, field_path), []).append((times[index], values))

    channels: dict[str, Channel] = {}
    unsorted_topics: set[str] = set()
    for name, parts in pieces.items():
        t = parts[0][0] if len(parts) == 1 else np.concatenate([p[0] for p in parts])
        v = parts[0][1] if len(parts) == 1 else np.concatenate([p[1] for p in parts])
        if t.size > 1 and (np.diff(t) < 0).any():
            order = np.argsort(t, kind="stable")
            t, v = t[order], v[order]
            unsorted_topics.add(name)
        channels[name] = Channel(name, t, v)
    if unsorted_topics:
        source.warnings.append(
            f"{len(unsorted_topics)} channel(s) not in time order in the file, sorted by time: "
            + ", ".join(sorted(unsorted_topics)[:5]) + (" ..." if len(unsorted_topics) > 5 else "")
        )
    if undecodable:
        source.warnings.append("topics skipped (no decoder): " + ", ".join(sorted(set(undecodable))))
    if use_header_stamp:
        missing = sorted(decoded_topics - stamp_topics)
        if stamp_topics and not missing:
            source.time_source = "header.stamp"
        elif stamp_topics:
            source.time_source = "header.stamp (log_time for " + ", ".join(missing) + ")"
        else:
            source.time_source = "log_time (no header.stamp found)"

    log = Log(channels=channels, source=source)
    attach_logscan_records(log)
    return log


def _raise_if_unrecoverable(scan: _Scan) -> None:
    """CorruptLogError when the walk stopped before any message, or nothing it read can be trusted."""
    if scan.problem is not None and (scan.messages_read == 0 or scan.problem.fatal):
        lost = "nothing read can be trusted" if scan.problem.fatal else "no messages could be recovered"
        raise CorruptLogError(
            f"corrupt MCAP: {_problem_text(scan)}; {lost}",
            path=scan.path, hint="the file is damaged; re-export or re-record it",
        )


# ---------------------------------------------------------------------------------------------
# metadata without the messages


def read_mcap_metadata(path: str | os.PathLike) -> dict[str, dict[str, str]]:
    """Metadata records of the MCAP file ``path`` (name -> key/value map), without its messages.

    When the file ends in a footer whose summary indexes every metadata record (MetadataIndex
    records; a Statistics record, if any, counts as many), only the footer, the summary and the
    indexed records are read, and checked: both magics, the footer's framing, the summary CRC
    (when non-zero), the summary's record framing, and each indexed record's place (inside the
    data section), opcode, length and name. Metadata records have no CRC of their own and the
    data-section CRC would need the whole file, so this path does not check it (``read_mcap`` does).
    Otherwise (no summary, no index, a check failing) the whole file is walked as ``read_mcap``
    walks it: same result as ``read_mcap(path, set()).source.metadata``, and CorruptLogError where
    that raises it.
    """
    path = str(path)
    try:
        with open(path, "rb") as fh:
            indexed = _indexed_metadata(fh)
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=path) from None
    if indexed is not None:
        return indexed
    scan = _scan(path, set(), keep_raw=False)
    _raise_if_unrecoverable(scan)
    return dict(scan.metadata)


_FOOTER_RECORD = 9 + 20  # opcode, length, summary_start u64, summary_offset_start u64, summary_crc u32


def _indexed_metadata(fh) -> dict[str, dict[str, str]] | None:
    """Metadata through the summary's MetadataIndex records, or None when they cannot be trusted."""
    size = fh.seek(0, os.SEEK_END)
    footer_at = size - len(MCAP_MAGIC) - _FOOTER_RECORD
    if footer_at < len(MCAP_MAGIC):
        return None
    fh.seek(0)
    if fh.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
        return None
    fh.seek(footer_at)
    tail = fh.read(_FOOTER_RECORD + len(MCAP_MAGIC))
    if tail[0] != _OP_FOOTER or tail[1:9] != struct.pack("<Q", 20) or tail[_FOOTER_RECORD:] != MCAP_MAGIC:
        return None
    summary_start, _offsets_start, summary_crc = struct.unpack_from("<QQI", tail, 9)
    if not len(MCAP_MAGIC) < summary_start <= footer_at:
        return None  # 0: no summary section
    fh.seek(summary_start)
    summary = fh.read(footer_at - summary_start)
    # the CRC covers the summary section and the footer up to summary_crc
    if summary_crc != 0 and zlib.crc32(tail[:25], zlib.crc32(summary)) != summary_crc:
        return None
    records = _walk_records(np.frombuffer(summary, dtype=np.uint8), 0, len(summary))
    if records.status != WALK_END:
        return None
    indexes: list[tuple[int, int, str]] = []
    counted: int | None = None
    try:
        for op, start, length in zip(records.ops.tolist(), records.offsets.tolist(), records.lengths.tolist()):
            cur = _Cursor(summary, start, start + length)
            if op == _OP_METADATA_INDEX:
                offset, record_length = cur.take("<QQ")
                indexes.append((offset, record_length, cur.string()))
            elif op == _OP_STATISTICS:
                counted = cur.take("<QHIIII")[4]  # message, schema, channel, attachment, metadata counts
        if (not indexes and counted != 0) or (counted is not None and counted != len(indexes)):
            return None  # the summary does not account for every metadata record
        out: dict[str, dict[str, str]] = {}
        for offset, record_length, name in indexes:
            if offset < len(MCAP_MAGIC) or record_length < 9 or offset + record_length > summary_start:
                return None
            fh.seek(offset)
            record = fh.read(record_length)
            if record[0] != _OP_METADATA or struct.unpack_from("<Q", record, 1)[0] != record_length - 9:
                return None
            cur = _Cursor(record, 9, record_length)
            if cur.string() != name:
                return None
            out[name] = cur.string_map()
    except _PARSE_ERRORS:
        return None
    return out


def attach_logscan_records(log: Log) -> None:
    """Ground truth and embedded profile from the ``logscan.truth`` / ``logscan.profile`` records."""
    meta = log.source.metadata
    truth = meta.get(TRUTH_RECORD)
    if truth is not None:
        try:
            log.truth = json.loads(truth["json"])
        except (KeyError, ValueError) as exc:
            log.source.warnings.append(f"metadata record {TRUTH_RECORD!r} ignored: no valid 'json' key ({exc})")
    profile = meta.get(PROFILE_RECORD)
    if profile is not None:
        if "toml" in profile:
            log.profile_text = profile["toml"]
        else:
            log.source.warnings.append(f"metadata record {PROFILE_RECORD!r} ignored: no 'toml' key")
