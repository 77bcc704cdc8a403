"""The filter's consistency warnings: a measurement group whose NIS is far from the chi-square law
of its size says the profile's model or noise does not fit the log (`NisConsistency.lines`).

They are judged on each group's NIS at its updates (`nis_consistency`), kept as those values, so
that a log analysed in blocks judges the log's values summed over its blocks (`summed`), not each
block's on its own (docs/algorithms.md section 8.1b).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.special import bdtrc, chdtri  # chi-square quantiles without scipy.stats (46 MB to import)

from logscan.docs import doc_url

# A group whose median NIS is more than NIS_MISMATCH times the chi-square median of its size (a
# median: a fault over less than half of the log does not move it). Above NIS_MISMATCH times, the
# samples disagree with the prediction far beyond their noise (units, signs, frames, a wrong
# channel); below 1 / NIS_MISMATCH**2 its noise_std dwarfs the data's scatter, so a fault of that
# size hides. Checked only with enough updates to mean something.
NIS_MISMATCH = 10.0
NIS_MIN_UPDATES = 20
# A group whose mean NIS per output over the judged updates is below NIS_BLIND is blind: its test
# is looser than the data by more than 1 / sqrt(NIS_BLIND) (1.8x) in std, so a fault of that size
# hides and the verdict says so (healthy: [NIS_BLIND, 1 / NIS_BLIND], about 1 expected).
NIS_BLIND = 0.3
# A blind group's NIS scaled to a mean of 1 per output that passes its chi-square TAIL_ALPHA point on
# more updates than a chi-square law would by chance (binomial P < TAIL_P) has a scatter that varies
# over the log: no one noise_std fits, and lowering it (the usual advice) alarms on the larger
# stretches (the real Husky drive: 81 of 3951 wheel yaw rate updates against 4 expected).
TAIL_ALPHA = 0.001
TAIL_P = 0.001


@dataclass
class GroupNis:
    """One measurement group's NIS at its updates (finite ones, in time order) and which of them
    the detectors judge (the [alarms] policy's steps)."""

    name: str
    size: int
    nis: np.ndarray
    judged: np.ndarray


@dataclass
class NisConsistency:
    """Each group's NIS at its updates (`nis_consistency`); ``said``: the lines given for them."""

    groups: Sequence[GroupNis]  # a list, or block mode's groups joined as each is read (`logscan.pipeline.kept_nis`)
    said: frozenset[str] = frozenset()

    def group_names(self) -> list[str]:
        """The groups' names (of joined groups without joining them)."""
        names = getattr(self.groups, "names", None)
        return list(names) if names is not None else [group.name for group in self.groups]

    def lines(self, alarmed: set, calibrate: str, uncalibrated: frozenset = frozenset()) -> list[str]:
        """One warning per group whose median NIS is far above the chi-square median of its size, or
        whose mean NIS per output over the judged updates is blind (below NIS_BLIND); ``alarmed``: the
        groups whose checks alarmed (a fault over much of the log, rather than a mismatch);
        ``calibrate``: the command that calibrates the noise; ``uncalibrated``: the groups the tables'
        calibration could not bring to 1."""
        out = []
        for group in self.groups:  # one at a time: each joined group is dropped once judged
            if group.nis.size < NIS_MIN_UPDATES or not group.size:
                continue
            ratio = float(np.median(group.nis)) / float(chdtri(group.size, 0.5))
            if ratio > NIS_MISMATCH:
                out.append(_mismatch_line(group.name, ratio, group.name in alarmed, calibrate))
            else:
                out.extend(_blind_line(group, calibrate, group.name in uncalibrated))
        return out


def nis_consistency(trace, judged: np.ndarray | None, first_step: int = 0) -> NisConsistency | None:
    """Each group's NIS at its updates from ``first_step`` on (a block's own steps, after its
    lead-in), and which of them lie in the ``judged`` steps (None: all); None without a filter trace."""
    if trace is None or trace.nis_group is None:
        return None
    groups = []
    for g, (name, size) in enumerate(zip(trace.group_names, trace.group_sizes.tolist(), strict=True)):
        nis = trace.nis_group[first_step:, g]  # a column view: a mask picks from it a few times faster than [used, g]
        used = trace.updated[first_step:, g] & np.isfinite(nis)
        flags = np.ones(int(used.sum()), bool) if judged is None else judged[first_step:][used]
        groups.append(GroupNis(name, int(size), nis[used], flags))
    return NisConsistency(groups)


def summed(parts: Sequence[NisConsistency | None]) -> NisConsistency | None:
    """The groups' NIS of consecutive blocks, end to end: the log's (a group a block lacks adds nothing)."""
    found = [part for part in parts if part is not None]
    if not found:
        return None
    return NisConsistency(
        [
            GroupNis(
                name,
                pieces[0].size,
                np.concatenate([p.nis for p in pieces]),
                np.concatenate([p.judged for p in pieces]),
            )
            for name, pieces in pieces_by_group(found).items()
        ]
    )


def pieces_by_group(parts: Sequence[NisConsistency]) -> dict[str, list[GroupNis]]:
    """Each group's pieces in ``parts``, in order, by name (in the order the groups first come)."""
    by_name: dict[str, list[GroupNis]] = {}
    for part in parts:
        for group in part.groups:
            by_name.setdefault(group.name, []).append(group)
    return by_name


def _mismatch_line(name: str, ratio: float, alarmed: bool, calibrate: str) -> str:
    if alarmed:
        return (
            f"group {name!r}: median NIS {ratio:.3g} times its chi-square median (about 1 expected), and its "
            "checks alarmed: a fault over much of the log (the incidents below), or a model or profile "
            "mismatch (units, signs, frames, noise_std) if the log is healthy; calibrate only on healthy logs "
            f"({doc_url('troubleshooting.md')})"
        )
    return (
        f"group {name!r}: median NIS {ratio:.3g} times its chi-square median (about 1 expected): model or "
        "profile mismatch, check units, signs and frames of its channels, or its noise_std "
        f"({doc_url('troubleshooting.md')}; `{calibrate}`, then --tables tables.json)"
    )


def _blind_line(group: GroupNis, calibrate: str, kept: bool) -> list[str]:
    """The "blind" warning of ``group`` when its mean NIS per output is below NIS_BLIND over the
    judged updates (all of them when fewer than NIS_MIN_UPDATES are judged)."""
    nis = group.nis[group.judged] if int(group.judged.sum()) >= NIS_MIN_UPDATES else group.nis
    name, size = group.name, group.size
    level = float(np.mean(nis)) / size
    if not level < NIS_BLIND:
        return []
    tail = heavy_tail(nis, size, level)
    if tail is not None:
        return [
            f"group {name!r} is blind most of the time: mean NIS per output {level:.3g} over {nis.size} updates "
            f"(about 1 expected, {NIS_BLIND:g} at the least), but its NIS is not one scaled chi-square: fitted to "
            f"that mean, {tail[0]} of them would pass its {TAIL_ALPHA:.1%} point ({tail[1]:.2g} expected). Its "
            "scatter varies over the log (quiet stretches and larger ones: at rest and moving, or a fault), so no "
            "one noise_std fits it: a smaller one alarms on the larger stretches, and a fault smaller than the "
            "present one hides in the quiet ones"
        ]
    return [
        f"group {name!r} is blind: mean NIS per output {level:.3g} over {nis.size} updates (about 1 "
        f"expected, {NIS_BLIND:g} at the least): its noise_std is {1.0 / np.sqrt(level):.3g} times the scatter "
        "the filter sees, so a fault of that size hides; "
        + (
            "the tables' calibration found no noise_std that brings it to 1 (see their training report)"
            if kept
            else f"lower noise_std: `{calibrate}`, then analyze with --tables tables.json"
        )
    ]


def heavy_tail(nis: np.ndarray, size: int, level: float) -> tuple[int, float] | None:
    """(how many updates, how many expected) pass the chi-square TAIL_ALPHA point of ``size`` once
    the NIS is scaled to a mean of 1 per output, when that count is beyond chance for a chi-square
    law (binomial P(K >= k) < TAIL_P: a scatter that varies, not one noise); else None."""
    k = int(np.count_nonzero(nis / level > chdtri(size, TAIL_ALPHA)))
    if k == 0 or not bdtrc(k - 1, nis.size, TAIL_ALPHA) < TAIL_P:
        return None
    return k, nis.size * TAIL_ALPHA
