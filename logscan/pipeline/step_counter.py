"""The filter's steps, counted while its kernel runs: the progress a long log's filtering step shows.

The EKF is one compiled call over every step of the log (it cannot resume from a block's end,
`logscan.pipeline.refilter`), so it cannot call back per block as a reader does. Instead it writes
the steps it has filtered into a one-element array at every step, and runs without the GIL: a
thread of ours reads that array every ``interval`` seconds and hands it on as (done, total), the
same call a reader makes with the bytes it has read. With nobody listening no thread is started.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np

INTERVAL_S = 0.25  # the bar is redrawn every 0.5 s: two readings per redraw


@contextmanager
def counted_steps(
    total: int, fraction: Callable[[int, int], None] | None, interval: float = INTERVAL_S
) -> Iterator[np.ndarray]:
    """A (1,) int64 step counter for a kernel of ``total`` steps; while the block runs, its value
    goes to ``fraction(done, total)`` every ``interval`` seconds, and once more at the end."""
    counter = np.zeros(1, dtype=np.int64)
    if fraction is None or total <= 0:
        yield counter
        return
    stop = threading.Event()

    def watch() -> None:
        while not stop.wait(interval):
            fraction(int(counter[0]), total)

    watcher = threading.Thread(target=watch, name="logscan-filter-steps", daemon=True)
    watcher.start()
    try:
        yield counter
    finally:
        stop.set()
        watcher.join()
    fraction(int(counter[0]), total)  # not in `finally`: a failed filter has no fraction to show
