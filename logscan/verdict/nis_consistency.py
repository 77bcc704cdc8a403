"""The filter's consistency warnings: a measurement group whose NIS is far from the chi-square law
of its size says the profile's model or noise does not fit the log (`NisConsistency.lines`).

They are judged on each group's NIS at its updates (`nis_consistency`), kept as those values, so
that a log analysed in blocks judges the log's values summed over its blocks (`summed`), not each
block's on its own (docs/algorithms.md section 8.1b). A group may come in pieces (a block's each, in
order): its median, mean and tail count are the pieces' together, read a piece at a time
(`order_statistic`), so judging a day-long log holds a piece, not the group.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.special import bdtrc, chdtri  # chi-square quantiles without scipy.stats (46 MB to import)

from logscan.docs import doc_url
from logscan.log import read_in_chunks

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
    the detectors judge (the [alarms] policy's steps): the log's, or a piece of it."""

    name: str
    size: int
    nis: np.ndarray
    judged: np.ndarray


@dataclass
class NisConsistency:
    """Each group's NIS at its updates (`nis_consistency`); ``said``: the lines given for them."""

    groups: Sequence[GroupNis]  # a group's pieces in time order (block mode: `logscan.pipeline.kept_nis`)
    said: frozenset[str] = frozenset()

    def group_names(self) -> list[str]:
        """The groups' names, in the order they first come."""
        return list(pieces_by_group([self]))

    def lines(self, alarmed: set, calibrate: str, uncalibrated: frozenset = frozenset()) -> list[str]:
        """One warning per group whose median NIS is far above the chi-square median of its size, or
        whose mean NIS per output over the judged updates is blind (below NIS_BLIND); ``alarmed``: the
        groups whose checks alarmed (a fault over much of the log, rather than a mismatch);
        ``calibrate``: the command that calibrates the noise; ``uncalibrated``: the groups the tables'
        calibration could not bring to 1."""
        out = []
        for name, pieces in pieces_by_group([self]).items():
            updates, size = sum(piece.nis.size for piece in pieces), pieces[0].size
            if updates < NIS_MIN_UPDATES or not size:
                continue
            ratio = _median([piece.nis for piece in pieces]) / float(chdtri(size, 0.5))
            if ratio > NIS_MISMATCH:
                out.append(_mismatch_line(name, ratio, name in alarmed, calibrate))
            else:
                out.extend(_blind_line(pieces, calibrate, name in uncalibrated))
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
    """Each group's pieces in ``parts`` (and within each), in order, by name (in the order the groups
    first come)."""
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


def _blind_line(pieces: list[GroupNis], calibrate: str, kept: bool) -> list[str]:
    """The "blind" warning of the group in ``pieces`` when its mean NIS per output is below
    NIS_BLIND over the judged updates (all of them when fewer than NIS_MIN_UPDATES are judged)."""
    judged = sum(int(np.count_nonzero(piece.judged)) for piece in pieces) >= NIS_MIN_UPDATES
    nis, masks = [piece.nis for piece in pieces], [piece.judged for piece in pieces] if judged else None
    name, size = pieces[0].name, pieces[0].size
    updates = sum(int(np.count_nonzero(mask)) for mask in masks) if masks else sum(part.size for part in nis)
    if len(nis) == 1:
        level = float(np.mean(nis[0][masks[0]] if masks else nis[0])) / size
    else:  # the pieces' sums added: the joined values' mean to its last bits
        level = sum(float(np.sum(chunk)) for chunk in _chunks(nis, masks)) / updates / size
    if not level < NIS_BLIND:
        return []
    tail = heavy_tail(nis, size, level, masks)
    if tail is not None:
        return [
            f"group {name!r} is blind most of the time: mean NIS per output {level:.3g} over {updates} updates "
            f"(about 1 expected, {NIS_BLIND:g} at the least), but its NIS is not one scaled chi-square: fitted to "
            f"that mean, {tail[0]} of them would pass its {TAIL_ALPHA:.1%} point ({tail[1]:.2g} expected). Its "
            "scatter varies over the log (quiet stretches and larger ones: at rest and moving, or a fault), so no "
            "one noise_std fits it: a smaller one alarms on the larger stretches, and a fault smaller than the "
            "present one hides in the quiet ones"
        ]
    return [
        f"group {name!r} is blind: mean NIS per output {level:.3g} over {updates} updates (about 1 "
        f"expected, {NIS_BLIND:g} at the least): its noise_std is {1.0 / np.sqrt(level):.3g} times the scatter "
        "the filter sees, so a fault of that size hides; "
        + (
            "the tables' calibration found no noise_std that brings it to 1 (see their training report)"
            if kept
            else f"lower noise_std: `{calibrate}`, then analyze with --tables tables.json"
        )
    ]


def heavy_tail(
    nis: np.ndarray | list[np.ndarray], size: int, level: float, judged: list[np.ndarray] | None = None
) -> tuple[int, float] | None:
    """(how many updates, how many expected) pass the chi-square TAIL_ALPHA point of ``size`` once
    the NIS (an array, or its pieces; only where ``judged``, the pieces' masks, where given) is
    scaled to a mean of 1 per output, when that count is beyond chance for a chi-square law
    (binomial P(K >= k) < TAIL_P: a scatter that varies, not one noise); else None."""
    pieces = [nis] if isinstance(nis, np.ndarray) else nis
    point = chdtri(size, TAIL_ALPHA)
    k = sum(int(np.count_nonzero(chunk / level > point)) for chunk in _chunks(pieces, judged))
    n = sum(int(np.count_nonzero(mask)) for mask in judged) if judged else sum(piece.size for piece in pieces)
    if k == 0 or not bdtrc(k - 1, n, TAIL_ALPHA) < TAIL_P:
        return None
    return k, n * TAIL_ALPHA


# Order statistics of pieces together: radix selection on each value's 64-bit sort key, RADIX_BITS
# at a time from the top, until the values sharing the found prefix are at most SELECT_AT_ONCE
# (those are then partitioned in memory).
RADIX_BITS = 16
SELECT_AT_ONCE = 1 << 20


def _median(pieces: list[np.ndarray]) -> float:
    """``np.median`` of the pieces joined, without joining them (one piece: ``np.median`` itself)."""
    if len(pieces) == 1:
        return float(np.median(pieces[0]))
    n = sum(piece.size for piece in pieces)
    upper = order_statistic(pieces, n // 2)
    if n % 2:
        return upper
    return float(np.mean(np.array([order_statistic(pieces, n // 2 - 1), upper])))  # as np.median does


def order_statistic(pieces: list[np.ndarray], k: int) -> float:
    """The ``k``-th smallest (from 0) of the finite float64 values in ``pieces`` together: what
    ``np.partition(np.concatenate(pieces), k)[k]`` gives, holding at most SELECT_AT_ONCE values."""
    prefix, rank = 0, k  # the sort keys' top bits found so far; k's rank among the keys with them
    for shift in range(64 - RADIX_BITS, -1, -RADIX_BITS):
        counts = np.zeros(1 << RADIX_BITS, np.int64)
        for keys in _keys_with_prefix(pieces, prefix, shift + RADIX_BITS):
            digits = (keys >> np.uint64(shift)) & np.uint64((1 << RADIX_BITS) - 1)
            counts += np.bincount(digits.astype(np.intp), minlength=counts.size)
        below = np.cumsum(counts)
        digit = int(np.searchsorted(below, rank, side="right"))  # the first bucket holding rank + 1 keys
        rank -= int(below[digit - 1]) if digit else 0
        prefix = (prefix << RADIX_BITS) | digit
        if shift == 0:  # every key with this prefix is the one value (a run of equal values)
            return float(_values(np.array([prefix], np.uint64))[0])
        if counts[digit] <= SELECT_AT_ONCE:
            kept = np.concatenate([keys for keys in _keys_with_prefix(pieces, prefix, shift)])
            return float(_values(np.partition(kept, rank)[rank : rank + 1])[0])
    raise AssertionError("unreachable: the last digit is the whole key")


_SIGN = np.uint64(1 << 63)


def _keys_with_prefix(pieces: list[np.ndarray], prefix: int, low_bits: int) -> Iterator[np.ndarray]:
    """The sort keys of the values in ``pieces`` whose top 64 - ``low_bits`` key bits are ``prefix``
    (all where ``low_bits`` is 64), a chunk at a time. A float64's key is its bits with the sign
    bit set for a positive value and every bit flipped for a negative one: keys order as the values
    (-0.0 just below 0.0, which np.partition counts equal: the value is the same)."""
    for chunk in _chunks(pieces):
        bits = np.asarray(chunk, np.float64).view(np.uint64)
        keys = np.where(bits & _SIGN, ~bits, bits | _SIGN)
        if low_bits < 64:
            keys = keys[(keys >> np.uint64(low_bits)) == np.uint64(prefix)]
        yield keys


def _values(keys: np.ndarray) -> np.ndarray:
    """The float64 values of sort keys (`_keys_with_prefix`)."""
    return np.where(keys & _SIGN, keys ^ _SIGN, ~keys).view(np.float64)


def _chunks(pieces: list[np.ndarray], masks: list[np.ndarray] | None = None) -> Iterator[np.ndarray]:
    """Each piece's values (where its mask is set, given masks) a chunk at a time: pieces waiting on
    disk (`logscan.readers.spill`) are told as read (`read_in_chunks`), so their pages go back as
    the pass goes on."""
    for i, piece in enumerate(pieces):
        if masks is None:
            yield from read_in_chunks(piece)
        else:
            for values, mask in zip(read_in_chunks(piece), read_in_chunks(masks[i]), strict=True):
                yield values[mask]
