"""MCAP metadata without the messages (through the summary's index), and the truth and profile records logscan embeds.

Metadata records logscan writes and reads back (``source.metadata[name]`` holds every record):
 - ``logscan.truth``: key ``json`` -> a JSON document, the ground truth
   (``{"events": [{"start": s, "end": s, "kind": str, "target": str, ...}], ...}``) -> ``Log.truth``.
 - ``logscan.profile``: key ``toml`` -> the profile's TOML text -> ``Log.profile_text``.
"""

from __future__ import annotations

import json
import os
import struct
import zlib

import numpy as np

from logscan.log import Log
from logscan.readers.common import MCAP_MAGIC, input_error, stat_input
from logscan.readers.mcap.records import (
    OP_FOOTER,
    OP_METADATA,
    OP_METADATA_INDEX,
    OP_STATISTICS,
    PARSE_ERRORS,
    WALK_END,
    Cursor,
    walk_records,
)
from logscan.readers.mcap.scan import scan_file
from logscan.readers.mcap.scan_damage import raise_if_unrecoverable

TRUTH_RECORD = "logscan.truth"
PROFILE_RECORD = "logscan.profile"


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
    stat_input(path)  # a FIFO or device is refused before it is opened
    try:
        with open(path, "rb") as fh:
            indexed = _indexed_metadata(fh)
    except OSError as exc:
        raise input_error(exc, path) from None
    if indexed is not None:
        return indexed
    scan = scan_file(path, set(), keep_raw=False)
    raise_if_unrecoverable(scan)
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
    if tail[0] != OP_FOOTER or tail[1:9] != struct.pack("<Q", 20) or tail[_FOOTER_RECORD:] != MCAP_MAGIC:
        return None
    summary_start, _offsets_start, summary_crc = struct.unpack_from("<QQI", tail, 9)
    if not len(MCAP_MAGIC) < summary_start <= footer_at:
        return None  # 0: no summary section
    fh.seek(summary_start)
    summary = fh.read(footer_at - summary_start)
    # the CRC covers the summary section and the footer up to summary_crc
    if summary_crc != 0 and zlib.crc32(tail[:25], zlib.crc32(summary)) != summary_crc:
        return None
    records = walk_records(np.frombuffer(summary, dtype=np.uint8), 0, len(summary))
    if records.status != WALK_END:
        return None
    indexes: list[tuple[int, int, str]] = []
    counted: int | None = None
    try:
        for op, start, length in zip(records.ops.tolist(), records.offsets.tolist(), records.lengths.tolist()):
            cur = Cursor(summary, start, start + length)
            if op == OP_METADATA_INDEX:
                offset, record_length = cur.take("<QQ")
                indexes.append((offset, record_length, cur.string()))
            elif op == OP_STATISTICS:
                counted = cur.take("<QHIIII")[4]  # message, schema, channel, attachment, metadata counts
        if (not indexes and counted != 0) or (counted is not None and counted != len(indexes)):
            return None  # the summary does not account for every metadata record
        out: dict[str, dict[str, str]] = {}
        for offset, record_length, name in indexes:
            if offset < len(MCAP_MAGIC) or record_length < 9 or offset + record_length > summary_start:
                return None
            fh.seek(offset)
            record = fh.read(record_length)
            if record[0] != OP_METADATA or struct.unpack_from("<Q", record, 1)[0] != record_length - 9:
                return None
            cur = Cursor(record, 9, record_length)
            if cur.string() != name:
                return None
            out[name] = cur.string_map()
    except PARSE_ERRORS:
        return None
    return out


def attach_logscan_records(log: Log) -> None:
    """Ground truth and embedded profile from the ``logscan.truth`` / ``logscan.profile`` records."""
    meta = log.source.metadata
    truth = meta.get(TRUTH_RECORD)
    if truth is not None:
        try:
            log.truth = json.loads(truth["json"])
        except (KeyError, ValueError, RecursionError) as exc:  # RecursionError: JSON nested too deep
            log.source.warnings.append(f"metadata record {TRUTH_RECORD!r} ignored: no valid 'json' key ({exc})")
    profile = meta.get(PROFILE_RECORD)
    if profile is not None:
        if "toml" in profile:
            log.profile_text = profile["toml"]
        else:
            log.source.warnings.append(f"metadata record {PROFILE_RECORD!r} ignored: no 'toml' key")
