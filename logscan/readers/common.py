"""Helpers every reader shares: format magic bytes, which inputs may be opened and how OS errors read,
which topics and channels are wanted, time-order warnings, messages lost to damage, byte progress of
a read in stages."""

from __future__ import annotations

import errno
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from logscan.errors import InputError
from logscan.input_files import SPECIAL_FILE_HINT, os_error_text, special_kind
from logscan.log import SourceInfo

MCAP_MAGIC = b"\x89MCAP0\r\n"
ULOG_MAGIC = b"ULog\x01\x12\x35"

ZERO_TIMESTAMP_WHY = "timestamp 0 (never set by the publisher)"  # ULog and ulog2csv rows
UNDECODED_WHY = "message bytes do not decode"  # a message dropped: damaged bytes, or not its schema


@dataclass(frozen=True)
class ReadWindow:
    """The part of a log a read is for (`read_log`'s ``window``): ``start_s`` .. ``end_s`` seconds
    since the log's time zero (either None: that end of the log), and ``margin_s``, how far outside
    them a sample may still be held (a sensor's delay, an input stamped a step early)."""

    start_s: float | None
    end_s: float | None
    margin_s: float
    # path -> what a read of the file learnt that does not depend on the window (an MCAP file's
    # `logscan.readers.mcap.file_plan.FilePlan`), kept for the next window of it (block mode's)
    plans: dict | None = field(default=None, compare=False, hash=False)


def file_stat(path: str | os.PathLike) -> tuple[int, int]:
    """(size, modification time in ns) of ``path``: what tells a plan kept for a file that it changed."""
    st = os.stat(path)
    return st.st_size, st.st_mtime_ns


def input_error(exc: OSError, path: str | os.PathLike, *, directory: bool = False) -> InputError:
    """The one-line InputError for an OSError met while reading the input ``path``."""
    message, hint = os_error_text(exc, directory=directory)
    return InputError(message, path=str(path), hint=hint)


def stat_input(path: str | os.PathLike) -> os.stat_result:
    """``os.stat(path)``, checked before anything is opened: InputError when the path is missing or
    unreachable, or is not a regular file or a directory (opening a FIFO for reading blocks until
    a writer comes; a device can be endless)."""
    try:
        st = os.stat(path)
    except OSError as exc:
        raise input_error(exc, path) from None
    kind = special_kind(st.st_mode)
    if kind is not None:
        raise InputError(f"is {kind}, not a regular file", path=str(path), hint=SPECIAL_FILE_HINT)
    return st


def list_directory(path: str | os.PathLike) -> list[tuple[str, int]]:
    """(name, st_mode) of every entry of the directory ``path``, following symbolic links; entries
    that vanish or are dangling links are left out. InputError when the directory cannot be
    listed or searched (no read or no execute permission) or a read fails."""
    entries: list[tuple[str, int]] = []
    try:
        with os.scandir(path) as it:
            for entry in it:
                try:
                    entries.append((entry.name, entry.stat().st_mode))
                except (FileNotFoundError, NotADirectoryError):  # vanished, or a dangling link
                    continue
                except PermissionError:  # an entry cannot be stat'ed: the directory is not searchable
                    raise
                except OSError as exc:
                    if exc.errno == errno.ELOOP:  # a symbolic-link loop is no log
                        continue
                    raise input_error(exc, os.path.join(path, entry.name)) from None
    except OSError as exc:
        raise input_error(exc, path, directory=True) from None
    return entries


def topic_wanted(topic: str, wanted: set[str] | None) -> bool:
    """True when ``topic`` is wanted (``wanted`` None: all): it is in ``wanted``, a wanted channel
    lies under it (``topic/...``), or it lies under a wanted prefix (a profile may name an on-board
    estimator by the prefix ``/ekf/state`` of channels that a CSV holds as columns). Leading and
    trailing "/" are ignored, so ULog and CSV topics without one match too."""
    if wanted is None:
        return True
    name = topic.strip("/")
    for item in wanted:
        want = item.strip("/")
        if name == want or want.startswith(name + "/") or name.startswith(want + "/"):
            return True
    return False


def channel_wanted(channel: str, topic: str, wanted: set[str] | None) -> bool:
    """Keep ``channel`` of ``topic`` when all are wanted, it is asked for, or its whole topic is
    (as ``topic`` or ``/topic``)."""
    if wanted is None or topic in wanted or "/" + topic in wanted:
        return True
    return topic_wanted(channel, wanted)


def report_time_order(t_ns: np.ndarray, label: str, source: SourceInfo, note: str = "") -> None:
    """Warn about timestamps that go backwards or repeat; the values stay in file order.

    Used by the ULog and CSV readers. Alignment (logscan.align) sorts and deduplicates.
    """
    if t_ns.size < 2:
        return
    steps = np.diff(t_ns)
    backwards = int((steps < 0).sum())
    if backwards == 0 and bool((steps > 0).all()):
        return
    duplicates = int((np.diff(np.sort(t_ns)) == 0).sum())
    source.warnings.append(
        f"{label}: timestamps not strictly increasing ({backwards} step(s) backwards, "
        f"{duplicates} duplicate(s)); kept in file order, alignment sorts and deduplicates"
        + (f" ({note})" if note and backwards else "")
    )


class StagedBytes:
    """``progress(done, total)`` of a read that passes over one file in stages (frame it, parse its
    definitions, convert its columns), for a bar with an ETA: ``total`` is the file's size, ``done``
    that size times the share of the read done. A stage's own part is a byte fraction (bytes
    framed, bytes of the topics converted so far) weighted by the stage's measured share of the
    read's time, so the bar advances about evenly in time rather than jumping to the end after a
    fast framing pass. ``done`` never decreases and never exceeds ``total``; `finish` reports
    ``(total, total)``."""

    def __init__(self, progress: Callable[[int, int], None], size: int, shares: Sequence[float]) -> None:
        self.progress = progress
        self.size = size
        scale = 1.0 / sum(shares)
        self.shares = [share * scale for share in shares]
        self.starts = [sum(self.shares[:stage]) for stage in range(len(shares))]
        self.done = 0

    def at(self, stage: int, fraction: float) -> None:
        """Stage ``stage`` (0-based) is ``fraction`` (0..1, a byte fraction of that stage) done."""
        share = self.starts[stage] + self.shares[stage] * min(max(fraction, 0.0), 1.0)
        self.done = max(self.done, min(self.size, int(share * self.size)))
        self.progress(self.done, self.size)

    def at_bytes(self, stage: int, done: int) -> None:
        """Stage ``stage`` has passed ``done`` bytes of the file."""
        self.at(stage, done / max(1, self.size))

    def finish(self) -> None:
        self.done = self.size
        self.progress(self.size, self.size)


def undecoded_as_partial(source: SourceInfo) -> None:
    """Messages dropped because their bytes do not decode make the log read only in part, as a damaged
    chunk does: data of the log is missing, so no verdict may say it was all checked."""
    lost = [item for item in source.skipped if item.why == UNDECODED_WHY]
    if not lost:
        return
    count = sum(item.count for item in lost)
    where = ", ".join(f"{item.what} x{item.count}" for item in lost)
    text = f"{count} message(s) whose bytes do not decode dropped ({where})"
    source.partial = True
    source.partial_reason = "; ".join(filter(None, [source.partial_reason, text]))
