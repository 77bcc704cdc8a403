"""A window's EKF started from the log before it (`lead_in_start`, `filter_start`).

A window (--start/--end) that begins after the log's first grid step would start its filter from
the model's prior, mid-flight: the prior's state (at rest, level) and its covariance are not the
vehicle's, and the first updates' innovations judge that, not the sensors (on the quadcopter the
prior is 26-50 standard deviations from the whole run's state, and the first second's NIS 5-15 off).
A profile's ``ignore_start_s`` would also hold back the window's own first seconds, not the log's.

So the filter starts earlier and is filtered up to the window's first step, which it predicts but
does not update: that prediction and its covariance are the window filter's prior there, as the
whole run's are. How much earlier is the filter's own answer: lead-ins of LEAD_IN_S (30 s, the KGN
probe's lead, docs/algorithms.md section 3), then twice, four times ... as long, up to MAX_LEAD_IN_S,
until two of them agree where the detectors look, in the window's first second of innovations
(`settled`); the longer is taken. A lead-in that reaches back to the log's first step is the whole
run's start, exact without a comparison: the window's trace is then the whole run's rows
(tests/test_lead_in.py). One that does not settle by MAX_LEAD_IN_S is taken with a warning.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from logscan.filters.ekf import pack_run
from logscan.pipeline.refilter import filter_rows

LEAD_IN_S = 30.0  # the first lead-in tried, s
CHUNK = 4096  # rows filtered at a time (their full covariances: 2 x 4096 x n x n float64)
MAX_LEAD_IN_S = 240.0  # the longest (read with the window's chunks): 30, 60, 120, 240 s
# Two starts agree when the window's innovations over its first SETTLED_OVER_S, filtered from each,
# differ by at most SETTLED_SIGMA of their predicted spread sqrt(S), output by output, and their
# predicted variances S by at most SETTLED_VARIANCE: what the detectors judge then moves by less
# than a tenth of its noise (a NIS of about 1 per output by about 0.2). States the measurements do
# not see (a random walk no sensor observes) may differ without changing what is judged.
SETTLED_SIGMA = 0.1
SETTLED_VARIANCE = 0.1
SETTLED_OVER_S = 1.0
NO_PARTS = {"store_gain": False, "store_S": False, "store_innovations": False}  # x and P only


@dataclass(frozen=True)
class FilterStart:
    """The EKF's prior at a window's first step, from the lead-in filtered into it."""

    start_s: float  # the lead-in's first grid time (seconds since the log's time zero)
    x0: np.ndarray  # (n,) the prediction into the window's first step
    P0: np.ndarray  # (n, n) its covariance
    # a directly observed group not yet seeded in the lead-in (its first sample comes later): the
    # window seeds every direct group from its next sample, as a run from the model's prior does
    seed: bool = False
    warning: str = ""  # the lead-in did not settle within MAX_LEAD_IN_S

    def arguments(self) -> dict:
        """The EKF's start as `FILTERS["ekf"]` takes it."""
        return {"x0": self.x0, "P0": self.P0, "seed": self.seed}


def lead_in_start(start_s: float | None) -> float | None:
    """Where the longest lead-in of a window from ``start_s`` begins (alignment starts it no earlier
    than the log's first step, which may be before time zero); None: no window start, or at time
    zero."""
    if start_s is None or start_s <= 0.0:
        return None
    return start_s - MAX_LEAD_IN_S


def carry_freshness(run, lead) -> None:
    """The window's first step counts a sample as new only when it is newer than the step before,
    as in the whole run: the lead-in's freshness there. The window's own alignment takes any sample
    within the staleness limit as new at its first step, which would update the carried state with
    a sample the lead-in already used (a NIS of 12 where the whole run has 2.9)."""
    at = int(np.flatnonzero(np.asarray(lead.t) == run.t[0])[0])
    for groups, led in ((run.groups, lead.groups), (run.redundant, lead.redundant)):
        for name, group in groups.items():
            if name in led:
                group.fresh[0] = led[name].fresh[at]
                if group.channel_fresh is not None and led[name].channel_fresh is not None:
                    group.channel_fresh[0] = led[name].channel_fresh[at]


def filter_start(model, lead_run, first_t: float, from_log_start: bool) -> FilterStart | None:
    """The EKF's prior at the window's first grid time ``first_t``, from ``lead_run`` (the log
    aligned from the longest lead-in's start to SETTLED_OVER_S into the window; ``from_log_start``:
    that start is the log's first step). None where no lead-in can stand for the log before the
    window: no step before it, or every lead-in's filter diverged (a restart returns to the model's
    prior): the window then starts from the prior as before."""
    t = np.asarray(lead_run.t)
    at = np.flatnonzero(t == first_t)
    if at.size == 0 or at[0] == 0:
        return None
    last = int(at[0])
    k = pack_run(model, lead_run)
    lengths = [LEAD_IN_S * 2.0**i for i in range(int(np.log2(MAX_LEAD_IN_S / LEAD_IN_S)) + 1)]
    firsts = sorted({int(np.searchsorted(t, first_t - length - 1e-9)) for length in lengths} | {0}, reverse=True)
    judged = slice(last, int(np.searchsorted(t, first_t + SETTLED_OVER_S + 1e-9)))  # the window's first second
    earlier: tuple[FilterStart, tuple] | None = None
    for first in (row for row in firsts if row < last):
        start = _filtered(k, first, last, float(t[first]))
        if start is None:
            continue
        if first == 0 and from_log_start:  # the whole run's own start: nothing to compare
            return start
        seen = _innovations(k, judged, start)
        if earlier is not None and settled(earlier[1], seen):
            return start
        earlier = (start, seen)
    if earlier is None:
        return None
    longest = earlier[0]
    note = (
        f"the filter had not settled over the {first_t - longest.start_s:g} s before the window (the first "
        f"second's innovations from two lead-ins differ by more than {SETTLED_SIGMA:g} of their spread): the "
        "window's first steps may still judge the filter's start; give an earlier --start"
    )
    return FilterStart(longest.start_s, longest.x0, longest.P0, longest.seed, warning=note)


def settled(shorter: tuple, longer: tuple) -> bool:
    """Whether the window's first innovations (y, S's diagonal) from two starts agree: every y within
    SETTLED_SIGMA of the longer start's sqrt(S), every S within SETTLED_VARIANCE of it; an output
    updated from one start and not the other (a sample rejected, a group seeded) disagrees."""
    (y_short, s_short), (y_long, s_long) = shorter, longer
    if not np.array_equal(np.isfinite(y_short), np.isfinite(y_long)):
        return False
    both = np.isfinite(y_long) & np.isfinite(s_long) & (s_long > 0)
    y_close = np.abs(y_short[both] - y_long[both]) <= SETTLED_SIGMA * np.sqrt(s_long[both])
    s_close = np.abs(s_short[both] - s_long[both]) <= SETTLED_VARIANCE * s_long[both]
    return bool(np.all(y_close) and np.all(s_close))


def _innovations(k, rows: slice, start: FilterStart) -> tuple[np.ndarray, np.ndarray]:
    """(y, S's diagonal) (R, m) of the packed run's ``rows`` filtered from ``start``, as float64."""
    from_start = replace(k, x0=start.x0, P0=start.P0, seed_at_start=start.seed)
    out, _ = filter_rows(from_start, rows.start, rows.stop, store_gain=False, store_S=False, store_innovations=True)
    return out.y_out.astype(np.float64), out.S_diag_out.astype(np.float64)


def _filtered(k, first: int, last: int, start_s: float) -> FilterStart | None:
    """The packed run's rows first .. last filtered from the model's prior, the last predicted but
    not updated; None when the filter diverged (or left a non-finite state). Filtered CHUNK rows at
    a time, each from the state the one before left (`logscan.pipeline.refilter.filter_rows`: the
    same numbers), so that the full covariances it needs at the end take CHUNK rows of memory, not
    the lead-in's (240 s of a 250 Hz, 16-state INS log: 250 MB); in one go when a chunk would start
    with the direct groups' seeding half done (the kernel seeds all of them or none)."""
    direct = k.direct_groups()
    seeded = np.zeros(direct.size, dtype=bool)
    carry = None  # (x_post, P_post, last finite input, seeding pending) of the chunk before
    for start in range(first, last + 1, CHUNK):
        stop = min(start + CHUNK, last + 1)
        out, left = filter_rows(k, start, stop, carry, predict_last=stop == last + 1, **NO_PARTS)
        if out.diverged.any():
            return None
        if stop == last + 1:
            break
        seeded |= out.seeded.any(axis=0)
        pending = bool(k.seed_at_start) and not bool(np.all(seeded[direct]))
        if pending and bool(np.any(seeded[direct])):
            out, _ = filter_rows(k, first, last + 1, None, predict_last=True, **NO_PARTS)
            if out.diverged.any():
                return None
            break
        carry = (*left, pending)
    x0, P0 = out.x_prior[-1].copy(), out.P_prior_full[-1].copy()
    if not (np.all(np.isfinite(x0)) and np.all(np.isfinite(P0))):
        return None
    seeded |= out.seeded.any(axis=0)
    unseeded = bool(k.seed_at_start) and not bool(np.all(seeded[direct]))
    return FilterStart(start_s=start_s, x0=x0, P0=P0, seed=unseeded)
