"""The damage an MCAP scan found, in words: the data-section CRC and the summary's Statistics record
checked against the walk, the walk's damage summed up, and whether anything it read can be trusted.

Each damage line makes the read partial (`logscan.readers.mcap.scan` explains which damage stops the
walk and which does not); `raise_if_unrecoverable` refuses a scan that kept no message, or read
nothing that can be trusted.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from typing import Protocol

import numpy as np

from logscan.errors import CorruptLogError
from logscan.readers.mcap.records import OP_STATISTICS, PARSE_ERRORS, Cursor, Records
from logscan.readers.mcap.scan_records import _Corrupt


class Scan(Protocol):
    """What these functions read and write of a `logscan.readers.mcap.scan.Scan` (named by its
    fields, not imported: the scan imports this module)."""

    path: str
    problem: _Corrupt | None
    damage: list[str]
    messages_read: int
    skipped_chunks: list[tuple[int, str]]
    unknown_channel_messages: int
    beyond_int64: int
    redefined: list[str]
    redefined_messages: int


CRC_BLOCK = 16 << 20  # bytes of the data-section CRC computed before their pages are given back


def data_section_damage(
    raw: bytes,
    start: int,
    length: int,
    give_back: Callable[[int], None],
    skipped_chunks: list[tuple[int, str]],
    unchecked_records: int,
) -> str | None:
    """The data-section CRC of the DataEnd record at ``start`` checked (None: it matches or is 0);
    ``give_back(stop)`` returns the pages before ``stop`` as the CRC passes them. A mismatch the
    skipped chunks explain, or one outside every record the walk used, is damage; any other is a
    fatal `_Corrupt` (nothing read can be trusted)."""
    (expected,) = Cursor(raw, start, start + length).take("<I")
    if expected == 0:
        return None
    actual = 0
    with memoryview(raw) as view:
        for lo in range(0, start - 9, CRC_BLOCK):
            hi = min(lo + CRC_BLOCK, start - 9)
            actual = zlib.crc32(view[lo:hi], actual)
            give_back(hi)
    if actual == expected:
        return None
    if skipped_chunks:
        return (
            f"data section CRC mismatch (DataEnd record at byte {start - 9}): the damaged chunks skipped "
            "explain it, unless records outside them are damaged too"
        )
    if unchecked_records == 0:
        # Every message read came from a chunk whose own CRC matched, but the damage may be a
        # chunk's opcode byte, and such a chunk was skipped like a private record: messages may
        # be missing, so the read is partial (a damaged message index alone costs nothing, but
        # the CRC cannot tell the two apart).
        return (
            f"data section CRC mismatch (DataEnd record at byte {start - 9}): bytes outside the "
            "CRC-checked chunks are damaged, and a chunk whose opcode byte is damaged is skipped "
            "like an unknown record, so messages may be missing"
        )
    raise _Corrupt("data section CRC mismatch (the data section is corrupt)", start - 9, fatal=True)


def statistics_damage(raw: bytes, top: Records, first: int, messages_read: int, chunks_read: int) -> str | None:
    """Damage when the summary's Statistics record (from record ``first`` on) counts other numbers
    of messages or chunks than the walk read: a chunk was skipped (the data section may have no CRC
    to show it)."""
    for k in np.flatnonzero(top.ops[first:] == OP_STATISTICS).tolist():
        start = int(top.offsets[first + k])
        try:
            messages, _schemas, _channels, _attachments, _metadata, chunks = Cursor(
                raw, start, start + int(top.lengths[first + k])
            ).take("<QHIIII")
        except PARSE_ERRORS:
            continue  # a statistics record that does not parse is no evidence either way
        if (messages, chunks) != (messages_read, chunks_read):
            return (
                f"the summary's Statistics record (byte {start - 9}) counts {messages} messages in "
                f"{chunks} chunks, the data section holds {messages_read} in {chunks_read} "
                "(a chunk was skipped, or the summary is damaged)"
            )
        return None
    return None


def chunk_damage(scan: Scan) -> None:
    """The damage of the walk, once it is over, into ``scan.damage``: chunks skipped, messages on
    undefined channels, channels defined twice (each makes the read partial)."""
    if scan.skipped_chunks:
        offset, why = scan.skipped_chunks[0]
        more = f" (and {len(scan.skipped_chunks) - 1} more)" if len(scan.skipped_chunks) > 1 else ""
        scan.damage.insert(
            0,
            f"{len(scan.skipped_chunks)} damaged chunk(s) skipped with their messages; the first at byte "
            f"{offset}: {why}{more}",
        )
    if scan.unknown_channel_messages:
        scan.damage.append(
            f"{scan.unknown_channel_messages} message(s) on channel ids no Channel record defines were "
            "dropped (a damaged channel id, or a lost Channel record)"
        )
    if scan.beyond_int64:
        scan.damage.append(
            f"{scan.beyond_int64} message(s) dropped: a log_time beyond int64 nanoseconds (after 2262), "
            "a damaged message header"
        )
    if scan.redefined:
        scan.damage.append(
            f"{len(scan.redefined)} Channel/Schema record(s) redefine an id with other content "
            f"({scan.redefined[0]}); the first definition is kept, and {scan.redefined_messages} message(s) "
            "of the chunks holding the others may be attributed wrongly"
        )


def problem_text(scan: Scan) -> str:
    """Why and where the scan stopped early."""
    problem = scan.problem
    assert problem is not None
    where = f" at byte {problem.offset}" if problem.offset >= 0 else ""
    return f"{problem.reason}{where}"


def raise_if_unrecoverable(scan: Scan) -> None:
    """CorruptLogError when the walk stopped before any message, or nothing it read can be trusted,
    or it found damage (``Scan.damage``) and no message."""
    if scan.problem is not None and (scan.messages_read == 0 or scan.problem.fatal):
        lost = "nothing read can be trusted" if scan.problem.fatal else "no messages could be recovered"
        raise CorruptLogError(
            f"corrupt MCAP: {problem_text(scan)}; {lost}",
            path=scan.path,
            hint="the file is damaged; re-export or re-record it",
        )
    if scan.damage and scan.messages_read == 0:
        raise CorruptLogError(
            f"corrupt MCAP: {'; '.join(scan.damage)}; no messages could be recovered",
            path=scan.path,
            hint="the file is damaged; re-export or re-record it",
        )
