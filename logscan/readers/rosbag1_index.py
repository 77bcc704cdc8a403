"""A ROS 1 bag's message index as one table: rosbags' reader, whose open keeps an object per
message (about 170 bytes: 270 MB for an eight-hour drive, built again at each open of the bag),
made to keep each index record's entries as they lie in the file instead.

A bag's IndexData record (version 1) lists one connection's messages in one chunk: a header of
fields ``op`` (0x04), ``ver`` (1), ``conn`` and ``count``, then ``count`` entries of (time sec
uint32, time nsec uint32, offset in the chunk uint32).
"""

from __future__ import annotations

import struct

import numpy as np

try:
    from rosbags.rosbag1 import Reader, ReaderError
    from rosbags.rosbag1.reader import IndexData
except ImportError as exc:  # a broken install: opening a bag says what is missing (`opened`), not an import
    ROSBAGS_MISSING: ImportError | None = exc
    Reader, ReaderError, IndexData = object, ValueError, tuple  # type: ignore[assignment,misc]
else:
    ROSBAGS_MISSING = None

_ENTRY = np.dtype([("sec", "<u4"), ("nsec", "<u4"), ("offset", "<u4")])
_INDEX_OP = b"\x04"
MAX_HEADER_BYTES = 4096  # an IndexData header is 47 bytes: a longer length is damage, not read


class TableIndexReader(Reader):
    """rosbags' ROS 1 reader with the message index as ``index``: an int64 table of (connection id,
    receive time ns, chunk position, offset in the chunk) per message, in file order (chunk by
    chunk). ``connections`` carry their message counts as rosbags gives them; ``indexes`` (rosbags'
    own, which its `messages` reads) stays empty until `index_objects` makes it."""

    index: np.ndarray

    def open(self) -> None:
        self._records: list[tuple[int, int, np.ndarray]] = []  # (connection id, chunk position, entries)
        try:
            super().open()  # reads each chunk's index records through `read_index_data`
            self.index = _table(self._records)
        finally:
            del self._records
        counts = dict(zip(*np.unique(self.index[:, 0], return_counts=True)))
        self.connections = [c._replace(msgcount=int(counts.get(c.id, 0))) for c in self.connections]

    def read_index_data(self, pos: int, indexes) -> None:  # noqa: ARG002 - rosbags' signature
        """One IndexData record at the file's position, of the chunk at ``pos``, kept as its entries."""
        assert self.bio
        fields = _header_fields(self.bio)
        if fields.get("op") != _INDEX_OP or _u32(fields.get("ver")) != 1:
            raise ReaderError("an index record of another kind or version than IndexData 1")
        count = _u32(fields.get("count"))
        size = _u32(self.bio.read(4))
        if size != count * _ENTRY.itemsize:  # checked before reading: a damaged length reads no 4 GiB
            raise ReaderError("an index record whose entries do not fill it")
        data = self.bio.read(size)
        if len(data) != size:
            raise ReaderError("an index record cut short")
        self._records.append((_u32(fields.get("conn")), pos, np.frombuffer(data, _ENTRY)))

    def index_objects(self) -> None:
        """rosbags' own index (``indexes``, an object per message, by time as its open sorts it),
        for its `messages`: the read of a bag whose types the chunk walk cannot decode."""
        ordered = self.index[np.lexsort((self.index[:, 1], self.index[:, 0]))]  # stable: ties keep file order
        entries = list(map(IndexData, *(ordered[:, column].tolist() for column in (1, 2, 3))))
        ids, starts = np.unique(ordered[:, 0], return_index=True)
        ends = np.r_[starts[1:], len(entries)]
        self.indexes = {c.id: [] for c in self.connections}
        self.indexes.update({int(i): entries[a:b] for i, a, b in zip(ids, starts, ends)})


def _table(records: list[tuple[int, int, np.ndarray]]) -> np.ndarray:
    table = np.empty((sum(entries.size for _, _, entries in records), 4), dtype=np.int64)
    at = 0
    for connection, chunk, entries in records:
        rows = table[at : at + entries.size]
        rows[:, 0] = connection
        rows[:, 1] = entries["sec"].astype(np.int64) * 1_000_000_000 + entries["nsec"]  # t = sec * 1e9 + nsec
        rows[:, 2] = chunk
        rows[:, 3] = entries["offset"]
        at += entries.size
    return table


def _header_fields(bio) -> dict[str, bytes]:
    """A record header's fields (``<len><name>=<value>`` each, after the header's own length)."""
    size = _u32(bio.read(4))
    if size > MAX_HEADER_BYTES:
        raise ReaderError(f"a record header of {size} bytes")
    header = bio.read(size)
    if len(header) != size:
        raise ReaderError("a record header cut short")
    fields, at = {}, 0
    while at + 4 <= size:
        length = _u32(header[at : at + 4])
        name, equals, value = header[at + 4 : at + 4 + length].partition(b"=")
        if not equals:
            raise ReaderError("a record header field without '='")
        fields[name.decode("ascii", "replace")] = value
        at += 4 + length
    return fields


def _u32(raw: bytes | None) -> int:
    if raw is None or len(raw) != 4:
        raise ReaderError("a record field is missing or not 4 bytes")
    return struct.unpack("<I", raw)[0]


def opened(path) -> TableIndexReader:
    """A `TableIndexReader` of ``path``, open (ImportError without rosbags)."""
    if ROSBAGS_MISSING is not None:
        raise ROSBAGS_MISSING
    reader = TableIndexReader(path)
    reader.open()
    return reader
