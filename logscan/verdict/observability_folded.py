"""The observability verdict of a long log with its final windows reduced to what the verdict's
readers read of them (block mode, issue 29 item 2; docs/algorithms.md section 10, "Block mode").

The merged `Observability` is read only by `blind_periods` (the summary's ``unobservable``, the
report's shading, `describe`) at the reference sizes and by `event_verdict` (per truth event at its
own magnitude). So of the rows no later block can replace (`FoldedObservability.reduced`) it keeps:

- per (direction, kind) the runs of blind rows at the reference size, each as the starts of its
  first and last row (`spans_of` reads no more), a run still going at the last reduced row open
  (``pending``) so the next rows join it as `true_runs` joins adjacent rows;
- per truth event the largest finite evidence of its direction among the reduced rows it fills
  (`inside_rows`): with m^2 >= 0, ``m^2 x >= snr_min^2`` holds for some x exactly when it holds for
  their maximum (rounding is monotonic), so the verdict is the one the rows give;
- the first row's start (the report's time axis).

The rows after them stay at full resolution in ``t_start`` and ``evidence`` (the block still open).
Every output is then exactly the unreduced verdict's, and the state grows with the number of blind
runs, not with the log's length.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from logscan.alarms import true_runs
from logscan.verdict.observability import (
    REFERENCE_SIZE,
    Observability,
    blind_rows,
    fault_scale,
    inside_rows,
    spans_of_runs,
)

_NO_RUNS = np.empty((0, 2))


@dataclass
class FoldedObservability(Observability):
    """An `Observability` whose rows before ``t_start[0]`` are reduced (module docstring)."""

    events: tuple = ()  # the log's truth events the maxima are kept for
    first_start: float | None = None  # the first reduced row's start (None: none reduced)
    last_reduced: float = -np.inf  # the last reduced row's start: no row may come before it any more
    runs: dict = field(default_factory=dict)  # (direction, kind) -> (R, 2) closed runs [first, last] start
    pending: dict = field(default_factory=dict)  # (direction, kind) -> [first, last] start of the run open at the end
    maxima: dict = field(default_factory=dict)  # `_key` of an event -> the largest finite evidence it fills

    @property
    def t_first(self) -> float:
        return self.t_start[0] if self.first_start is None else self.first_start

    def unobservable_intervals(self, d: int, kind: str, magnitude: float | None = None) -> list[tuple[float, float]]:
        """As `Observability.unobservable_intervals`, at the reference size only (the runs kept)."""
        if magnitude is not None and magnitude != REFERENCE_SIZE[kind]:
            raise ValueError("a reduced observability verdict keeps the blind periods at the reference sizes only")
        blind = blind_rows(self.evidence[:, d], kind, None, self.snr_min)
        closed, still = _runs_of(blind, self.t_start, self.pending.get((d, kind)))
        last = _NO_RUNS if still is None else still[None, :]
        runs = np.concatenate((self.runs.get((d, kind), _NO_RUNS), closed, last))
        return spans_of_runs(runs[:, 0], runs[:, 1], self.stride_s, self.t_end)

    def seen_before(self, event, magnitude: float) -> bool | None:
        """Whether the reduced rows the event fills saw it (their maximum's verdict); None: none."""
        if self.first_start is not None and _key(event) not in self.maxima:
            raise LookupError(f"no verdict kept for {event}: not among the events the verdict was reduced for")
        past = self.maxima.get(_key(event), -np.inf)
        if past == -np.inf:
            return None
        size = fault_scale(event.kind, magnitude)
        return bool(size * size * past >= self.snr_min**2)

    def nbytes(self) -> int:
        """The bytes of what the verdict keeps per row or per blind run (the rows in full, the runs)."""
        runs = sum(r.nbytes for r in self.runs.values()) + 16 * (len(self.pending) + len(self.maxima))
        return self.t_start.nbytes + self.evidence.nbytes + runs

    def reduced(self, rows: int) -> FoldedObservability:
        """This verdict with its first ``rows`` rows reduced (no later block may replace them)."""
        if rows <= 0:
            return self
        t_start, evidence = self.t_start[:rows], self.evidence[:rows]
        runs, pending = self._runs_with(t_start, evidence)
        maxima = self._maxima_with(t_start, evidence)
        return replace(
            self,
            t_start=self.t_start[rows:].copy(),  # copies: `windows_once` grows them in place
            evidence=self.evidence[rows:].copy(),
            first_start=self.t_first,
            last_reduced=float(t_start[-1]),
            runs=runs,
            pending=pending,
            maxima=maxima,
        )

    def _runs_with(self, t_start: np.ndarray, evidence: np.ndarray) -> tuple[dict, dict]:
        """(runs, pending) with the rows (``t_start``, ``evidence``) after those reduced so far."""
        runs, pending = dict(self.runs), {}
        for d, direction in enumerate(self.directions):
            for kind in self.kinds_of(direction):
                blind = blind_rows(evidence[:, d], kind, None, self.snr_min)
                closed, still = _runs_of(blind, t_start, self.pending.get((d, kind)))
                runs[(d, kind)] = np.concatenate((runs.get((d, kind), _NO_RUNS), closed))
                if still is not None:
                    pending[(d, kind)] = still
        return runs, pending

    def _maxima_with(self, t_start: np.ndarray, evidence: np.ndarray) -> dict:
        """The events' maxima with the rows (``t_start``, ``evidence``) after those reduced so far."""
        maxima = dict(self.maxima)
        for event in self.events:
            direction = self.find(event.target, event.channels or ())
            if direction is None:
                continue
            column = evidence[:, direction]
            inside = inside_rows(t_start, column, event, self)
            here = float(column[inside].max()) if inside.any() else -np.inf
            maxima[_key(event)] = max(maxima.get(_key(event), -np.inf), here)
        return maxima


def folded(verdict: Observability, events) -> FoldedObservability:
    """``verdict`` as a `FoldedObservability` (nothing reduced yet) that keeps ``events``' maxima."""
    if isinstance(verdict, FoldedObservability):
        return verdict
    return FoldedObservability(
        **{name: getattr(verdict, name) for name in Observability.__dataclass_fields__}, events=tuple(events)
    )


def _key(event) -> tuple:
    """What of a truth event picks the rows it fills (its direction and span): its verdict at any
    magnitude or kind reads the same maximum."""
    return (event.target, tuple(event.channels or ()), event.t_start, event.t_end)


def _runs_of(blind: np.ndarray, t_start: np.ndarray, pending) -> tuple[np.ndarray, np.ndarray | None]:
    """(the closed runs, the run still open at the last row or None) of the rows' ``blind`` mask,
    the run ``pending`` before them joined to a run starting at their first row."""
    first, stop = true_runs(blind)
    runs = np.column_stack((t_start[first], t_start[stop - 1]))
    if pending is not None:
        if blind.size and blind[0]:
            runs[0, 0] = pending[0]
        else:
            runs = np.concatenate((pending[None, :], runs))
    if blind.size and blind[-1]:
        return runs[:-1], runs[-1].copy()
    return runs, None
