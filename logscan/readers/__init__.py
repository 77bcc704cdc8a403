"""The format table: pick the reader by the file's content (magic bytes), not only its suffix."""

from __future__ import annotations

import os
import stat
from collections.abc import Iterable
from pathlib import Path

from logscan.errors import InputError, UnsupportedFormatError
from logscan.log import Log
from logscan.readers.common import (
    MCAP_MAGIC,
    SPECIAL_FILE_HINT,
    ULOG_MAGIC,
    input_error,
    list_directory,
    special_kind,
    stat_input,
)


def detect_format(path: str | os.PathLike) -> str:
    """Return "mcap", "ulog", "csv" or "csv-dir" for ``path``, judged by content.

    Only regular files and directories are read, and that is checked before anything is opened
    (opening a FIFO blocks until a writer comes). Raises InputError when the path is missing,
    unreadable, not a regular file or directory (FIFO, device, socket), a directory that cannot be
    listed or searched, or a directory holding a special file named ``*.csv``; and
    UnsupportedFormatError when the content matches no reader.
    """
    p = Path(path)
    if stat.S_ISDIR(stat_input(p).st_mode):
        csvs = [(name, mode) for name, mode in list_directory(p) if name.lower().endswith(".csv")]
        for name, mode in csvs:
            kind = special_kind(mode)
            if kind is not None:
                raise InputError(f"is {kind}, not a regular file", path=str(p / name), hint=SPECIAL_FILE_HINT)
        if any(stat.S_ISREG(mode) for _, mode in csvs):
            return "csv-dir"
        raise UnsupportedFormatError(
            "directory holds no .csv files", path=str(p), hint="give an MCAP, ULog or CSV file"
        )
    try:
        with open(p, "rb") as fh:
            head = fh.read(4096)
    except OSError as exc:
        raise input_error(exc, p) from None
    if head.startswith(MCAP_MAGIC):
        return "mcap"
    if head.startswith(ULOG_MAGIC):
        return "ulog"
    if not head:
        raise InputError("file is empty", path=str(p))
    if _looks_like_text(head):
        return "csv"
    raise UnsupportedFormatError(
        f"not an MCAP, ULog or CSV file (unknown magic bytes {head[:8].hex(' ')})",
        path=str(p),
        hint="logscan reads .mcap, .ulg and .csv logs",
    )


def _looks_like_text(head: bytes) -> bool:
    if b"\x00" in head:
        return False
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:
        # A multi-byte character cut at the 4096-byte boundary is still text.
        if exc.start < len(head) - 4:
            return False
    return True


def read_log(
    path: str | os.PathLike,
    topics: Iterable[str] | None = None,
    *,
    use_header_stamp: bool = False,
) -> Log:
    """Read ``path`` into a Log, decoding only ``topics`` (all when None).

    ``topics`` are source topic names (MCAP topics, ULog ``topic_instance`` names, CSV file topics)
    or channel names; a reader keeps a topic when it or any channel under it is asked for.
    """
    fmt = detect_format(path)
    wanted = None if topics is None else set(topics)
    if fmt == "mcap":
        from logscan.readers.mcap import read_mcap

        return read_mcap(path, wanted, use_header_stamp=use_header_stamp)
    if fmt == "ulog":
        from logscan.readers.ulog_reader import read_ulog

        return read_ulog(path, wanted)
    from logscan.readers.csv_reader import read_csv, read_csv_dir

    if fmt == "csv-dir":
        return read_csv_dir(path, wanted)
    return read_csv(path, wanted)


def read_embedded(path: str | os.PathLike) -> tuple[str | None, dict | None]:
    """(profile TOML, ground truth) a log carries, read without its messages; None where absent.

    MCAP: the metadata records ``logscan.profile`` (key ``toml``) and ``logscan.truth`` (key
    ``json``), through the summary's metadata index when there is one. CSV file or directory: the
    ``<log>.profile.toml`` and ``<log>.truth.json`` sidecars. ULog: neither.
    Raises like ``read_log`` for a missing, unknown or corrupt file.
    """
    fmt = detect_format(path)
    if fmt == "mcap":
        from logscan.log import Log, SourceInfo
        from logscan.readers.mcap import attach_logscan_records, read_mcap_metadata

        header = Log(channels={}, source=SourceInfo(str(path), "mcap", metadata=read_mcap_metadata(path)))
        attach_logscan_records(header)
        return header.profile_text, header.truth
    if fmt in ("csv", "csv-dir"):
        from logscan.readers.csv_reader import read_profile_sidecar, read_truth_sidecar

        return read_profile_sidecar(Path(path)), read_truth_sidecar(Path(path))
    return None, None


def read_embedded_profile(path: str | os.PathLike) -> str | None:
    """The profile TOML a log carries (see `read_embedded`); None when it carries none."""
    return read_embedded(path)[0]
