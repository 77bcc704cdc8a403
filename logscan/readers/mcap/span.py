"""The time span of an indexed MCAP file from its summary section alone (`indexed_span_s`): what
block mode (`logscan.pipeline.blocks`) plans its windows from before any message is read."""

from __future__ import annotations

import os


def indexed_span_s(path: str | os.PathLike) -> tuple[float, int] | None:
    """(seconds from the file's first message to its last, its message count: the summary's
    Statistics record), when every chunk is indexed (a Chunk Index record with Message Index
    offsets for each): the files whose windows decode only the chunks they need
    (`logscan.readers.mcap.window`). None for a file without a summary, statistics or chunk
    indexes, or one the library cannot open: a window of it would read it whole, so it is not
    worth reading in blocks."""
    try:
        from mcap.reader import make_reader

        with open(path, "rb") as fh:
            summary = make_reader(fh).get_summary()
    except Exception:  # noqa: BLE001 - a damaged or summary-less file: the whole read says what is wrong
        return None
    if summary is None or summary.statistics is None or not summary.chunk_indexes:
        return None
    if not all(index.message_index_offsets for index in summary.chunk_indexes):
        return None
    statistics = summary.statistics
    if statistics.message_count == 0 or statistics.message_end_time < statistics.message_start_time:
        return None
    return (statistics.message_end_time - statistics.message_start_time) / 1e9, int(statistics.message_count)
