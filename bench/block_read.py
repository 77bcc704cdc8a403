"""The CPU and peak memory of reading and aligning consecutive blocks of a long indexed MCAP log,
as block mode reads them (a window with a 240-s lead-in, aligned), with the file's plan kept from
one block to the next where the tree has one (`ReadWindow.plans`).

    python bench/block_read.py LOG [FIRST_S [BLOCK_S [COUNT]]]    # default: 43200 s, 1800 s, 3 blocks
    PYTHONPATH=../before python bench/block_read.py LOG           # a tree without plans: each block alone

Prints one line per block: its read and alignment's CPU seconds (user, system) and the peak RSS so far.
"""

from __future__ import annotations

import inspect
import resource
import sys

from logscan.align import align
from logscan.profiles import parse_profile
from logscan.readers import read_embedded_profile, read_log
from logscan.readers.common import ReadWindow

LEAD_IN_S = 240.0  # what block mode reads before a block (`logscan.pipeline.lead_in.MAX_LEAD_IN_S`)
MARGIN_S = 5.02  # a 100 Hz profile's (`preparation._read_window`)


def cpu() -> tuple[float, float]:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime, usage.ru_stime


def main(argv: list[str]) -> int:
    if not 1 <= len(argv) <= 4:
        print(__doc__)
        return 2
    path = argv[0]
    first, block, count = (
        (float(argv[1]) if len(argv) > 1 else 43200.0),
        (float(argv[2]) if len(argv) > 2 else 1800.0),
        (int(argv[3]) if len(argv) > 3 else 3),
    )
    profile = parse_profile(read_embedded_profile(path), source=path)
    plans: dict = {}
    kept = "plans" in inspect.signature(ReadWindow).parameters
    for k in range(count):
        start, end = first + k * block, first + (k + 1) * block
        window = ReadWindow(start - LEAD_IN_S, end, MARGIN_S, **({"plans": plans} if kept else {}))
        before = cpu()
        log = read_log(path, topics=profile.topics(), window=window)
        align(log, profile, start_s=start, end_s=end)
        user, system = (b - a for a, b in zip(before, cpu()))
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(
            f"block {k + 1}: {start:.0f}-{end:.0f} s  CPU {user + system:.2f} s "
            f"(user {user:.2f}, sys {system:.2f})  peak {peak:.0f} MiB"
        )
        del log
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
