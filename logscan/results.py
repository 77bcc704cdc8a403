"""The data between layers: detector results, ground-truth fault events and the JSON summary of a
series.

Detectors produce `DetectorResult`s holding `AlarmInterval`s (defined below this module, in
`logscan.alarms`, with the shared alarm logic that makes them); scoring, the report and the artifacts
read these typed objects directly. Ground truth, whether written by `logscan simulate` or read back
from a log, is a list of `FaultEvent`s. The one JSON policy, `jsonable`, lives in
`logscan.json_policy`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, overload

import numpy as np

from logscan.alarms import AlarmInterval, alarm_intervals, judged_alarms, judged_counts, sample_masks
from logscan.errors import InputError
from logscan.json_policy import jsonable

# --- JSON summaries -------------------------------------------------------------------------------


def series_summary(values: np.ndarray, counts: tuple[int, int] | None = None) -> dict:
    """n, finite count, min and max of one series (the JSON summary's view of a statistic);
    ``counts``: (n, finite) of the full-rate series ``values`` is the envelope of (block mode)."""
    values = np.asarray(values)
    finite = np.isfinite(values)
    count = int(np.count_nonzero(finite))
    low = high = None
    if count and count + int(np.count_nonzero(np.isnan(values))) == values.size:
        # only NaN besides the finite values: fmin / fmax skip them, with no copy of the finite ones
        # (an extreme of zero is left to min / max below: which of 0.0 and -0.0 they return differs)
        low, high = float(np.fmin.reduce(values)), float(np.fmax.reduce(values))
    if count and (low is None or low == 0.0 or high == 0.0):  # an infinity, or a zero extreme
        kept = np.asarray(values[finite], dtype=np.float64)
        low, high = float(kept.min()), float(kept.max())
    n, count = (int(values.size), count) if counts is None else counts
    return {"n": n, "finite": count, "min": low, "max": high}


# --- alarms ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class GroundAround:
    """A window's (--start/--end) ground channel held on the grid steps just before and after it:
    a take-off before the window or a landing after it holds back steps inside it in the whole log."""

    t_before: np.ndarray
    before: np.ndarray
    t_after: np.ndarray
    after: np.ndarray

    def joined(self, t: np.ndarray, ground: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """(times, ground values, index of the window's first step) over the steps before, inside and
        after the window."""
        times = np.concatenate([self.t_before, t, self.t_after])
        values = np.concatenate([self.before, ground, self.after])
        return times, values, int(self.t_before.size)


@dataclass(frozen=True)
class AlarmPolicy:
    """Floors a profile puts under every statistic's alarm options (the profile's [alarms] table):
    an alarm needs at least ``n_persist`` consecutive exceeding samples and lasts at least
    ``min_duration_s`` seconds, whatever a detector asks for (so that healthy one- or two-sample
    transients cannot raise an alarm). Its suspension (ground time, take-off and landing, the start)
    is for the model-based statistics; the checks of the vehicle's own reports are never suspended
    (`unsuspended`)."""

    n_persist: int = 1
    min_duration_s: float = 0.0
    merge_gap_s: float = 1.0  # alarms of one statistic closer than this merge (logscan.verdict.incidents)
    # ground time: a channel non-zero while the vehicle is on the ground (a landed flag); no
    # statistic is judged there, nor for after_ground_s after each take-off (the transient), nor
    # for before_ground_s before each landing (a land detector confirms a touchdown late)
    ground_channel: str | None = None
    after_ground_s: float = 5.0
    before_ground_s: float = 0.0
    # a ground span shorter than this between two airborne ones is a land detector's blip, not a
    # landing (a bounce, an impact, a fall): flight, judged as flight (the built-in px4 profile:
    # PX4's own time to confirm a landing, LNDMC_TRIG_TIME)
    min_ground_s: float = 0.0
    ignore_start_s: float = 0.0  # not judged for this long from the grid's start (the filter converging)
    # (N,) bool, the grid steps not judged (from the keys above, set per run by the pipeline)
    suspended: np.ndarray | None = field(default=None, repr=False, compare=False)
    # (N,) bool, the steps in flight (said not on the ground, blips ignored); None: no ground channel
    airborne: np.ndarray | None = field(default=None, repr=False, compare=False)
    # whether ignore_start_s held back any step of the run (a window's filter led in: none)
    start_held: bool = field(default=False, repr=False, compare=False)
    # alarms are seen from this time on (`logscan.alarms` rule 6): a window's first step, when a
    # check runs on a grid led in before it (`logscan.pipeline.raw_lead`); None: from the first step
    alarms_from_s: float | None = field(default=None, repr=False, compare=False)

    @property
    def suspends(self) -> bool:
        """Whether the policy leaves any step unjudged (ground time, take-off, the start)."""
        return bool(self.ground_channel or self.ignore_start_s)

    def suspend(self, t, ground, filter_from: float | None = None, around: GroundAround | None = None) -> AlarmPolicy:
        """A copy with ``suspended`` and ``airborne`` set for a run of grid times ``t`` and held ground
        channel values ``ground`` (None: none; NaN: unknown, judged; blips under min_ground_s: flight).
        ``filter_from``: where the filter started converging, when before the run (a window's
        lead-in, `logscan.pipeline.lead_in`); ignore_start_s counts from there. ``around``: a
        window's ground channel on the grid steps just outside it, so that a take-off before it or
        a landing after it holds back what the whole log would."""
        import dataclasses

        t = np.asarray(t, dtype=np.float64)
        out = np.zeros(t.size, dtype=bool)
        if t.size and self.ignore_start_s > 0:
            out |= t < (t[0] if filter_from is None else filter_from) + self.ignore_start_s
        start_held = bool(out.any())
        on = None
        if ground is not None and t.size:
            ground = np.asarray(ground, dtype=np.float64)
            t_all, ground_all, first = (t, ground, 0) if around is None else around.joined(t, ground)
            on_all = _without_blips(t_all, np.nan_to_num(ground_all, nan=0.0) != 0.0, self.min_ground_s)
            inside = slice(first, first + t.size)
            on = on_all[inside]
            out |= self._near_ground(t_all, on_all)[inside]
        airborne = None if on is None else ~on & np.isfinite(ground)  # unknown is judged, but not flight
        return dataclasses.replace(self, suspended=out if out.any() else None, airborne=airborne, start_held=start_held)

    def _near_ground(self, t: np.ndarray, on: np.ndarray) -> np.ndarray:
        """The steps on the ground (``on``), after_ground_s after each take-off and before_ground_s
        before each landing."""
        out = on.copy()
        # the latest take-off (ground -> air) at or before each step
        takeoff = np.concatenate([[False], on[:-1] & ~on[1:]])
        last = np.maximum.accumulate(np.where(takeoff, t, -np.inf))
        out |= t < last + self.after_ground_s
        if self.before_ground_s > 0:  # the next landing (air -> ground) at or after each step
            landing = np.concatenate([[False], ~on[:-1] & on[1:]])
            following = np.minimum.accumulate(np.where(landing, t, np.inf)[::-1])[::-1]
            out |= t >= following - self.before_ground_s
        return out

    def margins_s(self) -> tuple[float, float]:
        """How far before and after a window its ground channel can change what is held back in it:
        a take-off after_ground_s before it, a landing before_ground_s after it, and a blip's
        min_ground_s on either side (0, 0: no ground channel)."""
        if not self.ground_channel:
            return 0.0, 0.0
        return self.after_ground_s + self.min_ground_s, self.before_ground_s + self.min_ground_s

    def unsuspended(self) -> AlarmPolicy:
        """This policy's floors without its suspension: for the checks of what the vehicle itself
        reported (its health topics, messages and estimator flags), judged on the whole log."""
        import dataclasses

        return self if self.suspended is None else dataclasses.replace(self, suspended=None)

    def apply(self, options: dict) -> dict:
        """Alarm options with the floors applied (n_persist and min_duration_s raised to them)."""
        out = dict(options)
        out["n_persist"] = max(int(out.get("n_persist", 1)), self.n_persist)
        out["min_duration_s"] = max(float(out.get("min_duration_s", 0.0)), self.min_duration_s)
        return out


def _without_blips(t: np.ndarray, on: np.ndarray, min_ground_s: float) -> np.ndarray:
    """``on`` (held ground flags on the grid times ``t``) less its ground spans shorter than
    ``min_ground_s`` that have flight on both sides (a land detector's blip in flight)."""
    if min_ground_s <= 0 or not on.any():
        return on
    edges = np.diff(np.concatenate(([0], on.view(np.int8), [0])))
    first, stop = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)  # each span is [first, stop)
    inside = (first > 0) & (stop < t.size)  # flight before and after it
    # a span lasts from its first step to the step flight resumes
    short = inside & (t[np.minimum(stop, t.size - 1)] - t[first] < min_ground_s)
    if not short.any():
        return on
    out = on.copy()
    cover = np.zeros(t.size + 1, dtype=np.int32)
    np.add.at(cover, first[short], 1)
    np.add.at(cover, stop[short], -1)
    out[np.cumsum(cover[:-1]) > 0] = False
    return out


@dataclass
class Band:
    """Threshold series of one statistic on the grid: upper and/or lower, (N,) each (float64 while
    alarms are drawn from them, float32 once kept for figures; a constant is a broadcast view)."""

    upper: np.ndarray | None = None
    lower: np.ndarray | None = None


@dataclass(frozen=True)
class NotChecked:
    """A check a detector could not run on a log, with its real reason.

    ``partial`` (the log is "not fully checked", exit 2): the sensor is in the log but gave no valid
    sample to judge over the whole log (a battery reporting ``connected`` 0, a GNSS without a 3D
    fix), as a measurement group without valid samples is (`logscan.verdict.coverage`). Otherwise the log
    holds nothing for the check to judge (no such topic or field, never armed): listed, the verdict
    stands."""

    reason: str
    partial: bool = False


@dataclass
class DetectorResult:
    """What one detector found on one run.

    series:     named statistic series, each (N,) on the run's grid (NaN where undefined).
    thresholds: statistic name -> Band of threshold series (N,) for that statistic.
    alarms:     alarm intervals (from `logscan.alarms.alarm_intervals`).
    warnings:   things the user should know (coverage limits, skipped groups...).
    extras:     further (N,) or (N, k) series for figures (coding vector, bands...).
    info:       JSON-ready facts (coverage notes, parameters used, counts).
    checks:     statistic name -> the check it belongs to for scoring (e.g. "rejected.accel" ->
                "e_x"), declared by the detector through `add_statistic(..., check=...)`, so no other
                layer names a detector's signals.
    possible:   "possible fault" intervals: a warning level below an alarm (e.g. the UBIKF test's
                upper chi-square sum over its threshold while the lower one is not), drawn and
                listed apart; they fail a run only with `--fail-on warning` (`add_possible`).
    not_checked: the checks it could not run, each with its reason (`NotChecked`).
    """

    detector: str
    series: dict[str, np.ndarray] = field(default_factory=dict)
    thresholds: dict[str, Band] = field(default_factory=dict)
    alarms: list[AlarmInterval] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    extras: dict[str, np.ndarray] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)
    checks: dict[str, str] = field(default_factory=dict)
    possible: list[AlarmInterval] = field(default_factory=list)
    suppressed: list[tuple[AlarmInterval, str]] = field(
        default_factory=list
    )  # (alarm, reason): logscan.verdict.suppressions
    not_checked: list[NotChecked] = field(default_factory=list)
    alarm_policy: AlarmPolicy | None = field(default=None, repr=False, compare=False)
    judged_fraction: dict[str, float] = field(default_factory=dict)  # statistic -> judged / valid samples
    # statistic -> (judged, valid) samples, the fraction's counts (block mode sums the blocks')
    judged_counts: dict[str, tuple[int, int]] = field(default_factory=dict, repr=False, compare=False)
    # statistic -> (N,) bool, the samples that could raise an alarm (valid, not in warm-up); the
    # report's margins are taken over these. All True: a read-only broadcast view.
    judged: dict[str, np.ndarray] = field(default_factory=dict, repr=False, compare=False)
    # statistic -> (n, finite) of its full-rate series, where ``series`` holds its envelope (block mode)
    series_counts: dict[str, tuple[int, int]] = field(default_factory=dict, repr=False, compare=False)

    def add_statistic(
        self,
        t: np.ndarray,
        name: str,
        statistic: np.ndarray,
        upper=None,
        lower=None,
        check: str | None = None,
        **alarm_options,
    ) -> list[AlarmInterval]:
        """Store a statistic with its thresholds and append its alarms (the shared alarm logic;
        ``alarm_options`` go to `alarm_intervals`: n_persist, hold_off_s, warmup, valid...).
        ``check``: the check this statistic is scored with, when not its own name."""
        n = np.asarray(t).size
        statistic = np.asarray(statistic, dtype=np.float64)
        band = Band(upper=_band_series(upper, n), lower=_band_series(lower, n))
        self.series[name] = statistic
        self.thresholds[name] = band
        if check is not None:
            self.checks[name] = check
        suspended = None
        if self.alarm_policy is not None:
            alarm_options = self.alarm_policy.apply(alarm_options)
            suspended = self.alarm_policy.suspended
            if suspended is not None and np.shape(suspended) != (n,):  # the grid's statistics only
                suspended = None
        t = np.asarray(t, dtype=np.float64)
        judged, in_warmup = sample_masks(
            t, alarm_options.pop("valid", None), alarm_options.pop("warmup", None), alarm_options.pop("warmup_s", 0.0)
        )
        # a warm-up or window longer than most of the log leaves the statistic unable to alarm there
        # (the profile's suspension, ground time, is a choice of scope, not a gap in the check)
        alarmable = judged if in_warmup is None else ~in_warmup if judged is None else judged & ~in_warmup
        counts = self.judged_counts[name] = judged_counts(t, judged, alarmable, self._alarms_from()) if n else (0, 0)
        self.judged_fraction[name] = float(counts[0] / max(counts[1], 1)) if n else 1.0
        if suspended is not None:
            alarmable = ~suspended if alarmable is None else alarmable & ~suspended
        if alarmable is not None and not alarmable.all():
            own = alarmable is not judged  # else the caller's ``valid`` (maybe a view of the trace's): copied
            self.judged[name] = alarmable if own else alarmable.copy()
        else:
            self.judged[name] = np.broadcast_to(True, (n,))
        if suspended is not None:
            judged = ~suspended if judged is None else judged & ~suspended
        options = {"signal": name, "detector": self.detector, "from_t": self._alarms_from(), **alarm_options}
        alarms = judged_alarms(t, statistic, band.upper, band.lower, judged, in_warmup, **options)
        self.alarms.extend(alarms)
        # once the alarms are drawn from them, the statistic and its band are only drawn and read for
        # margins (7 digits): float32 halves them (a 1-hour 100 Hz log: 1.4 MB per statistic)
        self.series[name] = _drawn(statistic)
        self.thresholds[name] = Band(upper=_drawn(band.upper), lower=_drawn(band.lower))
        return alarms

    def add_possible(self, t: np.ndarray, name: str, statistic: np.ndarray, upper, **alarm_options) -> list:
        """ "Possible fault" intervals of ``statistic`` over ``upper`` (the shared alarm logic), less
        those that overlap an alarm already raised (the alarm says more); stored, not scored."""
        if self.alarm_policy is not None:
            alarm_options = self.alarm_policy.apply(alarm_options)
        alarm_options.pop("check", None)
        alarm_options["from_t"] = self._alarms_from()
        found = alarm_intervals(t, statistic, upper, None, signal=name, detector=self.detector, **alarm_options)
        kept = [p for p in found if not any(a.start <= p.end and p.start <= a.end for a in self.alarms)]
        self.possible.extend(kept)
        return kept

    def _alarms_from(self) -> float | None:
        return None if self.alarm_policy is None else self.alarm_policy.alarms_from_s

    def check_of(self, signal: str) -> str:
        """The check (score family) a statistic belongs to: declared by the detector, else the
        statistic's own name without a ``<detector>.`` prefix (``nis.accel`` -> ``accel``)."""
        if signal in self.checks:
            return self.checks[signal]
        own = f"{self.detector}."
        return signal[len(own) :] if signal.startswith(own) else signal

    def to_dict(self, summary_only: bool = True) -> dict:
        """JSON-ready view; summary_only=False adds every series as a list (NaN -> null)."""
        out: dict[str, Any] = {
            "detector": self.detector,
            "n_alarms": len(self.alarms),
            "alarms": [a.to_dict() for a in self.alarms],
            "n_possible": len(self.possible),
            "possible_faults": [a.to_dict() for a in self.possible],
            "suppressed": [{**a.to_dict(), "reason": reason} for a, reason in self.suppressed],
            "warnings": list(self.warnings),
            "not_checked": [{"reason": c.reason, "partial": c.partial} for c in self.not_checked],
            "info": jsonable(self.info),
            "series": {name: series_summary(v, self.series_counts.get(name)) for name, v in self.series.items()},
        }
        if not summary_only:
            out["series_values"] = {name: jsonable(v) for name, v in self.series.items()}
            out["thresholds"] = {
                name: {"upper": jsonable(b.upper), "lower": jsonable(b.lower)} for name, b in self.thresholds.items()
            }
            out["extras"] = {name: jsonable(v) for name, v in self.extras.items()}
        return out


@overload
def _drawn(series: np.ndarray) -> np.ndarray: ...
@overload
def _drawn(series: None) -> None: ...
def _drawn(series: np.ndarray | None) -> np.ndarray | None:
    """A statistic or band series as kept for figures: float32, a broadcast constant as it is."""
    if series is None or series.strides == (0,):
        return series
    with np.errstate(over="ignore"):  # beyond float32's range a drawn threshold is off the chart
        return series.astype(np.float32)


def _band_series(value, n: int) -> np.ndarray | None:
    """A threshold as an (N,) series; a constant one as a read-only broadcast view (no N floats)."""
    if value is None:
        return None
    value = np.asarray(value, np.float64)
    if value.ndim == 0:
        return np.broadcast_to(value, (n,))
    return np.broadcast_to(value, (n,)).copy() if value.shape != (n,) else value


@dataclass
class Incident:
    """Alarms of different checks that overlap in time, headed by their most likely source
    (`logscan.verdict.incidents`): one line for a user, the alarms behind it for the details.

    ``headline`` gives the times in seconds since the log's time zero; ``what`` (the source in
    words) and ``detail`` (the quoted check and its peak), when set, let `headline_in` give the same
    line in the log's own clock."""

    start: float
    end: float
    source: str  # a measurement group, or the signal of the alarm that heads the incident
    headline: str
    alarms: list[AlarmInterval] = field(default_factory=list)
    what: str = ""  # "accelerometer inconsistent"
    detail: str = ""  # "nis.accel, peak 10.7x"
    quoted: AlarmInterval | None = None  # the alarm of the check the headline quotes: its span is the headline's
    size: str = ""  # "+0.92 m/s² (9.2σ) on accel ax for 11.3 s" (`logscan.verdict.deviation`); "": not known

    def headline_in(self, clock=None, size: str | None = None) -> str:
        """'accelerometer inconsistent: +0.92 m/s² (9.2σ) on accel ax for 11.3 s, 30.00-41.27 s
        (nis.accel, peak 10.7x)': the source in words, the deviation's size (``size``, else the
        incident's own), the span of the check the headline quotes (the incident's when it quotes
        none) in ``clock`` (a `logscan.timebase.clock.Clock`; None: seconds since the log's time
        zero) and that check. The one wording of an incident: terminal, JSON and report."""
        if not self.what:
            return self.headline
        size = self.size if size is None else size
        a, b = (self.start, self.end) if self.quoted is None else (float(self.quoted.start), float(self.quoted.end))
        if b - a < 1e-9:  # an instant (a logged message): "at 3.24 s", not "3.24-3.24 s"
            span = f"at {a:.2f} s" if clock is None else f"at {clock.text(a)}"
        else:
            span = f"{a:.2f}-{b:.2f} s" if clock is None else clock.span_text(a, b)
        return f"{self.what}{f': {size},' if size else ''} {span} ({self.detail})"

    def to_dict(self, clock=None) -> dict:
        """JSON view; with a ``clock`` the headline is in it and start/end are also given in it."""
        out = {
            "start": self.start,
            "end": self.end,
            "source": self.source,
            "headline": self.headline_in(clock),
            "checks": sorted({f"{a.detector}:{a.signal}" for a in self.alarms}),
            "n_alarms": len(self.alarms),
        }
        return jsonable(clock.stamp(out) if clock is not None else out)


# --- ground truth ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class FaultEvent:
    """A ground-truth fault: [t_start, t_end] seconds (t_end None: until the end of the log).

    The one truth schema: `logscan simulate` writes these into a log (`to_truth`) and scoring, the
    report and evaluation read them back (`events_from_truth`). magnitude's unit depends on the
    kind; channels are the log channels (or estimator fields) the fault touched.
    """

    t_start: float
    t_end: float | None
    kind: str = ""
    target: str = ""
    magnitude: float | None = None
    channels: tuple[str, ...] = ()

    @property
    def end_or_inf(self) -> float:
        return math.inf if self.t_end is None else self.t_end

    def to_dict(self) -> dict:
        """The scoring view: interval, kind and target."""
        return {"t_start": self.t_start, "t_end": self.t_end, "kind": self.kind, "target": self.target}

    def to_truth(self) -> dict:
        """The record stored in a log's ground truth."""
        return {
            "kind": self.kind,
            "target": self.target,
            "start": self.t_start,
            "end": self.t_end,
            "magnitude": self.magnitude,
            "channels": list(self.channels),
        }


def _optional_float(value: Any) -> float | None:
    try:
        return None if value is None else float(value)
    except (TypeError, ValueError):
        return None


def events_from_truth(items: Iterable[Mapping], *, path: str | None = None) -> list[FaultEvent]:
    """Fault events from ground-truth records: dicts with t_start (or start), t_end (or end,
    may be null), kind, target and optionally magnitude and channels. Raises InputError on a
    record without a usable interval."""
    events = []
    for i, item in enumerate(items):
        start = item.get("t_start", item.get("start"))
        end = item.get("t_end", item.get("end"))
        try:
            start = float(start)
            end = None if end is None else float(end)
        except (TypeError, ValueError):
            raise InputError(
                f"ground-truth event {i} has no numeric t_start/t_end ({start!r}, {end!r})",
                path=path,
                hint="each fault event needs t_start and t_end in seconds (t_end may be null)",
            ) from None
        if not math.isfinite(start) or (end is not None and (math.isnan(end) or end < start)):
            raise InputError(
                f"ground-truth event {i} has an invalid interval [{start}, {end}]",
                path=path,
                hint="t_start must be finite and t_end >= t_start",
            )
        channels = item.get("channels") or ()
        events.append(
            FaultEvent(
                start,
                end,
                str(item.get("kind", "")),
                str(item.get("target", "")),
                magnitude=_optional_float(item.get("magnitude")),
                channels=tuple(str(c) for c in channels) if isinstance(channels, (list, tuple)) else (),
            )
        )
    return events
