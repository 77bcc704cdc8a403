"""The format table: pick the reader by the file's content (magic bytes), not only its suffix."""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from logscan.errors import InputError, UnsupportedFormatError
from logscan.log import Log
from logscan.readers.common import MCAP_MAGIC, ULOG_MAGIC


def detect_format(path: str | os.PathLike) -> str:
    """Return "mcap", "ulog", "csv" or "csv-dir" for ``path``, judged by content.

    Raises InputError when the path is missing or unreadable and UnsupportedFormatError when the
    content matches no reader.
    """
    p = Path(path)
    if p.is_dir():
        if any(child.suffix.lower() == ".csv" for child in p.iterdir()):
            return "csv-dir"
        raise UnsupportedFormatError(
            "directory holds no .csv files", path=str(p), hint="give an MCAP, ULog or CSV file"
        )
    if not p.exists():
        raise InputError("no such file", path=str(p))
    try:
        with open(p, "rb") as fh:
            head = fh.read(4096)
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=str(p)) from None
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
