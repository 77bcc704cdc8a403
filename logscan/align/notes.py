"""Alignment's warnings of a channel's gaps and of a group's gate, from their figures (`GapReport`,
`gate_line`): the aligner says them of its run, and block mode of the log, from the figures of each
block's own steps summed (`logscan.pipeline.block_fold`), by the same words."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

MAX_GAP_WARNINGS = 20  # gap lines given; the rest are in the report's gap list


@dataclass
class GapReport:
    """A channel's stretches without a sample for longer than its staleness limit (``limit``, as
    said), from ``starts`` to ``ends`` (seconds from the log's time zero); ``before``: of each, the
    points of the grid it was held on (the run's steps, or those a delay or a start stamp shifts)
    before its end, so a block tells the gaps ending after the block before's last step on that
    grid; ``open_end``: the last one ran to the end of the run's span without a sample (in a
    block, the next block sees where it ends)."""

    name: str
    limit: str
    starts: np.ndarray
    ends: np.ndarray
    before: np.ndarray | None = None
    open_end: bool = False


def gap_lines(reports: Iterable[GapReport]) -> list[str]:
    """One warning per topic's channels with the same gaps (a GNSS receiver's ten fields lost
    together are one line), in the order the channels were reported, at most MAX_GAP_WARNINGS."""
    channels: dict[tuple, list[str]] = {}
    for report in reports:
        if not report.starts.size:
            continue
        lengths = report.ends - report.starts
        longest = int(np.argmax(lengths))
        figures = (report.starts.size, report.limit, f"{lengths[longest]:.3f}", f"{report.starts[longest]:.3f}")
        channels.setdefault((report.name.rsplit("/", 1)[0], *figures), []).append(report.name)
    lines = []
    for (topic, count, limit, longest_s, at), names in channels.items():
        if len(names) == 1:
            what = f"channel {names[0]!r}: {count} gap{'s' if count > 1 else ''}"
        else:
            fields = ", ".join(name[len(topic) + 1 :] for name in names)
            what = f"channels {topic}/{{{fields}}}: {count} gap{'s' if count > 1 else ''} each"
        lines.append(
            f"{what} longer than stale_s={limit} s (longest {longest_s} s from t={at} s); held values are NaN there"
        )
    return lines[:MAX_GAP_WARNINGS]


def gate_line(group: str, channel: str, minimum: float, gated_s: float, total_s: float) -> str:
    """The warning of a group whose gate channel was below its minimum for ``gated_s`` of ``total_s``."""
    closed = f"below {minimum:g} for {seconds(gated_s)} s of {total_s:.1f} s"
    return f"group {group!r}: {channel} {closed}; no sample used there"


def seconds(value: float) -> str:
    """A duration in a warning: tenths of a second, or milliseconds under a tenth (a gate closed for
    a step or two is not "0.0 s")."""
    return f"{value:.1f}" if value >= 0.05 else f"{value:.3f}"
