"""Free the large per-step series no detector still to run reads (`release_unread`), order the
detectors so that less is held while they run (`run_order`), and pack the EKF's innovations for the
report before the samples' buffer is reused (`pack_innovations_for`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from logscan.align.aligned import HeldTable
from logscan.filters.ekf import samples_side_by_side
from logscan.pipeline.refilter import RefilteredPart
from logscan.pipeline.stages import Prepared
from logscan.report.sensor_views import pack_innovations

# The large per-step series a detector declares it reads (`Detector.reads`): each is freed once no
# detector still to run reads it. What runs after the detectors (incidents, coverage, the summary)
# reads none of them.
RELEASABLE_TRACE = (
    "x_prior", "x_post", "P_prior_diag", "P_post_diag", "y", "S_diag", "K", "S", "P_prior", "P_post", "ex_variance",
)  # fmt: skip


# "z": the measurement groups' samples; "redundant": the [redundant] groups' readings
RELEASABLE_RUN = ("onboard_state", "onboard_variance", "u", "z", "mode", "redundant")


RELEASABLE = frozenset(RELEASABLE_TRACE + RELEASABLE_RUN)


# the filter whose trace the report draws against a simulated log's true states (its envelopes,
# `logscan.report.ubikf_truth_view`): without it no page reads them, and `prepare` does not make them
TRUTH_DRAWN_WITH = "ubikf"


def reads_samples(detector, prepared: Prepared | None = None) -> bool:
    """Whether a detector reads the groups' samples (undeclared reads: it may), also through a
    trace part the EKF filters again from them as it is read (K, S: `logscan.pipeline.refilter`)."""
    if detector.reads is None or "z" in detector.reads:
        return True
    traces = prepared.traces.values() if prepared is not None else ()
    return any(isinstance(getattr(trace, part, None), RefilteredPart) for trace in traces for part in detector.reads)


def run_order(prepared: Prepared, detectors: Sequence) -> list[int]:
    """The indices of ``detectors`` in the order they run, so that less is held while each runs
    (each large series is freed once no detector still to run reads it, `release_unread`):
    those that read the samples first (the report's pack then takes their buffer); then those
    that read other large series, the fewer bytes of them first (what only they read is freed
    before the heavier ones, whose working memory grows with what they read, run); last those
    that read none (running one frees nothing, and its results would be held through the others)."""

    def rank(index: int) -> tuple[int, int]:
        detector = detectors[index]
        if reads_samples(detector, prepared):
            return (0, 0)
        size = _bytes_read(prepared, detector.reads)
        return (1, size) if size else (2, 0)

    return sorted(range(len(detectors)), key=rank)


def _bytes_read(prepared: Prepared, reads: frozenset[str]) -> int:
    """The bytes of the large series among ``reads`` the prepared log holds now."""
    parts = [getattr(trace, name, None) for trace in prepared.traces.values() for name in reads]
    parts += [getattr(prepared.run, name, None) for name in reads if name in RELEASABLE_RUN]
    total = 0
    for part in parts:
        if isinstance(part, HeldTable):  # the samples at their own rate and each step's row
            total += part.samples.nbytes + part.row.nbytes
        elif isinstance(part, np.ndarray):
            total += part.nbytes
    return total


def pack_innovations_for(prepared: Prepared, detectors: Sequence, reuse_samples: bool) -> None:
    """`Prepared.innovations` from the EKF trace's innovations and the groups' samples; with
    ``reuse_samples``, into the samples' own buffer when no detector reads them (they are dropped)."""
    trace, run = prepared.trace, prepared.run
    if trace is None or trace.y is None or trace.S_diag is None:
        return
    samples = None
    if reuse_samples and not any(reads_samples(d, prepared) for d in detectors):
        samples = samples_side_by_side(run, trace.group_names, trace.group_offsets, trace.group_sizes)
    prepared.innovations = pack_innovations(run, trace, samples)
    if samples is not None:  # the buffer now holds the pack: no group may read it as samples
        for group in (*run.groups.values(), *run.redundant.values()):
            if isinstance(group.z, np.ndarray) and group.z.base is samples:
                group.z = None  # type: ignore[assignment]  # released: read by no detector still to run


def release_unread(prepared: Prepared, still_to_run: Sequence, keep: frozenset[str] = frozenset()) -> None:
    """Free the large series none of ``still_to_run`` declares it reads (all of them declare), but
    those in ``keep``."""
    wanted: set[str] = set(keep)
    for detector in still_to_run:
        if detector.reads is None:
            return
        wanted |= detector.reads
    for trace in prepared.traces.values():
        for name in RELEASABLE_TRACE:
            if name not in wanted and getattr(trace, name, None) is not None:
                setattr(trace, name, None)
    run = prepared.run
    for name in ("onboard_state", "onboard_variance", "u", "mode"):
        if name not in wanted and getattr(run, name) is not None:
            setattr(run, name, None)
    # released: read by no detector still to run (they declare what they read)
    if "z" not in wanted:
        for group in run.groups.values():
            group.z = group.fresh = group.channel_fresh = None  # type: ignore[assignment]
    if "redundant" not in wanted:
        for group in run.redundant.values():
            group.z = group.fresh = group.channel_fresh = None  # type: ignore[assignment]
