"""The blocks' groups' NIS, kept for the log's consistency warnings (`logscan.verdict.nis_consistency`).

Block mode judges the filter's consistency on the log's NIS at each group's updates, every block's
end to end, as at once (docs/algorithms.md 8.1b). Those values grow with the log (a 100 Hz
quadcopter's four groups: 3.7 MB per 30-minute block, 180 MB at 24 hours), so they wait on disk
(`logscan.readers.spill`), a few MB at a time in one file each, and the merge joins one group at a
time as the warnings read it (`JoinedGroups`): the blocks hold none of it, and the merge only the
group it is judging (9 bytes per update: 78 MB for the 100 Hz accelerometer of a 24-hour log).
Where nothing can be put on disk (a tmpfs ``TMPDIR``, no room) the values stay in memory.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from logscan.readers import spill
from logscan.verdict.nis_consistency import GroupNis, NisConsistency, pieces_by_group, summed


class KeptNis:
    """The blocks' groups' NIS (`nis_consistency`), in order: the latest blocks' as they came, the
    earlier ones joined `PENDING_BYTES` at a time into a file of their own."""

    PENDING_BYTES = 8 << 20

    def __init__(self) -> None:
        self.kept: list[NisConsistency] = []
        self.pending: list[NisConsistency | None] = []
        self.pending_bytes = 0

    def add(self, part: NisConsistency | None, on_disk: bool = True) -> None:
        """``part``: a block's (None: it had no filter); ``on_disk``: whether joined parts may wait there."""
        self.pending.append(part)
        self.pending_bytes += sum(g.nis.nbytes + g.judged.nbytes for g in part.groups) if part is not None else 0
        if self.pending_bytes < self.PENDING_BYTES:
            return
        joined = summed(self.pending)
        if joined is not None:
            self.kept.append(_moved_to_disk(joined, on_disk))
        self.pending, self.pending_bytes = [], 0

    def summed(self) -> NisConsistency | None:
        """The log's: every block's groups' NIS end to end, each group joined when it is read."""
        found = [part for part in [*self.kept, *self.pending] if part is not None]
        return NisConsistency(JoinedGroups(found)) if found else None


class JoinedGroups(Sequence):
    """The groups of consecutive parts, each joined end to end only when it is read (``[i]``, a
    loop): a loop that keeps no group holds one at a time. ``names``: the groups', without joining."""

    def __init__(self, parts: Sequence[NisConsistency]) -> None:
        self._pieces = pieces_by_group(parts)
        self.names = list(self._pieces)

    def __len__(self) -> int:
        return len(self.names)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        pieces = self._pieces[self.names[index]]
        nis, judged = _joined([p.nis for p in pieces]), _joined([p.judged for p in pieces])
        return GroupNis(pieces[0].name, pieces[0].size, nis, judged)


def _joined(arrays: list[np.ndarray]) -> np.ndarray:
    """``np.concatenate(arrays)``, the pages read of those on disk given back after each: the
    join holds its result and one part's pages, not a growing share of the file pages read."""
    out = np.empty(sum(a.size for a in arrays), arrays[0].dtype)
    at = 0
    for array in arrays:
        out[at : at + array.size] = array
        at += array.size
        if spill.on_disk(array):
            spill.give_back()
    return out


def _moved_to_disk(part: NisConsistency, on: bool) -> NisConsistency:
    """``part``'s arrays in one file of their own when ``on`` (`spill.copied_together`: one file
    per part, not one per array, as a process maps at most `spill.MAX_FILES`), else as they are."""
    arrays = [array for group in part.groups for array in (group.nis, group.judged)]
    with spill.spilling(on, needs=2 * sum(array.nbytes for array in arrays)):  # its end gives back the pages written
        kept = spill.copied_together(arrays)
    pairs = zip(part.groups, kept[::2], kept[1::2], strict=True)
    return NisConsistency([GroupNis(group.name, group.size, nis, judged) for group, nis, judged in pairs])
