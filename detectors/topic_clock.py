"""A topic's sample clock: how much time a silence in it lost, so a jitter is not read as a stop.

A sensor that stops loses samples: after its silence, each sample comes later than the count of
samples before it says (t_i - i T steps up by the silence). A timestamp jitter only moves samples:
a long gap is followed (or preceded) by samples closer together, and the count catches up. So the
time a gap lost is the step of the clock offset e_i = t_i - i T across it, each side's level the
median of the B samples there (docs/algorithms.md 3c, "sensor timeouts").
"""

from __future__ import annotations

import numpy as np


def block_size(n: int) -> int:
    """B = ceil(sqrt(n)) samples per block: a block's period carries the jitter's error over B, and
    the median over n / B blocks outvotes the blocks a stop falls in."""
    return max(int(np.ceil(np.sqrt(n))), 1)


def clock_period(t_ns: np.ndarray) -> float:
    """The topic's period (ns) from sorted sample times: the median over consecutive blocks of B
    samples of each block's span / B (a jitter averages out in a block; a stop spoils only its own)."""
    n = t_ns.size
    B = block_size(n)
    starts = np.arange(0, n - B, B)
    if starts.size == 0:
        return float(t_ns[-1] - t_ns[0]) / max(n - 1, 1)
    return float(np.median((t_ns[starts + B] - t_ns[starts]).astype(np.float64) / B))


def lost_time(t_ns: np.ndarray, gaps: np.ndarray, period: float) -> np.ndarray:
    """Per gap after sample ``gaps[j]`` (sorted ``t_ns``), the time it lost (ns): the median clock
    offset of the up to B samples after it minus that of the up to B samples before it (each side
    as many as both have, at least one)."""
    n = t_ns.size
    if gaps.size == 0:
        return np.zeros(0)
    e = t_ns.astype(np.float64) - np.arange(n) * period
    side = np.minimum(np.minimum(gaps + 1, n - 1 - gaps), block_size(n))[:, None]  # (gaps, 1)
    offsets = np.arange(block_size(n))[None, :]
    use = offsets < side
    before = np.where(use, e[np.clip(gaps[:, None] - offsets, 0, n - 1)], np.nan)
    after = np.where(use, e[np.clip(gaps[:, None] + 1 + offsets, 0, n - 1)], np.nan)
    return np.nanmedian(after, axis=1) - np.nanmedian(before, axis=1)
