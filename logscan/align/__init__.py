"""Alignment of a Log onto a profile's analysis grid: zero-order hold, staleness, fresh-sample masks.

INTERFACE (fixed): downstream code (filters, detectors, simulator tests) relies only on the
dataclasses below; fields may be added with defaults, never renamed or removed.

Time stays integer nanoseconds until the grid is built. Each channel is cleaned once (stable sort,
duplicate timestamps dropped keeping the last, non-finite samples removed and counted), then held
onto the grid with one compiled merge pass (numba): z[k] is the latest sample at or before t_k when it is no
older than the staleness limit, else NaN.

Time sanity (`logscan.timebase.time_sanity`, docs/algorithms.md section 8.1): the grid spans where the
input and measurement channels are dense (outlying runs dropped with a warning), its size is
checked before anything is allocated, and ``start_s``/``end_s`` cut it to a window of the log.
"""

from logscan.align.aligned import AlignedGroup, AlignedRun, HeldTable
from logscan.align.onto_grid import align
from logscan.align.sample_hold import _gaps, changed_steps, clean_samples, hold, stale_ns
from logscan.timebase.time_sanity import MAX_GRID_STEPS, check_window, outlying_runs

__all__ = [
    "MAX_GRID_STEPS",
    "AlignedGroup",
    "AlignedRun",
    "HeldTable",
    "_gaps",
    "align",
    "changed_steps",
    "check_window",
    "clean_samples",
    "hold",
    "outlying_runs",
    "stale_ns",
]
