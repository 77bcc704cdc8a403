"""Incidents: alarm fragments of one check merged, and alarms of different checks that overlap in time
grouped into one incident headed by its most likely source.

One injected fault trips several checks (the faulty sensor's group test, the overall test, later the
sensors that disagree with the drifting estimate), and a group test near its threshold flickers on
and off. A user needs "accelerometer inconsistent 30.00-48.80 s (nis.accel, peak 11x)", then the
alarms behind it. The rules:

1. Alarms of one statistic closer than ``gap_s`` (default 1 s) merge into one alarm (its peak is the
   largest peak of the parts; `logscan.alarms.merge_close`).
2. Alarms of any checks whose spans overlap or lie within ``gap_s`` of each other form one incident.
3. The incident's source is the measurement group the filter rejected the most samples of during
   the incident (physically impossible values), if any; else the group whose alarm started first
   (ties: the larger peak/threshold), because the sensors that disagree with an estimate pulled off
   by the faulty one alarm later. An alarm whose statistic's previous sample was held back by the
   [alarms] suspension (the ground, a take-off) was under way when judging resumed: its onset is
   somewhere before, so it starts, for this rule, where judging resumed, tied with every other
   alarm under way there (`alarm_onsets`); an alarm that names no group (an overall or state check) heads
   an incident only when no group alarm is in it. The headline quotes, of the source group's alarms
   that began first (within ``gap_s`` of its first), the one with the largest peak/threshold (a later,
   larger one is the fault's aftermath: a frozen GNSS's jump when it thaws); without a group it says
   what that statistic means (the detector's `signal_words`, else its `signal_label`).
4. An incident that begins while a model input is missing (the filter predicting on its last value,
   `InputGap`), or within ``gap_s`` after, is headed by that input: its checks judge the held
   input, not their sensors (the real Husky drive without its gyro for 10 s blamed the wheels').
5. An incident whose first alarm (rule 3's onsets; ties: the larger peak/threshold) is a check of a
   model input itself (`Detector.judged_input`: a wheel speed stuck at one value) is headed by that
   input and its channel: the checks that followed judged the stuck input (the real Husky drive's
   wheel speed held while the robot stood called its GNSS, rightly still, stuck).
6. An incident headed by a sensor that measures a rate the model integrates from its input, and
   whose pair (`Model.kinematic_pairs`: the GNSS velocity and position, the velocity down and the
   barometer) both leave their prediction the same way, is headed by that input
   (`logscan.verdict.input_fault`): an accelerometer fault, not the GNSS velocity that saw it first.
   Not for an alarm under way where judging resumed: the signs follow the filter's response, which
   turns (a GNSS position jump pulls the velocity against it, then back), and its start went unseen.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from logscan.alarms import AlarmInterval, merge_close, peak_rank, true_runs
from logscan.detectors import words
from logscan.detectors.registry import default_registry
from logscan.results import DetectorResult, Incident
from logscan.verdict.deviation import GroupViews, deviation
from logscan.verdict.input_fault import KinematicEvidence, input_suspect

DEFAULT_GAP_S = 1.0

# Plain words for measurement-group names (others are shown as named by the model): the detectors'
# shared vocabulary (`logscan.detectors.words`), here for the headlines of group incidents
GROUP_WORDS = words.GROUP_WORDS


def _detector_class(detector: str):
    """The registered class of ``detector``, None when the registry has none (or it is broken)."""
    try:
        return default_registry().get(detector)
    except Exception:  # noqa: BLE001 - an unknown or broken detector keeps the default wording
        return None


def plain_words(signal: str, detector: str) -> str | None:
    """The phrase a detector gives one of its statistics (`Detector.signal_words`), else None."""
    cls = _detector_class(detector)
    return None if cls is None else cls.signal_words(signal)


def signal_label(signal: str, detector: str) -> str:
    """What a statistic means in plain words (`Detector.signal_label`), "" when its detector gives
    none: shown next to the statistic's name, never instead of it."""
    cls = _detector_class(detector)
    label = cls.signal_label(signal) if cls is not None else None
    return str(label) if label else ""


def merge_fragments(results: Sequence[DetectorResult], gap_s: float = DEFAULT_GAP_S) -> None:
    """Merge, in place, each result's alarms of one statistic that are at most ``gap_s`` apart."""
    for result in results:
        result.alarms = merge_close(result.alarms, gap_s, by_signal=True)


def group_of(signal: str, groups: Sequence[str]) -> str | None:
    """The measurement group a statistic is about: a dot-separated part of its name that is a group
    of the model (``nis.accel`` -> ``accel``, ``rejected.gyro`` -> ``gyro``), else None."""
    parts = signal.split(".")
    return next((part for part in parts if part in groups), None)


def alarm_onsets(results: Sequence[DetectorResult], t: np.ndarray, suspended: np.ndarray | None) -> Onsets:
    """(detector, signal, start) -> where judging resumed, for each alarm that was under way then
    (rule 3): its statistic's last finite sample before its first exceedance was held back by the
    suspension (not judged, on a suspended step). Empty without a suspension."""
    onsets: Onsets = {}
    if suspended is None or not suspended.any():
        return onsets
    resumed = np.flatnonzero(suspended[:-1] & ~suspended[1:]) + 1  # the first judged step after each
    for result in results:
        for signal in {a.signal for a in result.alarms}:
            series, judged = result.series.get(signal), result.judged.get(signal)
            if series is None or judged is None or np.shape(series) != t.shape:
                continue
            finite = np.flatnonzero(np.isfinite(series))
            for alarm in (a for a in result.alarms if a.signal == signal):
                at = int(np.searchsorted(t, alarm.first_exceed - 1e-9))
                before = int(np.searchsorted(finite, at)) - 1
                if before < 0 or judged[finite[before]] or not suspended[finite[before]]:
                    continue
                after = int(np.searchsorted(resumed, finite[before]))  # the resumption that follows it
                if after < resumed.size and resumed[after] <= at:
                    onsets[(alarm.detector, alarm.signal, alarm.start)] = float(t[resumed[after]])
    return onsets


Onsets = dict[tuple[str, str, float], float]


def _onset_by_id(alarms: list[AlarmInterval], onsets: Onsets) -> dict[int, float]:
    """Each alarm's onset for rule 3 (`alarm_onsets`: where judging resumed, else its start), by id."""
    return {id(a): onsets.get((a.detector, a.signal, a.start), a.start) for a in alarms}


def _source(alarms: list[AlarmInterval], groups: Sequence[str], rejected: dict[str, int], onsets: Onsets, gap_s: float):
    """(group or None, the alarm the headline quotes) of one incident (rule 3)."""
    named = [(a, group_of(a.signal, groups)) for a in alarms]
    onset = _onset_by_id(alarms, onsets)
    if rejected:
        group = max(rejected, key=lambda g: (rejected[g], -groups.index(g)))
    else:
        grouped = [(a, g) for a, g in named if g is not None]
        first = min(grouped or named, key=lambda item: (onset[id(item[0])], -peak_rank(item[0])))
        group = first[1]
    quoted = [a for a, g in named if g == group] or alarms
    # its checks that alarmed first (within gap_s of the first): a later, larger alarm of the same
    # group is the fault's aftermath (a frozen GNSS's jump back when it thaws), not what it was
    earliest = min(onset[id(a)] for a in quoted)
    return group, max((a for a in quoted if onset[id(a)] <= earliest + gap_s + 1e-9), key=peak_rank)


def headline_parts(source: AlarmInterval, group: str | None, n_rejected: int = 0) -> tuple[str, str]:
    """('accelerometer inconsistent', 'nis.accel, peak 10.7x'): an incident's source in words and
    the check its headline quotes."""
    rejected = f"; {n_rejected} impossible sample{'s' if n_rejected != 1 else ''} rejected" if n_rejected else ""
    phrase = (
        None if group else (plain_words(source.signal, source.detector) or signal_label(source.signal, source.detector))
    )
    if not phrase:
        what = words.group_words(group) if group else f"{source.detector} {source.signal}"
        phrase = f"{what} {getattr(_detector_class(source.detector), 'group_verdict', 'inconsistent')}"
    return phrase, f"{quoted_peak(source)}{rejected}"


def quoted_peak(source: AlarmInterval) -> str:
    """'nis.accel, peak 10.7x': the check an incident's headline quotes and how high it peaked."""
    ratio = source.peak_ratio
    peak = "non-finite" if source.bound == "nonfinite" else ("-" if ratio is None else f"{ratio:.3g}x")
    return f"{source.signal}, peak {peak}"


def headline(source: AlarmInterval, group: str | None, start: float, end: float, n_rejected: int = 0) -> str:
    """'accelerometer inconsistent 30.00-60.00 s (nis.accel, peak 10.7x)'."""
    phrase, detail = headline_parts(source, group, n_rejected)
    return f"{phrase} {start:.2f}-{end:.2f} s ({detail})"


def _rejected_counts(trace, start: float, end: float) -> dict[str, int]:
    """Samples the filter rejected per group within [start, end] (groups with none left out)."""
    if trace is None:
        return {}
    inside = (trace.t >= start - 1e-9) & (trace.t <= end + 1e-9)
    counts = trace.rejected[inside].sum(axis=0)
    return {name: int(n) for name, n in zip(trace.group_names, counts) if n > 0}


@dataclass(frozen=True)
class InputGap:
    """A stretch where the filter held its inputs' last value: a model input was missing."""

    start: float  # s since the log's time zero: the first step held
    end: float  # the last step held
    channels: tuple[str, ...]  # the inputs missing there

    def words(self) -> str:
        names = ", ".join(self.channels) or "a model input"
        return f"model input {names} missing for {self.end - self.start:.1f} s (the filter held its last value), then"


def input_gaps(trace, run) -> list[InputGap]:
    """The stretches of steps where the filter held its inputs (`EkfTrace.input_held`), each with
    the input channels not finite there (none named when the run's inputs were already freed)."""
    held = getattr(trace, "input_held", None)
    if held is None or not held.any():
        return []
    u = getattr(run, "u", None)
    gaps = []
    for first, stop in zip(*true_runs(held)):
        if first == 0:  # no step before to hold a value from: the filter does not predict at step 0
            continue
        missing = () if u is None or u.shape[0] != held.size else ~np.isfinite(u[first:stop]).all(axis=0)
        names = tuple(name for name, gone in zip(run.input_channels, missing) if gone)
        gaps.append(InputGap(float(trace.t[first]), float(trace.t[stop - 1]), names))
    return gaps


def _held_input_gap(members: list[AlarmInterval], gaps: Sequence[InputGap], gap_s: float) -> InputGap | None:
    """The input gap that heads an incident (rule 4): one in which (or within ``gap_s`` after) its
    first alarm of the model's statistics begins, with no check of the vehicle's own reports
    (`Detector.raw_topics`, which the held input does not touch) alarming before it ends."""
    if not gaps:
        return None
    own = [a for a in members if getattr(_detector_class(a.detector), "raw_topics", ())]
    model = [a for a in members if not any(a is b for b in own)]
    if not model:
        return None
    first = min(a.start for a in model)
    gap = next((g for g in gaps if g.start - 1e-9 <= first <= g.end + gap_s + 1e-9), None)
    if gap is None or any(a.start < gap.end + gap_s for a in own):
        return None
    return gap


def _judged_input(alarm: AlarmInterval) -> str | None:
    """The model input an alarm's check judges (`Detector.judged_input`), None for any other."""
    judged = getattr(_detector_class(alarm.detector), "judged_input", None)
    return judged(alarm.signal) if judged is not None else None


def _stuck_input(members: list[AlarmInterval], onsets: Onsets) -> tuple[AlarmInterval, str] | None:
    """(its alarm, its name): the model input whose own check alarmed first in an incident (rule 5);
    None when none did, or another check's alarm began before it."""
    onset = _onset_by_id(members, onsets)
    first = min(members, key=lambda a: (onset[id(a)], -peak_rank(a)))
    name = _judged_input(first)
    return None if name is None else (first, name)


def input_words(alarm: AlarmInterval, name: str, channel: str) -> str:
    """'model input v (/odom/twist.twist.linear.x) stuck (its samples repeat one value)' (rule 5)."""
    verdict = getattr(_detector_class(alarm.detector), "group_verdict", "inconsistent")
    return f"model input {name} ({channel}) {verdict}" if channel != name else f"model input {name} {verdict}"


def inputs_of(prepared) -> dict[str, str]:
    """A prepared log's model inputs by name -> the channel each is read from (rule 5's words)."""
    names = getattr(getattr(prepared, "model", None), "input_names", ())
    return dict(zip(names, getattr(prepared.run, "input_channels", ())))


def find_incidents(
    results: Sequence[DetectorResult],
    trace,
    groups: Sequence[str],
    gap_s: float = DEFAULT_GAP_S,
    sizes: Sizes | None = None,
    onsets: Onsets | None = None,
    gaps: Sequence[InputGap] = (),
    inputs: Mapping[str, str] | None = None,
    kinematic: KinematicEvidence | None = None,
) -> list[Incident]:
    """Incidents in time order from every result's alarms (merge fragments first). ``trace``: the
    shared EKF trace (its rejected samples point at the source), or None. ``sizes``: the filter's
    innovations to give each headline the deviation's size with (`Sizes`); None: no size.
    ``onsets``: the alarms under way where judging resumed (`alarm_onsets`). ``gaps``: where a model
    input was missing (`input_gaps`, rule 4). ``inputs``: the model's inputs by name -> channel
    (`inputs_of`), to name a stuck one's channel (rule 5). ``kinematic``: the innovations of the
    sensors that measure the motion twice over (`kinematic_evidence`, rule 6)."""
    alarms = sorted((a for r in results for a in r.alarms), key=lambda a: (a.start, a.end))
    starts = np.array([a.start for a in alarms])
    ends = np.maximum.accumulate(np.array([a.end for a in alarms])) if alarms else np.zeros(0)
    # a new incident starts where an alarm begins more than gap_s after every earlier one ended
    breaks = np.flatnonzero(starts[1:] - ends[:-1] > gap_s + 1e-9) + 1 if alarms else np.zeros(0, int)
    incidents = []
    for chunk in np.split(np.array(alarms, dtype=object), breaks) if alarms else []:
        members: list[AlarmInterval] = list(chunk)
        start, stop = members[0].start, max(a.end for a in members)
        rejected = _rejected_counts(trace, start, stop)
        group, quoted = _source(members, list(groups), rejected, onsets or {}, gap_s)
        what, detail = headline_parts(quoted, group, rejected.get(group, 0))
        size = sizes.text(group, quoted) if sizes is not None and group is not None else ""
        source = group or quoted.signal
        # rule 6: the sensors agree against the input (judged from the alarm's start: not for one
        # under way where judging resumed, whose start, and the fault's, went unseen)
        seen = (quoted.detector, quoted.signal, quoted.start) not in (onsets or {})
        suspect = input_suspect(kinematic, group, quoted) if seen else None
        if suspect is not None and kinematic is not None:
            what, size, source = f"{kinematic.what} suspect: {suspect}", "", kinematic.channels
        stuck = _stuck_input(members, onsets or {})
        if stuck is not None:  # rule 5: the checks judged a stuck input
            quoted, name = stuck
            source = (inputs or {}).get(name, name)
            what, detail, size = input_words(quoted, name, source), headline_parts(quoted, None)[1], ""
        gap = _held_input_gap(members, gaps, gap_s)
        if gap is not None:  # rule 4: the checks judged a held input
            what, size, source = gap.words(), "", ", ".join(gap.channels) or "inputs"
        incident = Incident(start, stop, source, "", members, what, detail, quoted, size)
        incident.headline = incident.headline_in()
        incidents.append(incident)
    return incidents


@dataclass
class Sizes:
    """What an incident's headline needs for the deviation's size (`logscan.verdict.deviation`): every
    group's view of the filter's innovations, the analysis grid and the model's `describe()`."""

    views: GroupViews
    t: np.ndarray
    model: Mapping
    _cache: dict = field(default_factory=dict)

    def text(self, group: str, alarm: AlarmInterval) -> str:
        """'+0.92 m/s² (9.2σ) on accel ax for 11.3 s' during ``alarm`` on ``group``; "" when the
        group was not updated in it (or has no view)."""
        if group not in self._cache:
            self._cache[group] = self.views.view(group)
        view = self._cache[group]
        found = None if view is None else deviation(view, self.views.times(group, self.t), alarm, self.model)
        return "" if found is None else found.text()


def sizes_of(prepared) -> Sizes | None:
    """`Sizes` from a prepared log (`logscan.pipeline.stages.Prepared`) whose filter's innovations
    were kept (for a report); None when they were not."""
    views = getattr(prepared, "innovations", None)
    if views is None:
        return None
    model = getattr(prepared, "model", None)
    return Sizes(views, prepared.run.t, model.describe() if model is not None else {})
