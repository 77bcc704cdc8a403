"""ROS 1 bags without a Python step per message: chunk by chunk, records found and decoded by kernels.

rosbags opens the bag and reads its index (per connection: time, chunk position, offset of each
message record). Then, for the wanted connections only, each chunk holding their messages is read
and decompressed once; a numba kernel follows the index offsets to the message data in the chunk
(``_locate``), and a second runs a layout program over them in place (``_ros1_run``): the program
``logscan.readers.mcap.cdr`` builds for the type, run without CDR's alignment and encapsulation
header (ROS 1 serialization is packed; a string is a uint32 length and its bytes). The program is
built from the type as written (the ROS 1 ``std_msgs/Header`` with ``seq``) and its columns named
as in the ROS 2 type, so ``seq`` is read past and not kept: the channels equal those of the
``ros1_to_cdr`` path exactly (a test checks it). A type with no layout (variable-length arrays, an
empty message), or a batch a layout does not fit, is handed back as per-message bytes for that path.

Damage (a chunk that cannot be read or decompressed, a record the index points into that is not a
message of that connection) skips that chunk with its messages, as the MCAP reader does: the
source is partial and says how many chunks and messages; nothing recovered is an InputError.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from logscan.errors import InputError
from logscan.log import SourceInfo
from logscan.numba_cache import follow_dependencies
from logscan.readers import spill
from logscan.readers.flatten import FlatColumns, MessageBytes
from logscan.readers.mcap.cdr import CdrLayout, cdr_layout, le_value
from logscan.readers.mcap.scan_records import SchemaRec
from logscan.readers.rosbag_types import ros2_type_name

ROS1_HINT = "check the copy; an unindexed bag (a recording cut short) can be repaired with `rosbag reindex`"


class ChunkRead(NamedTuple):
    """What the chunk walk gives: per (topic, msgtype), flat columns already decoded (each with the
    receive times of its messages), and the raw messages left for the per-message path."""

    decoded: list[tuple[str, str, FlatColumns, np.ndarray]]
    raw: dict[tuple[str, str], tuple[list[int], list[bytes]]]


# The decoded chunks wait in memory until they hold this many bytes, then each topic's become one
# piece per field (`_flat`): on disk for a held read of a long bag (`spill.spilling`), so the read
# holds a batch, not the bag; few pieces to join, whatever the chunk size.
BATCH_BYTES = 16 << 20


class _Batch:
    """Decoded chunks not yet made pieces: per (topic, msgtype), its layout, the chunks' value
    tables and receive times, in order."""

    def __init__(self) -> None:
        self.tables: dict[tuple[str, str], tuple[CdrLayout, list[np.ndarray], list[np.ndarray]]] = {}
        self.nbytes = 0

    def add(self, topic: str, msgtype: str, layout: CdrLayout, out: np.ndarray, times: np.ndarray) -> None:
        _, outs, batch_times = self.tables.setdefault((topic, msgtype), (layout, [], []))
        outs.append(out)
        batch_times.append(times)
        self.nbytes += out.nbytes

    def into(self, result: ChunkRead) -> None:
        """Each topic's chunks as one batch of pieces, in order; the batch emptied."""
        for (topic, msgtype), (layout, outs, times) in self.tables.items():
            result.decoded.append((topic, msgtype, _flat(layout, outs), spill.joined(times)))
        self.tables, self.nbytes = {}, 0


def ros1_layout(wire: Any, store: Any, msgtype: str) -> CdrLayout | None:
    """The layout program of ``msgtype`` as a ROS 1 bag writes it, with the ROS 2 type's column
    names (``wire``: the bag's types with the ROS 1 Header; ``store``: the same as ROS 2 types)."""
    layouts = []
    for types in (wire, store):
        try:
            text = types.generate_msgdef(msgtype, ros_version=2)[0]
        except Exception:  # noqa: BLE001 - a type rosbags cannot write out: the per-message path
            return None
        layouts.append(
            cdr_layout(SchemaRec(id=0, name=ros2_type_name(msgtype), encoding="ros2msg", data=text.encode()))
        )
    as_written, as_ros2 = layouts
    if as_written is None or as_ros2 is None:
        return None
    if ((as_written.kinds == 0) & (as_written.columns < 0)).any():
        return None  # an empty message's placeholder byte: CDR has it, ROS 1 does not
    position = {path: column for column, path in enumerate(as_ros2.paths)}
    dropped = [path for path in as_written.paths if path not in position]
    if [path for path in as_written.paths if path in position] != as_ros2.paths:
        return None
    if any(path != "seq" and not path.endswith(".seq") for path in dropped):
        return None
    remap = np.array([position.get(path, -1) for path in as_written.paths] + [-1], dtype=np.int64)
    columns = remap[as_written.columns]  # column -1 indexes the trailing -1: stays unkept
    return CdrLayout(as_written.kinds, as_written.sizes, as_written.codes, columns, as_ros2.paths, as_ros2.skipped)


@njit(cache=True)
def _u32(buf, pos):  # pragma: no cover - compiled
    return (
        np.int64(buf[pos])
        | (np.int64(buf[pos + 1]) << 8)
        | (np.int64(buf[pos + 2]) << 16)
        | (np.int64(buf[pos + 3]) << 24)
    )


@njit(cache=True)
def _locate(buf, offsets, starts, ends, conns):  # pragma: no cover - compiled
    """Data start/end and connection id of the message record at (or after the connection records
    at) each offset of a decompressed chunk; the index of the first record that is not one, or -1.
    Arrays: buf uint8[n]; offsets, starts, ends, conns int64[m]."""
    n = buf.size
    for m in range(offsets.size):
        pos = offsets[m]
        while True:
            if pos < 0 or pos + 4 > n:
                return m
            header_end = pos + 4 + _u32(buf, pos)
            if header_end + 4 > n:
                return m
            op = -1
            conn = -1
            field = pos + 4
            while field + 4 <= header_end:
                length = _u32(buf, field)
                name = field + 4
                stop = name + length
                if length <= 0 or stop > header_end:
                    return m
                eq = name
                while eq < stop and buf[eq] != 61:  # '='
                    eq += 1
                if eq == name + 2 and buf[name] == 111 and buf[name + 1] == 112 and eq + 1 < stop:  # op
                    op = buf[eq + 1]
                elif eq == name + 4 and buf[name] == 99 and buf[name + 1] == 111 and eq + 4 < stop:  # conn
                    if buf[name + 2] == 110 and buf[name + 3] == 110:
                        conn = _u32(buf, eq + 1)
                field = stop
            data = header_end + 4
            end = data + _u32(buf, header_end)
            if end > n:
                return m
            if op == 7:  # a connection record before the message: step over it
                pos = end
                continue
            if op != 2:
                return m
            starts[m] = data
            ends[m] = end
            conns[m] = conn
            break
    return -1


@njit(cache=True)
def _ros1_run(buf, starts, ends, kinds, sizes, codes, columns, out):  # pragma: no cover - compiled
    """The layout program over packed ROS 1 messages (``cdr._cdr_run`` without alignment and
    encapsulation header; each message must be used up exactly); False when one does not fit.
    Arrays: buf uint8[n]; starts, ends int64[m]; kinds, sizes, codes, columns int64[k]; out float64[m, c]."""
    for m in range(starts.size):
        pos = starts[m]
        end = ends[m]
        for k in range(kinds.size):
            size = sizes[k]
            if kinds[k] == 0:
                if pos + size > end:
                    return False
                value = le_value(buf, pos, size, codes[k])
                if columns[k] >= 0:
                    out[m, columns[k]] = value
                pos += size
            elif kinds[k] == 1:
                if pos + 4 > end:
                    return False
                pos += 4 + _u32(buf, pos)
                if pos > end:
                    return False
            else:
                pos += size
                if pos > end:
                    return False
        if pos != end:
            return False
    return True


def _flat(layout: CdrLayout, outs: list[np.ndarray]) -> FlatColumns:
    """The columns of the chunks' value tables ``outs`` end to end, one array per field
    (`spill.joined`: on disk within `spill.spilling`)."""
    flat = FlatColumns()
    count = sum(out.shape[0] for out in outs)
    every = np.arange(count, dtype=np.int64)
    for column, path in enumerate(layout.paths):
        flat.columns[path] = (every, spill.joined([out[:, column] for out in outs]))
        flat.fields.append(path)
    for path in layout.skipped:
        flat.skipped[(path, "non-numeric")] = count
    return flat


def _index_arrays(reader, connections: list) -> tuple[np.ndarray, ...]:
    """(connection number, time, chunk position, offset) of every message of ``connections``, in
    chunk and record order (connection number: the index into ``connections``), from the bag's
    index table (`TableIndexReader.index`), which they take the place of: the reader's is emptied
    (32 bytes per message; nothing reads it after the walk's arrays are made)."""
    index, reader.index = reader.index, reader.index[:0]
    ids = np.array([c.id for c in connections], dtype=np.int64)
    wanted = np.isin(index[:, 0], ids)
    if not wanted.all():
        index = index[wanted]
    del wanted
    order = np.lexsort((index[:, 3], index[:, 2]))
    by_id = np.argsort(ids, kind="stable")
    numbers = by_id[np.searchsorted(ids, index[order, 0], sorter=by_id)].astype(np.int32)
    return numbers, index[order, 1], index[order, 2], index[order, 3]


def read_chunks(
    path: str,
    reader,
    connections: list,
    layouts: dict,
    source: SourceInfo,
    *,
    progress: Callable[[int, int], None] | None = None,
) -> ChunkRead:
    """Decode the messages of ``connections`` chunk by chunk (``layouts``: msgtype -> layout or
    None). A chunk that cannot be read is skipped with its messages and the walk goes on; the
    source then says how much was skipped and recovered (nothing recovered: InputError).
    ``progress(end of the chunk, file size)`` after each chunk read (chunks in file order)."""
    result = ChunkRead([], {})
    numbers, times, chunk_pos, offsets = _index_arrays(reader, connections)
    ids = np.array([c.id for c in connections], dtype=np.int64)
    bounds = np.flatnonzero(np.diff(chunk_pos)) + 1
    damaged: list[tuple[int, int, str]] = []  # (chunk position, messages skipped, why)
    batch = _Batch()
    with open(path, "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        for first, last in zip(np.r_[0, bounds].tolist(), np.r_[bounds, chunk_pos.size].tolist()):
            if first == last:
                continue
            position = int(chunk_pos[first])
            chunk = reader.chunks.get(position)
            found = _read_chunk(fh, chunk, offsets[first:last])
            if progress is not None:
                progress(min(size, chunk.datapos + chunk.datasize if chunk is not None else position), size)
            if not isinstance(found, str) and (found[3] != ids[numbers[first:last]]).any():
                found = "a message record of another connection than the index says"
            if isinstance(found, str):
                damaged.append((position, last - first, found))
                continue
            buf, starts, ends, _conns = found
            chunk_messages = numbers[first:last], times[first:last]
            _decode_chunk(buf, starts, ends, *chunk_messages, connections, layouts, result, batch)
            if batch.nbytes >= BATCH_BYTES:
                batch.into(result)
    batch.into(result)
    if damaged:
        _report_damage(path, source, damaged, int(chunk_pos.size))
    return result


def _report_damage(path: str, source: SourceInfo, damaged: list[tuple[int, int, str]], wanted: int) -> None:
    """The source made partial by the damaged chunks; InputError when nothing was recovered."""
    skipped = sum(count for _, count, _ in damaged)
    position, _, why = damaged[0]
    text = (
        f"{len(damaged)} damaged chunk(s) skipped with their {skipped} message(s); the first at byte {position}: {why}"
    )
    if skipped == wanted:
        raise InputError(f"cannot read the messages: {text}", path=path, hint=ROS1_HINT)
    source.partial = True
    source.partial_reason = f"{text}; recovered {wanted - skipped} of {wanted} messages"


def _read_chunk(fh, chunk, offsets: np.ndarray):
    """(chunk buffer, starts, ends, connection ids) of the records at ``offsets``, or what is wrong."""
    if chunk is None:
        return "a chunk the index names is missing"
    try:
        fh.seek(chunk.datapos)
        raw = fh.read(chunk.datasize)
        if len(raw) != chunk.datasize:
            return "a chunk is cut short"
        buf = np.frombuffer(chunk.decompressor(raw), dtype=np.uint8)
    except Exception as exc:  # noqa: BLE001 - bz2/lz4 errors on damaged data are many kinds
        return f"a chunk does not decompress ({type(exc).__name__}: {exc})"
    starts, ends, conns = (np.empty(offsets.size, dtype=np.int64) for _ in range(3))
    bad = _locate(buf, offsets.astype(np.int64), starts, ends, conns)
    if bad >= 0:
        return f"the message record the index places at offset {int(offsets[bad])} does not parse"
    return buf, starts, ends, conns


def _decode_chunk(
    buf, starts, ends, numbers, times, connections: list, layouts: dict, result: ChunkRead, batch: _Batch
) -> None:
    """One chunk's messages of each (topic, msgtype), decoded in place into ``batch`` or kept as bytes."""
    keys: dict[tuple[str, str], list[int]] = {}
    for number, connection in enumerate(connections):
        keys.setdefault((connection.topic, connection.msgtype), []).append(number)
    for (topic, msgtype), members in keys.items():
        mask = np.isin(numbers, members)
        if not mask.any():
            continue
        sel_starts, sel_ends, sel_times = starts[mask], ends[mask], times[mask]
        layout = layouts.get(msgtype)
        if layout is not None:
            out = np.empty((sel_starts.size, len(layout.paths)), dtype=np.float64)
            if _ros1_run(buf, sel_starts, sel_ends, layout.kinds, layout.sizes, layout.codes, layout.columns, out):
                batch.add(topic, msgtype, layout, out, sel_times)
                continue
        raw_times, raw_datas = result.raw.setdefault((topic, msgtype), ([], []))
        raw_times.extend(sel_times.tolist())
        raw_datas.extend(MessageBytes([(buf, sel_starts, sel_ends)]).to_list())


follow_dependencies(__name__)  # the cached kernels are stamped with cdr's value decoding too
