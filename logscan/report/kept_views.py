"""Block mode's sensor figures: of each block, per measurement group, only the rows of its packed
innovations (`logscan.report.sensor_views.Innovations`) that the sensor figures would draw, with
their times, kept once the block is freed (`kept_rows`), the blocks' end to end (`KeptRows.extend`).

A block keeps, per channel of a group, the steps `logscan.report.sensor_figures.drawn_steps` picks
on the block's own steps: the extremes of each drawn series in ``points`` buckets (the block's share
of `REDUCED_POINTS`, so the log keeps about as many as its figure draws at once, whatever the number
of blocks) and every sample inside the zoom windows around the block's alarms naming the group, as
the figure at once keeps them in full, up to the log's `FOCUS_ROWS` per group (past it, their
extremes: `_thinned`); where those windows cover too much of the block to be kept, the window of the
alarm its first incident quotes, which the page's headline may open on. The rows hold the group's
`SensorView` values (float32, as its pack gives them), so each block's own offsets and scales of
the pack are applied before its rows join the others. docs/algorithms.md section 8.1b.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from logscan.report.plotly_json import in_windows, zoom_windows
from logscan.report.sensor_figures import drawn_steps
from logscan.report.sensor_views import Innovations, SensorView
from logscan.verdict.incidents import group_of

_FIELDS = ("measured", "predicted", "sigma", "normalised")
_NO_WINDOWS = np.zeros((0, 2))
DRAWN_SERIES = 5  # a channel's figure draws predicted, measured, the band's two edges, the normalised innovation
# The rows kept inside zoom windows, per group over the whole log: 1,000 s of a 100 Hz group in full,
# about 28 MB for the quadcopter's groups together, so a log alarming all day stays within the
# memory bound (at once, as in a block, a page draws at most POINT_BUDGET * FOCUS_SHARE = 4,500
# points of a trace inside its windows, the extremes of what is kept there).
FOCUS_ROWS = 100_000


class KeptRows:
    """Every group's kept rows: its `SensorView` values and their times (seconds, float64), in time
    order; read as `Innovations` is (`view`, `normalised`, `predicted`, `times`)."""

    def __init__(self) -> None:
        self.group_names: list[str] = []
        self.channels: dict[str, list[str]] = {}
        self._pieces: dict[str, list[tuple[np.ndarray, SensorView]]] = {}
        self._joined: dict[str, tuple[np.ndarray, SensorView]] = {}
        self._lead: dict[str, np.ndarray] = {}  # group -> its rows' spans (K, 2) that replace earlier rows
        self.focus: dict[str, int] = {}  # group -> the rows added from inside zoom windows

    def add(
        self, group: str, t: np.ndarray, view: SensorView, replaces: np.ndarray | None = None, focus: int = 0
    ) -> None:
        """A block's rows of ``group`` at the times ``t``, ``focus`` of them from inside zoom windows,
        after the rows added before but for those of them inside ``replaces`` (spans (K, 2): its
        lead-in's zoom windows, kept here)."""
        if group not in self._pieces:
            self.group_names.append(group)
            self.channels[group] = list(view.channels)
            self._pieces[group] = []
        self.focus[group] = self.focus.get(group, 0) + focus
        if replaces is not None and replaces.size:
            self._lead[group] = replaces
            self._pieces[group] = [_without(p, replaces) for p in self._pieces[group]]
        self._pieces[group].append((t, view))
        self._joined.pop(group, None)

    def extend(self, other: KeptRows) -> None:
        """``other``'s rows (a later block's) after these, its lead-in's in place of theirs."""
        for group in other.group_names:
            for t, view in other._pieces[group]:
                self.add(group, t, view, other._lead.get(group))
            self.focus[group] += other.focus.get(group, 0)

    def _rows(self, group: str) -> tuple[np.ndarray, SensorView] | None:
        """The group's pieces joined once in time order (then kept as the one piece)."""
        pieces = self._pieces.get(group)
        if not pieces:
            return None
        if group not in self._joined:
            t = np.concatenate([p[0] for p in pieces])
            order = np.argsort(t, kind="stable")  # a lead-in's rows come before the block's own
            arrays = [np.concatenate([getattr(p[1], name) for p in pieces])[order] for name in _FIELDS]
            self._joined[group] = t[order], SensorView(group, self.channels[group], *arrays)
            self._pieces[group] = [self._joined[group]]
        return self._joined[group]

    def view(self, group: str) -> SensorView | None:
        rows = self._rows(group)
        return None if rows is None else rows[1]

    def times(self, group: str, t: np.ndarray) -> np.ndarray:
        """The times of the group's rows (``t``, the merged grid, is not theirs)."""
        rows = self._rows(group)
        return t[:0] if rows is None else rows[0]

    def normalised(self, group: str) -> np.ndarray | None:
        rows = self._rows(group)
        return None if rows is None else rows[1].normalised

    def predicted(self, group: str, channels: Sequence[int]) -> np.ndarray | None:
        rows = self._rows(group)
        return None if rows is None else rows[1].predicted[:, list(channels)]

    def nbytes(self) -> int:
        return sum(t.nbytes + sum(getattr(v, f).nbytes for f in _FIELDS) for p in self._pieces.values() for t, v in p)


def _taken(view: SensorView, rows) -> SensorView:
    """``view`` at ``rows`` (a slice, a mask or indices of its steps)."""
    return SensorView(view.group, view.channels, *(getattr(view, name)[rows] for name in _FIELDS))


def _without(piece: tuple[np.ndarray, SensorView], spans: np.ndarray) -> tuple[np.ndarray, SensorView]:
    """``piece``'s rows outside the sorted disjoint ``spans``."""
    t, view = piece
    keep = ~in_windows(t, spans)
    if keep.all():
        return piece
    return t[keep], _taken(view, keep)


def kept_rows(
    innovations: Innovations,
    t: np.ndarray,
    first: int,
    alarms: Sequence,
    points: int,
    focus_rows: Callable[[str], int] | None = None,
    quoted: Sequence = (),
) -> KeptRows:
    """Of ``innovations`` on the block's grid ``t``, from its step ``first`` on, each group's rows
    its sensor figures draw with at most ``points`` per series, and every one inside the zoom
    windows around the ``alarms`` that name the group; of the lead-in before ``first`` (the block
    before's steps) only those inside the windows, which replace the block before's there (an
    alarm from a border is drawn in full from before it, as at once). ``focus_rows``: how many rows
    inside the windows a group may keep (None: all); past it, their extremes (`_thinned`).
    ``quoted``: alarms a report's headline may zoom to (the block's first incident's), whose
    windows are kept even where the windows of all alarms cover too much of the block to be."""
    own = t[first:]
    kept = KeptRows()
    names = innovations.group_names
    for group in names:
        windows = zoom_windows(_spans(alarms, group, names), own)  # as many of the block's own as at once of the log
        if not windows.size:  # alarms all over the block: of them only the headline's window
            windows = zoom_windows(_spans(quoted, group, names), own, whatever_they_cover=True)
        view = innovations.view(group)
        if view is None:
            continue
        ours = _taken(view, slice(first, None))
        overview = [drawn_steps(ours, j, own, _NO_WINDOWS, points) + first for j in range(len(view.channels))]
        inside = np.flatnonzero(in_windows(t, windows) & np.isfinite(view.predicted).any(axis=1))
        led = inside.size > 0 and inside[0] < first  # the lead-in's rows inside: they replace earlier ones
        if focus_rows is not None:
            inside = _thinned(view, t, inside, focus_rows(group))
        rows = np.unique(np.concatenate([inside, *overview]))
        replaced = np.column_stack([windows[:, 0], np.minimum(windows[:, 1], own[0])]) if led else None
        kept.add(
            group,
            t[rows],
            _taken(view, rows),
            None if replaced is None else replaced[replaced[:, 0] < own[0]],
            focus=inside.size,
        )
    return kept


def _spans(alarms: Sequence, group: str, names: Sequence[str]) -> list[tuple[float, float]]:
    """The spans of the ``alarms`` naming ``group``."""
    return [(float(a.start), float(a.end)) for a in alarms if group_of(a.signal, names) == group]


def _thinned(view: SensorView, t: np.ndarray, rows: np.ndarray, limit: int) -> np.ndarray:
    """``rows`` (steps of ``view`` at the times ``t``), or past ``limit`` of them those drawing each
    channel's series with the most and least of each of ``limit / (DRAWN_SERIES * channels)``
    buckets (at least 16 points per series): the peaks a page draws inside a zoom window stay."""
    if rows.size <= limit:
        return rows
    inside, channels = _taken(view, rows), len(view.channels)
    points = max(16, limit // (DRAWN_SERIES * channels))
    picked = [drawn_steps(inside, j, t[rows], _NO_WINDOWS, points) for j in range(channels)]
    return rows[np.unique(np.concatenate(picked))]
