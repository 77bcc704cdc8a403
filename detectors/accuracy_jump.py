"""A sudden rise of a sensor's self-reported accuracy: the reported value over its own recent level.

Specified in docs/algorithms.md section 3c (the `health` detector's GNSS checks). A GNSS receiver's
reported accuracy (eph, epv, speed accuracy) follows the satellite geometry, which changes over
minutes (a satellite moves about 0.5 deg a minute; one rising or setting moves the accuracy by
tens of percent); a rise by a factor of 2 within seconds is the signal changing instead:
interference, an obstruction, or a spoofer capturing the receiver, which then reports worse
accuracy as the attack starts. That rise is a finding of its own, whatever the level.
"""

from __future__ import annotations

import numpy as np

# Entries of the (samples x window) matrix built at once: its rows are taken in slices of at most
# this many entries (8 MiB of float64), so the memory is bounded by the window, not the log (a
# 1-hour PX4 log's 67,000 GNSS reports x a 185-report window took ~560 MiB at once). The slices'
# medians are the whole matrix's, row by row.
WINDOW_ENTRIES = 2**20


def accuracy_jump(
    t_ns: np.ndarray, values: np.ndarray, window_s: float, judged: np.ndarray | None = None
) -> np.ndarray:
    """Per sample, ``values`` over the median of the finite positive values of the ``window_s``
    before it: NaN where not ``judged`` (default: every sample), where ``values`` is NaN, or where
    the window holds none.

    The reference is every valid value (NaN marks one not valid, e.g. no 3D fix), judged or not:
    a check judged only while armed still compares its first armed reports with the receiver's
    level just before arming; a reference of judged reports alone would hold only the jumped ones
    for a jump within a second of arming, and could never alarm.

    Vectorised over a window of samples (the count ``window_s`` spans at the median sample
    period), each window clipped to ``window_s`` in time, `WINDOW_ENTRIES` at a time."""
    t = np.asarray(t_ns, dtype=np.int64)
    v = np.asarray(values, dtype=np.float64)
    out = np.full(v.shape, np.nan)
    if v.size < 2:
        return out
    period = float(np.median(np.diff(t))) if np.any(np.diff(t) > 0) else 0.0
    k = int(np.clip(np.ceil(window_s * 1e9 / period), 1, v.size)) if period > 0 else 1
    good = np.where(np.isfinite(v) & (v > 0), v, np.nan)
    # row i: the k samples before sample i (NaN before the log's start), and their times
    padded = np.concatenate([np.full(k, np.nan), good])
    t_padded = np.concatenate([np.full(k, np.iinfo(np.int64).min // 2), t])
    windows = np.lib.stride_tricks.sliding_window_view(padded, k)[: v.size]  # views: nothing copied
    times = np.lib.stride_tricks.sliding_window_view(t_padded, k)[: v.size]
    oldest = t - int(window_s * 1e9)
    has = np.zeros(v.size, dtype=bool)
    reference = np.full(v.size, np.nan)
    rows = max(1, WINDOW_ENTRIES // k)
    for lo in range(0, v.size, rows):  # a slice of rows at a time: `WINDOW_ENTRIES`
        hi = min(lo + rows, v.size)
        inside = np.where(times[lo:hi] >= oldest[lo:hi, None], windows[lo:hi], np.nan)
        some = np.isfinite(inside).any(axis=1)
        has[lo:hi] = some
        if some.any():
            reference[lo:hi][some] = _row_nanmedians(inside[some])
    judge = has & np.isfinite(good)
    if judged is not None:
        judge &= np.asarray(judged, dtype=bool)
    out[judge] = good[judge] / reference[judge]
    return out


def _row_nanmedians(rows: np.ndarray) -> np.ndarray:
    """``np.nanmedian(rows, axis=1)`` of rows holding a finite value each, by one sort: NaN sorts
    last, so the n finite values of a row are its first n, their median the mean of the sorted
    row's ((n - 1) // 2)-th and (n // 2)-th. numpy's own takes a masked-array path for short rows,
    about ten times slower (3.5 s of a 1-hour PX4 log's health check)."""
    ordered = np.sort(rows, axis=1)
    n = np.count_nonzero(~np.isnan(rows), axis=1)
    low = np.take_along_axis(ordered, ((n - 1) // 2)[:, None], axis=1)[:, 0]
    high = np.take_along_axis(ordered, (n // 2)[:, None], axis=1)[:, 0]
    return (low + high) / 2
