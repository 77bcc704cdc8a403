"""The format table: pick the reader by the file's content (magic bytes), not only its suffix.

A new file format is a reader function plus one `register_reader` call (docs/extending.md, "Adding
a reader"): `detect_format` asks the registered readers' ``sniff`` after the built-in magic bytes
(MCAP, ULog, ROS bags) and before the CSV catch-all, and `read_log` calls the ``read`` of the one
that claimed the file.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import NamedTuple

from logscan.errors import InputError, UnsupportedFormatError
from logscan.input_files import SPECIAL_FILE_HINT, special_kind
from logscan.log import Log, SourceInfo
from logscan.readers.common import (
    MCAP_MAGIC,
    ULOG_MAGIC,
    ReadWindow,
    input_error,
    list_directory,
    stat_input,
    undecoded_as_partial,
)

ROS1_BAG_MAGIC = b"#ROSBAG V2.0\n"
SQLITE_MAGIC = b"SQLite format 3\x00"  # a rosbag2 .db3
DATAFLASH_HEAD = b"\xa3\x95"  # ArduPilot DataFlash message header
BUILTIN_FORMATS = frozenset({"mcap", "ulog", "ros1bag", "rosbag2", "csv", "csv-dir"})


class Reader(NamedTuple):
    """A registered reader: ``sniff(head, path)`` says whether a file's first 4096 bytes are its
    format; ``read(path, wanted, use_header_stamp=...)`` reads it into a Log (``wanted``: the
    source topics or channel names to keep, None for all)."""

    name: str
    sniff: Callable[[bytes, Path], bool]
    read: Callable[..., Log]


READERS: dict[str, Reader] = {}  # registered readers by format name, asked in registration order


def register_reader(name: str, sniff: Callable[[bytes, Path], bool], read: Callable[..., Log]) -> None:
    """Register a reader of the format ``name`` (a name the built-ins do not use; registering the
    same name again replaces it). Files only: a directory is always a ROS bag or CSV folder."""
    if name in BUILTIN_FORMATS:
        raise ValueError(f"{name!r} is a built-in format")
    READERS[name] = Reader(name, sniff, read)


def detect_format(path: str | os.PathLike) -> str:
    """Return "mcap", "ulog", "ros1bag", "rosbag2", "csv" or "csv-dir" for ``path``, judged by content,
    or the name of the registered reader (`register_reader`) whose ``sniff`` claims the file.

    "rosbag2" is a SQLite file (a rosbag2 ``.db3``) or a directory holding ``metadata.yaml``; any
    other directory is a folder of CSV files. Only regular files and directories are read, and that
    is checked before anything is opened (opening a FIFO blocks until a writer comes). Raises
    InputError when the path is missing, unreadable, not a regular file or directory (FIFO, device,
    socket), a directory that cannot be listed or searched, or a directory holding a special file
    named ``*.csv`` or ``metadata.yaml``; and UnsupportedFormatError when the content matches no
    reader (ArduPilot DataFlash and MAVLink telemetry logs say so, with what to do).
    """
    p = Path(path)
    if stat.S_ISDIR(stat_input(p).st_mode):
        return _directory_format(p)
    try:
        with open(p, "rb") as fh:
            head = fh.read(4096)
    except OSError as exc:
        raise input_error(exc, p) from None
    if head.startswith(MCAP_MAGIC):
        return "mcap"
    if head.startswith(ULOG_MAGIC):
        return "ulog"
    if head.startswith(ROS1_BAG_MAGIC):
        return "ros1bag"
    if head.startswith(b"#ROSBAG V"):
        version = head[9:16].split(b"\n")[0].decode("ascii", "replace")
        raise UnsupportedFormatError(
            f"ROS bag version {version} is not supported (only V2.0)",
            path=str(p),
            hint="migrate it with `rosbag fix` (ROS 1), then read the new bag",
        )
    if head.startswith(SQLITE_MAGIC):
        return "rosbag2"
    if not head:
        raise InputError("file is empty", path=str(p))
    for reader in READERS.values():
        if reader.sniff(head, p):
            return reader.name
    _refuse_ardupilot(head, p)
    _refuse_misnamed(p)
    if _looks_like_text(head):
        return "csv"
    raise UnsupportedFormatError(
        f"not an MCAP, ULog or CSV file, nor a ROS bag (unknown magic bytes {head[:8].hex(' ')})",
        path=str(p),
        hint="logscan reads .mcap, .ulg and .csv logs, ROS 1 .bag files, rosbag2 .db3 files and rosbag2 directories",
    )


# a file named like a binary log whose content is not that log: cut short, or not a log at all; read
# as text it would only give a misleading CSV message
BINARY_SUFFIXES = {".mcap": "an MCAP file", ".ulg": "a ULog", ".bag": "a ROS 1 bag", ".db3": "a rosbag2 .db3 file"}


def _refuse_misnamed(p: Path) -> None:
    what = BINARY_SUFFIXES.get(p.suffix.lower())
    if what is not None:
        raise UnsupportedFormatError(
            f"named {p.suffix} but not {what} (its first bytes are not that format's magic)",
            path=str(p),
            hint="its start is damaged or it is not a log: copy it again from the vehicle or the recorder",
        )


def _directory_format(p: Path) -> str:
    """ "rosbag2" for a directory holding metadata.yaml, "csv-dir" for one holding CSV files."""
    entries = list_directory(p)
    special = [(name, mode) for name, mode in entries if name.lower().endswith(".csv") or name == "metadata.yaml"]
    for name, mode in special:
        kind = special_kind(mode)
        if kind is not None:
            raise InputError(f"is {kind}, not a regular file", path=str(p / name), hint=SPECIAL_FILE_HINT)
    if any(name == "metadata.yaml" and stat.S_ISREG(mode) for name, mode in entries):
        return "rosbag2"
    if any(stat.S_ISREG(mode) for name, mode in special if name.lower().endswith(".csv")):
        return "csv-dir"
    raise UnsupportedFormatError(
        "directory holds no .csv files and no rosbag2 metadata.yaml",
        path=str(p),
        hint="give an MCAP, ULog, ROS bag or CSV file, a rosbag2 directory or a directory of CSV files",
    )


def ardupilot_hint(name: str, types: str) -> str:
    """What to do with a DataFlash or MAVLink log: convert the messages needed to CSV (pymavlink)."""
    return (
        f"convert it to CSV with `mavlogdump.py --format csv --types {types} {name} > log.csv` (pymavlink) "
        "and analyse the CSV"
    )


def _refuse_ardupilot(head: bytes, p: Path) -> None:
    """UnsupportedFormatError for an ArduPilot DataFlash log or a MAVLink telemetry log: by their
    content (DataFlash message headers 0xA3 0x95; MAVLink frames, each after an 8-byte timestamp
    in a .tlog), or a file no reader takes named .tlog, or .bin holding DataFlash message headers."""
    suffix = p.suffix.lower()
    # a DataFlash log starts with a message header; a .bin cut at a message holds several more
    if head.startswith(DATAFLASH_HEAD) or (suffix == ".bin" and head.count(DATAFLASH_HEAD) >= 3):
        raise UnsupportedFormatError(
            "ArduPilot DataFlash log: not supported yet", path=str(p), hint=ardupilot_hint(p.name, "IMU,GPS")
        )
    if _mavlink_frames(head, stamped=True) or _mavlink_frames(head, stamped=False) or suffix == ".tlog":
        raise UnsupportedFormatError(
            "MAVLink telemetry log (ArduPilot/PX4 .tlog): not supported yet",
            path=str(p),
            hint=ardupilot_hint(p.name, "RAW_IMU,GPS_RAW_INT"),
        )


def _mavlink_frames(head: bytes, *, stamped: bool, frames: int = 3) -> bool:
    """True when ``head`` starts with ``frames`` whole MAVLink v1/v2 frames back to back (each after
    an 8-byte big-endian microsecond timestamp of a plausible date when ``stamped``, as in a .tlog)."""
    pos = 0
    for _ in range(frames):
        if stamped:
            if pos + 8 > len(head):
                return False
            stamp_us = int.from_bytes(head[pos : pos + 8], "big")
            if not 946_684_800_000_000 <= stamp_us <= 4_102_444_800_000_000:  # 2000 .. 2100
                return False
            pos += 8
        if pos + 3 > len(head):
            return False
        if head[pos] == 0xFE:  # v1: magic, len, seq, sys, comp, msgid, payload, crc16
            pos += 8 + head[pos + 1]
        elif head[pos] == 0xFD:  # v2: magic, len, incompat, compat, seq, sys, comp, msgid[3], payload, crc16
            pos += 12 + head[pos + 1] + (13 if head[pos + 2] & 1 else 0)  # signed: 13 more bytes
        else:
            return False
        if pos > len(head):
            return False
    return True


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
    progress: Callable[[int, int], None] | None = None,
    window: ReadWindow | None = None,
    held: bool = False,
) -> Log:
    """Read ``path`` into a Log, decoding only ``topics`` (all when None); of an indexed MCAP file,
    only the chunks ``window`` needs (`logscan.readers.mcap.window`: other logs are read whole).
    ``held``: a log held for block mode's windows, a ULog's fields of a type float32 holds exactly
    kept as float32 (`read_ulog`); a long ULog's or ROS 1 bag's arrays on disk (`logscan.readers.spill`).

    ``topics`` are source topic names (MCAP and bag topics, ULog ``topic_instance`` names, CSV file
    topics) or channel names; a reader keeps a topic when it or any channel under it is asked for.
    ``progress(done, total)``: the bytes read so far of ``total`` (the file's size; a directory's
    files), a block at a time, never per message: an MCAP's chunks, a ROS 1 bag's chunks (a bag
    read through rosbags, a rosbag2 ``.db3``: every 4096 messages, estimated from the message count),
    a CSV directory's files, a CSV file's parse and columns, a ULog's framing, definitions and
    topics. Multi-stage reads (ULog, a CSV file) weight each stage's bytes by its share of the read's
    time (`common.StagedBytes`). ``done`` never decreases, and the last call is ``(total, total)``.
    Registered readers (`register_reader`) are not given it.

    Messages whose bytes do not decode make the log read only in part (`common.undecoded_as_partial`).
    """
    log = _read(path, topics, use_header_stamp=use_header_stamp, progress=progress, window=window, held=held)
    undecoded_as_partial(log.source)
    return log


def _read(path, topics, *, use_header_stamp: bool, progress, window, held: bool = False) -> Log:
    fmt = detect_format(path)
    wanted = None if topics is None else set(topics)
    if fmt in READERS:
        return READERS[fmt].read(path, wanted, use_header_stamp=use_header_stamp)
    if fmt == "mcap":
        from logscan.readers.mcap import read_mcap

        return read_mcap(path, wanted, use_header_stamp=use_header_stamp, progress=progress, window=window)
    if fmt == "ulog":
        from logscan.readers.ulog_reader import read_ulog

        return read_ulog(path, wanted, progress=progress, held=held)
    if fmt in ("ros1bag", "rosbag2"):
        from logscan.readers.rosbag import read_rosbag

        return read_rosbag(path, wanted, use_header_stamp=use_header_stamp, progress=progress, held=held)
    from logscan.readers.csv_reader import read_csv, read_csv_dir

    if fmt == "csv-dir":
        return read_csv_dir(path, wanted, progress=progress)
    return read_csv(path, wanted, progress=progress)


def read_embedded(path: str | os.PathLike) -> tuple[str | None, dict | None]:
    """(profile TOML, ground truth) a log carries, read without its messages; None where absent.

    MCAP: the metadata records ``logscan.profile`` (key ``toml``) and ``logscan.truth`` (key
    ``json``), through the summary's metadata index when there is one. CSV file or directory: the
    ``<log>.profile.toml`` and ``<log>.truth.json`` sidecars. ULog, ROS 1 bag, rosbag2: neither.
    Raises like ``read_log`` for a missing, unknown or corrupt file.
    """
    fmt = detect_format(path)
    if fmt == "mcap":
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
