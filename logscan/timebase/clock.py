"""The log's own clock: what the report axis, alarm times and summaries count time in.

Inside logscan every time is seconds since the log's time zero (the analysis grid's ``t``); a user
reads a log in its own clock. `clock_of` derives that clock from a Log and the time zero its run
counts from (``AlignedRun.start_ns``):

- time zero in the epoch range (2000-2100, whatever the format: MCAP log_time, a CSV's absolute
  time column, a ULog from a simulator whose boot time is wall-clock time) -> "UTC";
- else a PX4 ULog -> "PX4 boot time" (ULog timestamps are microseconds since PX4 booted, so the
  logger's start is itself a boot time); a GNSS time in the log (``time_utc_usec`` of
  vehicle_gps_position / sensor_gps, when read) gives the UTC of time zero too, shown in the log
  facts, while the axis stays boot time as PX4's own tools show it;
- else "time since log start" (simulated logs counting from 0), offset 0.

Clock time = t + offset_s (seconds; epoch seconds for UTC).
"""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass
from typing import Any

import numpy as np

EPOCH_MIN_S = 946_684_800.0  # 2000-01-01T00:00:00Z: earlier "absolute" times are not wall-clock
EPOCH_MAX_S = 4_102_444_800.0  # 2100-01-01T00:00:00Z
BOOT_TIME = "PX4 boot time"
UTC = "UTC"
SINCE_START = "time since log start"
# GNSS receiver time of PX4 logs (microseconds since the epoch, 0 before a fix); the pipeline reads
# these channels when the log has them so that `clock_of` can date a ULog's boot time
GNSS_UTC_CHANNELS = ("/vehicle_gps_position_0/time_utc_usec", "/sensor_gps_0/time_utc_usec")
_FLOAT32_MAX_S = 8192.0  # below this a float32 axis value resolves 1 ms (2**13 s * 2**-23)


@dataclass(frozen=True)
class Clock:
    """A log's clock: ``name``, the clock time of the analysis' time zero (``offset_s``), whether
    the clock is UTC, and the UTC epoch seconds of time zero when known (``utc_zero_s``)."""

    name: str = SINCE_START
    offset_s: float = 0.0
    utc: bool = False
    utc_zero_s: float | None = None

    @property
    def relative(self) -> bool:
        """True for "time since log start": clock times are the analysis' own times."""
        return self.name == SINCE_START and self.offset_s == 0.0

    def at(self, t: Any) -> Any:
        """Clock time of analysis time ``t`` (a float or an array)."""
        return t + self.offset_s

    def utc_text(self, t: float, *, date: bool = True) -> str | None:
        """ISO 8601 UTC of analysis time ``t`` ("2024-03-18T14:49:30.123Z"), None when unknown;
        ``date=False``: the time of day only ("14:49:30.123")."""
        if self.utc_zero_s is None or not np.isfinite(t):
            return None
        stamp = _dt.datetime.fromtimestamp(self.utc_zero_s + float(t), tz=_dt.UTC)
        if not date:
            return stamp.strftime("%H:%M:%S.") + f"{stamp.microsecond // 1000:03d}"
        return stamp.isoformat(timespec="milliseconds").replace("+00:00", "Z")

    def text(self, t: float, digits: int = 2) -> str:
        """Analysis time ``t`` as the clock shows it: "1234.56 s" or "2024-03-18 14:49:30.123 UTC"."""
        if self.utc:
            return self.utc_text(t).replace("T", " ").replace("Z", " UTC")
        return f"{self.at(float(t)):.{digits}f} s"

    def short(self, t: float, digits: int = 3) -> str:
        """A table cell: clock seconds ("1234.567"), or the UTC time of day ("14:49:30.123")."""
        return self.utc_text(t, date=False) if self.utc else f"{self.at(float(t)):.{digits}f}"

    def span_text(self, start: float, end: float, digits: int = 2) -> str:
        """An interval in the clock: "1234.56-1238.00 s", "2024-03-18 14:49:30.123-14:49:34.000 UTC"
        (the date once, when both ends share it)."""
        if not self.utc:
            return f"{self.at(float(start)):.{digits}f}-{self.at(float(end)):.{digits}f} s"
        first, last = self.utc_text(start), self.utc_text(end)
        same_day = first[:10] == last[:10]
        tail = self.utc_text(end, date=False) if same_day else last.replace("T", " ").replace("Z", "")
        return f"{first.replace('T', ' ').replace('Z', '')}-{tail} UTC"

    def axis_title(self) -> str:
        """The time axis' title: "PX4 boot time (s)", "UTC", "time since log start (s)"."""
        return self.name if self.utc else f"{self.name} (s)"

    def describe(self) -> str:
        """What the times of this clock count, named once above them (the terminal's ``times:``
        line, the Markdown summary's): "PX4 boot time (s); time zero at 20.309 s", "UTC (...)"."""
        utc = self.utc_text(0.0)
        if self.utc:
            return f"UTC (the log's clock; time zero {utc})"
        if self.relative:
            return self.axis_title()
        dated = f" = {utc} (GNSS)" if utc else ""
        return f"{self.axis_title()}; time zero at {self.at(0.0):.3f} s{dated}"

    def axis_values(self, x: Any) -> Any:
        """Analysis times as the report's time axis plots them: epoch milliseconds (float64, what a
        plotly date axis reads) for UTC; clock seconds otherwise, as float32 while that resolves
        1 ms over the log (keeps the page small), float64 beyond."""
        if x is None:
            return None
        arr = np.asarray(x, dtype=np.float64)
        if self.utc:
            return (arr + self.offset_s) * 1e3
        shifted = arr + self.offset_s
        finite = shifted[np.isfinite(shifted)]
        small = finite.size == 0 or float(np.abs(finite).max()) < _FLOAT32_MAX_S
        return shifted.astype(np.float32) if small else shifted

    def axis_value(self, t: float) -> float:
        """One analysis time on the report's axis (`axis_values`), in full float64 precision."""
        shifted = float(t) + self.offset_s
        return shifted * 1e3 if self.utc else shifted

    def stamp(self, item: dict, keys: tuple[str, ...] = ("start", "end")) -> dict:
        """``item`` (a JSON alarm or incident) with ``<key>_clock`` for each of ``keys`` it has, and
        ``<key>_utc`` (ISO 8601) when the UTC is known; the relative ``keys`` stay as they are."""
        out = dict(item)
        for key in keys:
            value = item.get(key)
            if value is None:
                continue
            out[f"{key}_clock"] = self.at(float(value))
            iso = self.utc_text(float(value))
            if iso is not None:
                out[f"{key}_utc"] = iso
        return out

    @classmethod
    def from_dict(cls, data: dict | None) -> Clock:
        """The clock of a JSON summary's log (`to_dict`'s view; None or {}: time since log start)."""
        if not data:
            return cls()
        offset, utc, start = float(data.get("offset_s", 0.0)), bool(data.get("utc")), data.get("utc_start")
        # a UTC clock's zero is its offset (to the digit); another's, its time zero in UTC (to the ms)
        zero = _dt.datetime.fromisoformat(start.replace("Z", "+00:00")).timestamp() if start else None
        zero = offset if utc else zero
        return cls(str(data.get("name", SINCE_START)), offset, utc, zero)

    def to_dict(self) -> dict:
        """The JSON view: name, offset_s, utc, and utc_start (ISO 8601 of time zero, or None)."""
        return {
            "name": self.name,
            "offset_s": self.offset_s,
            "utc": self.utc,
            "utc_start": self.utc_text(0.0),
        }


def is_epoch_s(seconds: float | None) -> bool:
    """True for a time in the plausible wall-clock range (2000-2100, epoch seconds)."""
    return seconds is not None and EPOCH_MIN_S <= seconds < EPOCH_MAX_S


def clock_of(log, start_ns: int | None = None) -> Clock:
    """The clock of ``log`` (a `logscan.log.Log`) whose analysis counts from ``start_ns`` (the
    aligned run's time zero; default: the log's own, ``log.origin_ns``). See the module docstring."""
    zero_ns = log.origin_ns if start_ns is None else start_ns
    if zero_ns is None:
        return Clock()
    zero_s = int(zero_ns) / 1e9
    if is_epoch_s(zero_s):
        return Clock(UTC, zero_s, utc=True, utc_zero_s=zero_s)
    if log.source.format == "ulog" or _ulog2csv_export(log.source):
        return Clock(BOOT_TIME, zero_s, utc_zero_s=gnss_utc_zero(log, int(zero_ns)))
    return Clock()


def _ulog2csv_export(source) -> bool:
    """Whether a CSV folder is a PX4 ulog2csv export (every topic in its layout): its timestamps are
    the ULog's own, microseconds since PX4 booted, and its times read as the .ulg's do."""
    topics = getattr(source, "topics", None) or {}
    return source.format == "csv-dir" and bool(topics) and all(t.schema == "ulog2csv" for t in topics.values())


def gnss_utc_zero(log, zero_ns: int) -> float | None:
    """UTC epoch seconds of log time ``zero_ns`` from the GNSS receiver's time in the log: the median
    over valid samples of (GNSS UTC - log time), robust to a receiver's first fixes; None without
    such samples (not read, no fix)."""
    for name in GNSS_UTC_CHANNELS:
        channel = log.channels.get(name)
        if channel is None or len(channel) == 0:
            continue
        utc_s = channel.values / 1e6
        valid = (utc_s >= EPOCH_MIN_S) & (utc_s < EPOCH_MAX_S)
        if not valid.any():
            continue
        # utc(t) = utc_zero + (t - zero): each valid sample gives one estimate of utc_zero
        estimates = utc_s[valid] - (channel.t[valid] - zero_ns) / 1e9
        return float(np.median(estimates))
    return None
