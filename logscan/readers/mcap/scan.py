"""The scan: one linear pass over an MCAP file (chunks decompressed, CRCs checked) into raw message batches.

Chunks are decompressed (lz4, zstd when ``zstandard`` is installed) and their CRC is checked when
it is non-zero; the data-section CRC in the DataEnd record is checked when non-zero. Messages are
never sliced one by one: each wanted channel keeps (buffer, starts, ends) segments into the
decompressed chunk or the file.

Corrupt files: the walk stops at the first top-level record that is truncated or does not parse;
``Scan.problem`` says where and why, and the messages read before it are kept. A chunk that
fails its CRC, fails to decompress, is over a decompression cap or whose records do not parse is
skipped (its messages are lost) and the walk goes on: the read is partial (``Scan.damage`` counts
the chunks skipped and says why). Damage found once the walk is through makes the read partial
too: a data-section CRC mismatch, a summary Statistics record counting other numbers of messages
or chunks than the data section holds, messages on a channel id no Channel record defines (they
are dropped and counted), and a channel or schema id defined twice with different content (the
first definition is kept; the messages of the chunk holding the second are counted). Records with
an opcode the spec leaves to private use (0x80-0xff) are skipped, as the spec says; a chunk whose
opcode byte is damaged looks exactly like one, so only that evidence can tell.

Bounded decompression, by what is produced (never by a ratio, which refuses real payloads: a
4 MB message of zeros is 130 bytes of zstd): chunks are decompressed a piece of
``INFLATE_STEP`` bytes at a time into a buffer whose pages are only touched as they are written,
counting the bytes as they come. A chunk stops (skipped as damaged) as soon as it produces more
than its header declares, more than ``MAX_CHUNK_BYTES``, or more than the file's budget left
(``max(MIN_FILE_BUDGET_BYTES, MAX_RATIO x the file size)`` for all its chunks); a chunk declaring
more than either cap is skipped before it is decompressed. So a lie costs at most what the frame
really produces up to the cap, and a bomb stops at the budget. Attachment records are never
decompressed or copied (the walk steps over them).

Bounded memory: the file is mapped, not read, and the pages already handed on are given back
(``madvise``); with ``Scan.on_flush`` set, the batches are handed to it (the reader decodes them)
whenever the chunks held for them pass ``FLUSH_BYTES``. Memory then follows the decoded columns
and a few chunks, not the file (a 1-hour log's 146 MB file was held whole before). A few MiB, not
tens: the chunks are decoded while they are still in the CPU's cache (at 32 MiB the CDR kernel of
the 1-hour log took twice as long, waiting on memory).
"""

from __future__ import annotations

import mmap
import os
import struct
import zlib
from collections.abc import Callable, Iterator

import numpy as np

from logscan.errors import CorruptLogError
from logscan.memory import drop_mapped_pages
from logscan.readers.common import MCAP_MAGIC, input_error, stat_input, topic_wanted
from logscan.readers.mcap.inflate import InflateError, inflate
from logscan.readers.mcap.records import (
    CHANNEL_IDS,
    MESSAGE_HEADER,
    OP_CHANNEL,
    OP_CHUNK,
    OP_DATA_END,
    OP_FOOTER,
    OP_MESSAGE,
    OP_METADATA,
    OP_SCHEMA,
    PARSE_ERRORS,
    WALK_BAD_OPCODE,
    WALK_END,
    WALK_FOOTER,
    WALK_TEXT,
    Cursor,
    Records,
    gather_u32,
    gather_u64,
    group_messages,
    walk_records,
)
from logscan.readers.mcap.scan_damage import (
    chunk_damage,
    data_section_damage,
    problem_text,
    statistics_damage,
)
from logscan.readers.mcap.scan_records import (
    ChannelRec,
    RawMessage,
    SchemaRec,
    _Batch,
    _claimed_end,
    _Corrupt,
    _map_file,
    _private_records,
    raise_corrupt,
)

# Decompression caps, on bytes produced. MCAP writers make chunks of 1-4 MiB (a chunk holds at least
# one message: a point cloud or an image may make it tens of MB); 512 MiB per chunk keeps a run under
# 2 GB whatever a file declares.
MAX_CHUNK_BYTES = 512 << 20  # one chunk never decompresses to more
MAX_RATIO = 1000  # the chunks of a file decompress to at most this times its size in all ...
MIN_FILE_BUDGET_BYTES = 1 << 30  # ... or this, whichever is larger
FLUSH_BYTES = 4 << 20  # message bytes held in batches before they are handed to ``on_flush``
TOP_LEVEL_SLICE = 1 << 16  # top-level records handled at a time (unchunked files)
WALK_WINDOW = 32 << 20  # bytes of the file walked for record boundaries before their pages go back


class Scan:
    """One linear pass over an MCAP file; fills channels, schemas, metadata and message batches."""

    def __init__(self, path: str, wanted: set[str] | None, keep_raw: bool = False):
        self.path = path
        self.wanted = wanted
        self.keep_raw = keep_raw
        self.schemas: dict[int, SchemaRec] = {}
        self.channels: dict[int, ChannelRec] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.batches: dict[int, _Batch] = {}
        self.counts: dict[int, int] = {}
        self.first: dict[int, int] = {}
        self.last: dict[int, int] = {}
        self.raw: list[RawMessage] = []
        self.unknown_channel_messages = 0
        self.skipped_chunks: list[tuple[int, str]] = []  # (offset, why) of the damaged chunks skipped
        self.redefined: list[str] = []  # channel / schema ids defined twice differently: what and where
        self.redefined_messages = 0  # messages of the chunks that redefine their channel
        self.beyond_int64 = 0  # messages dropped: a log_time int64 nanoseconds cannot hold
        self.messages_read = 0
        self.chunks_read = 0
        self.unchecked_records = 0  # schema/channel/message records outside CRC-checked chunks
        self.problem: _Corrupt | None = None
        self.damage: list[str] = []  # damage that did not stop the walk: the read is partial all the same
        self.warnings: list[str] = []
        self._wanted_ids: dict[int, bool] = {}
        self._slot = np.full(CHANNEL_IDS, -1, dtype=np.int64)  # `group_messages`' scratch, one per channel id
        self._inflate_budget = MIN_FILE_BUDGET_BYTES  # bytes the file's chunks may still decompress to
        self.on_flush: Callable[[Scan], None] | None = None  # takes (and empties) the batches
        self.on_position: Callable[[int], None] | None = None  # hears the file offset scanned to, per chunk
        # the body offsets of the only chunks to decode (a window's: `window.plan_window`), chosen
        # by ``plan`` from the top-level records once the summary's definitions are in; None: all
        self.plan: Callable[[Scan, np.ndarray, Records], set[int] | None] | None = None
        self.window_chunks: set[int] | None = None
        self.known_top: Records | None = None  # the top-level records a window read of the file found
        # channel id -> (messages, first, last log time) of the whole file, from its index: a
        # window's read counts what it did not decode as the whole read would
        self.window_totals: dict[int, tuple[int, int, int]] = {}
        self.counts_read: dict[int, int] = {}  # a window's: messages per channel in the chunks read
        self._held = 0  # message bytes in the batches since the last flush
        self._map: mmap.mmap | None = None

    # -- the pass -------------------------------------------------------------------------------

    def run(self) -> None:
        stat_input(self.path)  # a FIFO or device is refused before it is opened
        try:
            with open(self.path, "rb") as fh:
                raw = _map_file(fh)
        except OSError as exc:
            raise input_error(exc, self.path) from None
        self._map = raw if isinstance(raw, mmap.mmap) else None
        if raw[: len(MCAP_MAGIC)] != MCAP_MAGIC:
            raise CorruptLogError(
                "not an MCAP file (bad magic bytes at offset 0)",
                path=self.path,
                hint="the file is damaged or not an MCAP log",
            )
        self._inflate_budget = max(MIN_FILE_BUDGET_BYTES, MAX_RATIO * len(raw))
        u8 = np.frombuffer(raw, dtype=np.uint8)
        top = self.known_top if self.known_top is not None else self._walk(u8, len(MCAP_MAGIC), len(raw))
        self._summary_definitions(raw, u8, top)
        if self.plan is not None:
            self.window_chunks = self.plan(self, u8, top)
            self.give_back(len(raw))  # the index pages the plan read
        try:
            self._top_level(raw, u8, top)
        except PARSE_ERRORS as exc:  # a field inside a record did not parse
            self.problem = _Corrupt(f"malformed record ({type(exc).__name__}: {exc})", -1)
        if self.window_chunks is not None:
            self.counts_read = self.counts
            self.counts = {cid: total[0] for cid, total in self.window_totals.items()}
            self.first = {cid: total[1] for cid, total in self.window_totals.items()}
            self.last = {cid: total[2] for cid, total in self.window_totals.items()}
        if self.problem is None and top.status != WALK_FOOTER:
            self.problem = _Corrupt(WALK_TEXT[top.status], top.end)
        elif self.problem is None and raw[top.end : top.end + 8] != MCAP_MAGIC:
            self.problem = _Corrupt("no closing magic bytes after the footer (truncated?)", top.end)

    def _summary_definitions(self, raw: bytes, u8: np.ndarray, top: Records) -> None:
        """Schema and Channel records of the summary section (after DataEnd), registered first: the
        messages of a channel whose data-section definition lies in a skipped chunk are still read,
        and a damaged definition in the data section conflicts with them (damage). A summary that
        does not parse is not used."""
        ends = np.flatnonzero(top.ops == OP_DATA_END)
        if not ends.size:
            return
        after = slice(int(ends[0]) + 1, None)
        ops = top.ops[after]
        keep = (ops == OP_SCHEMA) | (ops == OP_CHANNEL)
        if not keep.any():
            return
        try:
            self._container(raw, u8, ops[keep], top.offsets[after][keep], top.lengths[after][keep], checked=True)
        except (_Corrupt, *PARSE_ERRORS):
            self.schemas.clear()
            self.channels.clear()
            self.redefined.clear()
            self.warnings.append("the summary section's Schema/Channel records do not parse: not used")

    def give_back(self, stop: int) -> None:
        """Drop the mapped file's pages before ``stop`` from this process (they are read again
        from the page cache if touched): RSS follows what is in hand, not the file."""
        if self._map is not None:
            drop_mapped_pages(self._map, stop)

    def _walk(self, u8: np.ndarray, start: int, stop: int) -> Records:
        """`walk_records` over the file a window at a time, giving back the pages walked: reading a
        record's header maps the whole folio around it (up to megabytes), so one walk over the file
        would hold all of it. Same records, end and status as a single walk."""
        parts = []
        pos = start
        while True:
            window = min(stop, max(pos + WALK_WINDOW, _claimed_end(u8, pos, stop)))
            part = walk_records(u8, pos, window)
            parts.append(part)
            self.give_back(window)
            if window >= stop or part.status in (WALK_FOOTER, WALK_BAD_OPCODE) or part.end == pos:
                break
            pos = part.end  # a record crossing the window is walked again in the next one
        if len(parts) == 1:
            return parts[0]
        return Records(
            np.concatenate([p.ops for p in parts]),
            np.concatenate([p.offsets for p in parts]),
            np.concatenate([p.lengths for p in parts]),
            parts[-1].end,
            parts[-1].status,
        )

    def _held_more(self, size: int, position: int) -> None:
        """``size`` more message bytes in the batches; past FLUSH_BYTES they go to ``on_flush``.
        Called once per chunk (or slice of top-level records) ending at file offset ``position``,
        never per message: ``on_position`` hears it here."""
        self._held += size
        if self._held >= FLUSH_BYTES:
            self.flush()
            self.give_back(position)
        if self.on_position is not None:
            self.on_position(position)

    def flush(self) -> None:
        """Hand the batches to ``on_flush`` (which empties them)."""
        if self.on_flush is not None and self.batches:
            self.on_flush(self)
        self._held = 0

    def _top_level(self, raw: bytes, u8: np.ndarray, top: Records) -> None:
        ops = top.ops
        special = np.flatnonzero(np.isin(ops, (OP_CHUNK, OP_DATA_END, OP_FOOTER, OP_METADATA)))
        # running count of schema / channel / message records, to skip runs without any
        content = np.concatenate([[0], np.cumsum(np.isin(ops, (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE)))])
        run_start = 0
        for i in special.tolist() + [ops.size]:
            if content[i] > content[run_start]:  # top-level schema / channel / message records
                for lo in range(run_start, i, TOP_LEVEL_SLICE):
                    hi = min(lo + TOP_LEVEL_SLICE, i)
                    lengths = top.lengths[lo:hi]
                    self._container(raw, u8, ops[lo:hi], top.offsets[lo:hi], lengths, checked=False)
                    self._held_more(int(lengths.sum()), int(top.offsets[hi - 1] + lengths[-1]))
            run_start = i + 1
            if i == ops.size:
                return
            op, start, length = int(ops[i]), int(top.offsets[i]), int(top.lengths[i])
            if op == OP_CHUNK:
                wanted = self.window_chunks is None or start in self.window_chunks
                self._held_more(self._chunk_or_skip(raw, start, length) if wanted else 0, start + length)
            elif op == OP_METADATA:
                cur = Cursor(raw, start, start + length)
                name = cur.string()
                self.metadata[name] = cur.string_map()
                self.unchecked_records += 1
            elif op == OP_DATA_END and self.window_chunks is None:  # a window's read: not every byte seen
                crc = data_section_damage(
                    raw, start, length, self.give_back, self.skipped_chunks, self.unchecked_records
                )
                counts = statistics_damage(raw, top, i + 1, self.messages_read, self.chunks_read)
                self.damage.extend(text for text in (crc, counts) if text)
                if self.damage:
                    self.damage.extend(_private_records(top))
                return
            else:  # footer, or a window's data end
                return

    def _chunk_or_skip(self, raw: bytes, start: int, length: int) -> int:
        """`_chunk`, or 0 when the chunk is damaged: it is skipped (counted) and the walk goes on."""
        try:
            return self._chunk(raw, start, length)
        except _Corrupt as exc:
            self.skipped_chunks.append((exc.offset, exc.reason))
        except PARSE_ERRORS as exc:  # a field inside one of its records did not parse
            self.skipped_chunks.append((start, f"malformed record in the chunk ({type(exc).__name__}: {exc})"))
        return 0

    def _chunk(self, raw: bytes, start: int, length: int) -> int:
        """Read one chunk's records; returns its uncompressed size."""
        self.chunks_read += 1
        cur = Cursor(raw, start, start + length)
        try:
            _t0, _t1, uncompressed_size, uncompressed_crc = cur.take("<QQQI")
            compression = cur.string()
            (size,) = cur.take("<Q")
            if size > cur.end - cur.pos:
                raise struct.error("chunk records longer than the chunk")
            payload = raw[cur.pos : cur.pos + size]
        except PARSE_ERRORS as exc:
            raise_corrupt(f"chunk header does not parse ({exc})", start)
        if compression == "":
            data = payload
        else:
            self._check_declared(uncompressed_size, start)
            try:
                data = inflate(compression, payload, uncompressed_size)
            except InflateError as exc:
                raise_corrupt(str(exc), start)
            self._inflate_budget -= len(data)
        if len(data) != uncompressed_size:
            raise_corrupt(f"chunk holds {len(data)} bytes, its header says {uncompressed_size}", start)
        if uncompressed_crc != 0 and zlib.crc32(data) != uncompressed_crc:
            raise_corrupt("chunk CRC mismatch", start)
        u8 = np.frombuffer(data, dtype=np.uint8)
        inner = walk_records(u8, 0, len(data))
        if inner.status != WALK_END:
            raise_corrupt("records inside a chunk do not fill it (corrupt chunk)", start)
        self._container(data, u8, inner.ops, inner.offsets, inner.lengths, checked=uncompressed_crc != 0)
        return len(data)

    def _check_declared(self, declared: int, offset: int) -> None:
        """Skip a compressed chunk declaring more than a cap before it is decompressed; `inflate`
        never produces more than the chunk declares, so its output stays within both caps."""
        if declared > MAX_CHUNK_BYTES:
            raise_corrupt(
                f"chunk declares {declared} bytes uncompressed, over logscan's limit of {MAX_CHUNK_BYTES >> 20} MiB "
                "per chunk: a corrupt chunk header or a decompression bomb",
                offset,
            )
        if declared > self._inflate_budget:
            raise_corrupt(
                f"chunk declares {declared} bytes uncompressed, and the file's chunks may decompress to "
                f"{MAX_RATIO}x the file size in all (at least {MIN_FILE_BUDGET_BYTES >> 20} MiB): "
                f"{max(0, self._inflate_budget)} bytes are left: a decompression bomb",
                offset,
            )

    def _container(self, data, u8, ops, offsets, lengths, *, checked: bool) -> None:
        """Schema, channel and message records of one chunk (or one run of top-level records)."""
        if not checked:
            self.unchecked_records += int(np.count_nonzero(np.isin(ops, (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE))))
        redefined = self._definitions(data, ops, offsets, lengths)
        found = group_messages(u8, ops, offsets, lengths, self._slot)
        if found.short_at >= 0:
            raise_corrupt("message record shorter than its header", found.short_at)
        self.messages_read += found.messages
        self.beyond_int64 += found.messages - found.channel_ids.size  # a damaged log_time: dropped, counted
        if redefined:
            self.redefined_messages += int(np.count_nonzero(np.isin(found.channel_ids, list(redefined))))
        bounds = found.bounds.tolist()
        for g, (cid, low, high) in enumerate(zip(found.group_ids.tolist(), found.low.tolist(), found.high.tolist())):
            lo, hi = bounds[g], bounds[g + 1]
            channel = self.channels.get(cid)
            if channel is None:
                self.unknown_channel_messages += hi - lo
                continue
            self.counts[cid] = self.counts.get(cid, 0) + hi - lo
            self.first[cid] = min(self.first.get(cid, low), low)
            self.last[cid] = max(self.last.get(cid, high), high)
            if not self._is_wanted(cid):
                continue
            batch = self.batches.setdefault(cid, _Batch())
            batch.times.append(found.grouped_times[lo:hi])
            batch.segments.append((u8, found.grouped_starts[lo:hi], found.grouped_ends[lo:hi]))
        if self.keep_raw and found.messages:
            self._keep_raw(data, u8, found.offsets, found.lengths, found.channel_ids, found.log_times)

    def _definitions(self, data, ops, offsets, lengths) -> set[int]:
        """Register the container's schema and channel records (few: in order, before its
        messages); the channel ids it defines otherwise than before."""
        redefined: set[int] = set()  # channel ids this container defines otherwise than before
        for k in np.flatnonzero((ops == OP_SCHEMA) | (ops == OP_CHANNEL)).tolist():
            start, length = int(offsets[k]), int(lengths[k])
            cur = Cursor(data, start, start + length)
            try:
                if ops[k] == OP_SCHEMA:
                    (sid,) = cur.take("<H")
                    name = cur.string()
                    encoding = cur.string()
                    (size,) = cur.take("<I")
                    self._define(self.schemas, sid, SchemaRec(sid, name, encoding, cur.raw(size)), "schema", start)
                else:
                    cid, sid = cur.take("<HH")
                    topic = cur.string()
                    encoding = cur.string()
                    meta = cur.string_map()
                    if not self._define(
                        self.channels, cid, ChannelRec(cid, sid, topic, encoding, meta), "channel", start
                    ):
                        redefined.add(cid)
            except PARSE_ERRORS as exc:
                raise_corrupt(f"schema/channel record does not parse ({exc})", start)
        return redefined

    def _keep_raw(self, data, u8, m_off, m_len, channel_ids, log_times) -> None:
        """Every message of the container, undecoded, into ``raw`` (``keep_raw``)."""
        sequences = gather_u32(u8, m_off + 2).tolist()
        publish = gather_u64(u8, m_off + 14).astype(np.int64).tolist()
        for k, cid in enumerate(channel_ids.tolist()):
            channel = self.channels.get(cid)
            start, stop = int(m_off[k]) + MESSAGE_HEADER, int(m_off[k] + m_len[k])
            self.raw.append(
                RawMessage(
                    channel.topic if channel else "",
                    cid,
                    sequences[k],
                    int(log_times[k]),
                    publish[k],
                    bytes(data[start:stop]),
                )
            )

    def _define(self, table: dict, key: int, record: SchemaRec | ChannelRec, kind: str, offset: int) -> bool:
        """Register a Schema or Channel record; False (the first kept, the conflict noted) when its
        id is already defined with other content. Writers repeat the same record in every chunk;
        an id is never redefined otherwise (the MCAP specification): this is a damaged record."""
        known = table.get(key)
        if known is None:
            table[key] = record
            return True
        if known == record:
            return True
        first = getattr(known, "topic", getattr(known, "name", ""))
        other = getattr(record, "topic", getattr(record, "name", ""))
        self.redefined.append(f"{kind} {key} {first[:60]!r}, redefined as {other[:60]!r} at byte {offset - 9}")
        return False

    def leave(self, cid: int) -> None:
        """Keep no batch of channel ``cid`` (a window's read counts its messages from the index)."""
        self._wanted_ids[cid] = False

    def _is_wanted(self, cid: int) -> bool:
        known = self._wanted_ids.get(cid)
        if known is None:
            known = self._wanted_ids[cid] = topic_wanted(self.channels[cid].topic, self.wanted)
        return known


def scan_file(scan: Scan | str, wanted: set[str] | None = None, keep_raw: bool = False) -> Scan:
    """Run ``scan`` (or a new Scan of the path ``scan``, keeping the batches of ``wanted`` topics and
    every raw message when ``keep_raw``); damage is left in ``scan.problem``."""
    if not isinstance(scan, Scan):
        scan = Scan(scan, wanted, keep_raw)
    try:
        scan.run()
    except _Corrupt as exc:
        scan.problem = exc
    chunk_damage(scan)
    return scan


def iter_raw_messages(path: str | os.PathLike) -> Iterator[RawMessage]:
    """Every message of the file in file order, undecoded (the layer ``read_mcap`` is built on).

    Raises CorruptLogError when the file is corrupt anywhere (this strict view is for checking
    files; ``read_mcap`` instead keeps what precedes the damage).
    """
    scan = scan_file(str(path), None, keep_raw=True)
    if scan.problem is not None or scan.damage:
        raise CorruptLogError(problem_text(scan) if scan.problem else "; ".join(scan.damage), path=str(path))
    yield from scan.raw
