"""The blocks' groups' NIS, kept for the log's consistency warnings (`logscan.verdict.nis_consistency`).

Block mode judges the filter's consistency on the log's NIS at each group's updates, every block's
end to end, as at once (docs/algorithms.md 8.1b). Those values grow with the log (a 100 Hz
quadcopter's four groups: 3.7 MB per 30-minute block, 180 MB at 24 hours), so they wait on disk
(`logscan.readers.spill`), a few MB at a time in one file each, and the merge's warnings read them
there piece by piece (`NisConsistency.lines`): neither the blocks nor the merge hold the log's
values, whatever its length. Where nothing can be put on disk (a tmpfs ``TMPDIR``, no room) the
values stay in memory.
"""

from __future__ import annotations

from logscan.readers import spill
from logscan.verdict.nis_consistency import GroupNis, NisConsistency, summed


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
        """The log's: every block's groups' NIS end to end, as pieces (the joined parts, then the
        latest blocks'), which the warnings read one at a time."""
        found = [part for part in [*self.kept, *self.pending] if part is not None]
        return NisConsistency([group for part in found for group in part.groups]) if found else None


def _moved_to_disk(part: NisConsistency, on: bool) -> NisConsistency:
    """``part``'s arrays in one file of their own when ``on`` (`spill.copied_together`: one file
    per part, not one per array, as a process maps at most `spill.MAX_FILES`), else as they are."""
    arrays = [array for group in part.groups for array in (group.nis, group.judged)]
    with spill.spilling(on, needs=2 * sum(array.nbytes for array in arrays)):  # its end gives back the pages written
        kept = spill.copied_together(arrays)
    pairs = zip(part.groups, kept[::2], kept[1::2], strict=True)
    return NisConsistency([GroupNis(group.name, group.size, nis, judged) for group, nis, judged in pairs])
