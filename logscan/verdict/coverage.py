"""What could not be checked in one analysed log: the reasons a "no alarms" verdict would be a lie.

A verdict is a promise: "no alarms" only when the whole log was read and every part the profile
names was checked. Each rule below yields one line saying what was not checked:

- the log was read only in part (truncated, failed CRC, broken framing: the reader says how much);
- the log ends in flight (its [alarms] ``ground_channel`` says airborne at the last step): the
  flight's end was not logged, as a truncated log's end is missing;
- a measurement group the filter used fewer than ``MIN_UPDATE_FRACTION`` of the updates its rate
  implies over the log (no valid sample at all, non-finite values, or silent after a while); a
  group whose ``gate`` was closed all the log (a GNSS without a 3D fix all flight) had no valid
  sample at all: not checked either (while the gate is closed for part of the log, no sample is
  expected there);
- the filter was diverged for more than ``MAX_DIVERGED_FRACTION`` of the grid;
- a detector statistic that is never finite over the log, or judged on fewer than
  ``MIN_JUDGED_FRACTION`` of its valid samples (a warm-up or window covering most of the log): the
  detector could not alarm there;
- a check a detector could not run because its sensor, present in the log, gave no valid sample
  over the whole log (`logscan.results.NotChecked` with ``partial``: a battery whose ``connected``
  is 0 all flight, a GNSS without a 3D fix all flight). This is the rule of a measurement group
  without valid samples, applied to the checks that read the autopilot's topics: the sensor is in
  the log and nothing of it was judged.

The other checks a detector could not run, because the log holds nothing for them (no such topic
or field, a vehicle never armed), are `skipped_checks`: listed with their reason in the summary,
the JSON and the report, so that "every check ran" is said only when it is true, but the verdict
and the exit code stand (a profile is built from what the log holds; what it does not hold is not
a part of the log left unjudged).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

MIN_UPDATE_FRACTION = 0.5  # of the updates a group's nominal rate implies over the log
MAX_DIVERGED_FRACTION = 0.5  # of the grid steps
MIN_JUDGED_FRACTION = 0.5  # of a statistic's valid samples that are out of warm-up
# of the flight (the whole log without a ground channel, or when it never flew) that the [alarms]
# policy may leave unjudged (ground, take-off, landing, the filter converging) before the log is "not
# fully checked": beyond it the model-based statistics judged less of the flight than they skipped
MAX_UNJUDGED_FLIGHT = 0.5


WHOLE_LOG = "the log"
BORDER_EPS_S = 1e-9  # a block's first step is at its border up to this (`own_steps`)


def judged_span(run) -> str:
    """What a log's coverage lines speak of: ``WHOLE_LOG``, or a window's "the --start/--end window"."""
    return WHOLE_LOG if getattr(run, "window", None) is None else "the --start/--end window"


def skipped_heading(span: str) -> str:
    """What the skipped checks' lines are headed with (`skipped_checks`): "nothing to judge in this
    log", or in a window (``span`` of `judged_span`) "... in the --start/--end window": there a check
    may have nothing to judge only because the window holds no sample of its topic."""
    return f"nothing to judge in {'this log' if span == WHOLE_LOG else span}"


def unchecked_reasons(prepared, results: Sequence) -> list[str]:
    """One line per part of the log that could not be checked (empty: everything was checked), of
    the filter's coverage alone (`Coverage.lines` with no stopped sensor or suspension)."""
    facts = filter_coverage(
        prepared.run, prepared.trace, getattr(getattr(prepared, "profile", None), "measurements", None)
    )
    coverage = Coverage(facts, None, {}, 0.0, frozenset(), tuple(log_end_lines(prepared)))
    return read_in_part(prepared) + coverage.lines(results, judged_span(prepared.run))[0]


def read_in_part(prepared) -> list[str]:
    """The line of a log the reader read only in part (truncated, failed CRC, broken framing)."""
    source = prepared.log.source
    return [f"the log was read only in part: {source.partial_reason}"] if source.partial else []


@dataclass(frozen=True)
class GroupUse:
    """A measurement group's updates the filter used in a run, against those its rate implies while
    its gate was open; ``gate``: the words of its gate where it was closed at some step (a GNSS
    without a 3D fix), "" where never or without a gate channel."""

    used: int
    expected: float
    rate_hz: float
    gate: str

    def __add__(self, other: GroupUse) -> GroupUse:
        return GroupUse(self.used + other.used, self.expected + other.expected, self.rate_hz, self.gate or other.gate)


@dataclass(frozen=True)
class FilterCoverage:
    """What the filter's run says of the coverage: each group's use, the steps it was diverged.
    Two runs' add (block mode judges the log's sum by the rules of a log at once)."""

    uses: dict[str, GroupUse]
    diverged_steps: int
    steps: int

    def __add__(self, other: FilterCoverage) -> FilterCoverage:
        uses = dict(self.uses)
        for name, use in other.uses.items():
            uses[name] = uses[name] + use if name in uses else use
        return FilterCoverage(uses, self.diverged_steps + other.diverged_steps, self.steps + other.steps)

    def lines(self) -> list[str]:
        """A group with no valid sample while its gate was closed, or fewer than
        MIN_UPDATE_FRACTION of the updates its rate implies; a filter diverged most of the log."""
        reasons = []
        for name, use in self.uses.items():
            if use.used == 0 and use.gate:
                # closed whenever it was known: not one valid sample, the group's sensor was never checked
                line = f"measurement group {name!r}: its gate was closed all flight ({use.gate}): no sample used"
                reasons.append(line)
            elif use.used < MIN_UPDATE_FRACTION * use.expected:
                reasons.append(
                    f"measurement group {name!r}: the filter used {use.used} of the ~{use.expected:.0f} updates its "
                    f"{use.rate_hz:g} Hz rate implies (no valid samples, non-finite values or a silent sensor)"
                )
        fraction = self.diverged_steps / max(self.steps, 1)
        if fraction > MAX_DIVERGED_FRACTION:
            reasons.append(f"the filter was diverged for {100 * fraction:.0f} % of the log")
        return reasons


def filter_coverage(run, trace, specs=None, from_s: float | None = None) -> FilterCoverage:
    """`FilterCoverage` of the filter's ``trace`` on ``run`` (None: no filter ran, nothing to say);
    ``from_s``: of the steps from then on only (a block's own, not its lead-in, which the block
    before counts)."""
    if trace is None:
        return FilterCoverage({}, 0, 0)
    dt = float(run.dt)
    own = slice(None) if from_s is None else slice(own_steps(np.asarray(run.t), from_s), None)
    steps = int(run.n_steps) if from_s is None else int(run.n_steps) - own.start
    duration = float(run.t[-1] - run.t[0]) + dt if from_s is None else steps * dt
    uses = {}
    for g, name in enumerate(trace.group_names):
        group = run.groups.get(name)
        rate = group.rate_hz if group is not None and group.rate_hz else 1.0 / dt
        # none expected while its gate was closed (a GNSS without a 3D fix): said at alignment
        gated_s = float(getattr(group, "gated_s", 0.0) or 0.0)
        closed = getattr(group, "gate_closed", None)
        if from_s is not None and closed is not None:
            gated_s = float(np.count_nonzero(closed[own])) * dt
        open_s = max(duration - gated_s, 0.0)
        spec = (specs or {}).get(name)
        gate = ""
        if gated_s > 0.0 and spec is not None and getattr(spec, "gate_channel", None):
            fix = ", no 3D fix" if "fix_type" in spec.gate_channel else ""
            gate = f"{spec.gate_channel} below {spec.gate_min:g}{fix}"
        uses[name] = GroupUse(int(trace.updated[own, g].sum()), min(open_s * rate, float(steps)), rate, gate)
    if from_s is None:
        return FilterCoverage(uses, sum(e.n_steps for e in trace.divergence_episodes), int(trace.n_steps))
    return FilterCoverage(uses, int(np.count_nonzero(trace.diverged[own])), steps)


def series_reasons(results: Sequence, span: str) -> list[str]:
    """The lines of `unchecked_reasons` the detectors' results give: a check without a valid sample
    (`NotChecked.partial`), a statistic never finite or judged on too few of its samples over
    ``span`` (`judged_span`). Block mode gives them of the merged results, not each block's."""
    reasons = []
    for result in results:
        reasons += [f"{result.detector}: {c.reason}" for c in result.not_checked if c.partial]
        for name, series in result.series.items():
            if series.size and not np.isfinite(series).any():
                reasons.append(f"{result.detector}: {name} was never computed (no finite value over {span})")
            elif result.judged_fraction.get(name, 1.0) < MIN_JUDGED_FRACTION:
                share = 100.0 * result.judged_fraction[name]
                reasons.append(
                    f"{result.detector}: {name} was judged on only {share:.0f} % of its samples (its warm-up "
                    f"{'or window ' if span == WHOLE_LOG else ''}covers most of {span})"
                )
    return reasons


def log_end_lines(prepared) -> list[str]:
    """`ends_in_flight` of an analysed run, with its profile's [alarms] policy."""
    return ends_in_flight(prepared.run, getattr(getattr(prepared, "profile", None), "alarm_policy", None))


def ends_in_flight(run, policy) -> list[str]:
    """One line when the log ends with the vehicle in flight: its ``ground_channel`` (PX4's
    ``landed``) says airborne at the grid's last step, with no landing after. The flight's end (the
    landing, or what stopped it) is missing from the log, as a truncated log's end is; a --end
    window ends where the user chose, not the log."""
    channel = getattr(policy, "ground_channel", None)
    ground = getattr(run, "ground", None)
    window = getattr(run, "window", None)
    if not channel or ground is None or not run.n_steps or (window is not None and window[1] is not None):
        return []
    ground = np.asarray(ground, dtype=np.float64)
    if not ground[-1] == 0.0:  # on the ground, or not known (NaN)
        return []
    on = np.flatnonzero(np.isfinite(ground) & (ground != 0.0))
    since = float(run.t[on[-1] + 1]) if on.size else float(run.t[0])
    return [
        f"the log ends in flight: {channel} says airborne from {since:.1f} s to the last step "
        f"({float(run.t[-1]):.1f} s after the log start), with no landing: the end of the flight was not "
        "logged (a crash, a power loss or the logger stopped)"
    ]


def skipped_checks(results: Sequence) -> list[str]:
    """One line per check a detector could not run because the log (or the window) holds nothing
    for it to judge (no such topic or field, never armed, no sample in the window): listed under
    `skipped_heading`, not a reason of "not fully checked"."""
    return [f"{result.detector}: {c.reason}" for result in results for c in result.not_checked if not c.partial]


@dataclass(frozen=True)
class Stop:
    """A measurement group's sensor stopped: its last sample's time, the judged time after it."""

    t: float
    unjudged_s: float


def stopped_groups(run, suspended, from_s: float | None = None) -> dict[str, Stop]:
    """Each measurement group whose sensor stopped while the log was still judged: no sample held
    (none within its staleness limit, its gate not known closed) from some step to the last judged
    one (``suspended``: the steps the [alarms] policy holds back, None: none). Unlike a gap, nothing
    after it judged that sensor again: "no alarms" cannot be said of it there (`stopped_lines`). A
    group never heard at all is `FilterCoverage.lines`'. ``from_s``: the judged time counted from
    then on (a block's own steps: its lead-in is the block before's)."""
    n = int(run.n_steps)
    judged = np.ones(n, dtype=bool) if suspended is None else ~np.asarray(suspended, dtype=bool)
    if from_s is not None:
        judged[: own_steps(np.asarray(run.t), from_s)] = False
    if n == 0 or not judged.any():
        return {}
    last_judged = int(np.flatnonzero(judged)[-1])
    stops = {}
    for name, group in run.groups.items():
        heard = _heard_steps(group)
        if heard is None or not heard.any():
            continue
        last = int(np.flatnonzero(heard)[-1])
        unjudged_s = float(np.count_nonzero(judged[last + 1 :])) * float(run.dt)
        if last < last_judged and unjudged_s > 0.0:
            stops[name] = Stop(float(run.t[last]), unjudged_s)
    return stops


def heard_groups(run, from_s: float | None = None) -> frozenset[str]:
    """The measurement groups with a sample held (or their gate known closed) at any step from
    ``from_s`` on (a block's own steps; None: any step), or whose samples are no longer held (not
    known: heard). Block mode: a sensor stopped in a block and heard in a later one did not stop."""
    first = 0 if from_s is None else own_steps(np.asarray(run.t), from_s)
    heard = {name: _heard_steps(group) for name, group in run.groups.items()}
    return frozenset(name for name, steps in heard.items() if steps is None or steps[first:].any())


def stopped_lines(stops: dict[str, Stop], span: str) -> list[str]:
    """One line per group of `stopped_groups` (``span``: `judged_span`)."""
    return [
        f"measurement group {name!r}: no sample after {stop.t:.1f} s, {stop.unjudged_s:.1f} s of the "
        f"judged time before the end of {span} (its sensor stopped): not judged there"
        for name, stop in stops.items()
    ]


def unheard_stops(lines: list[str], stops: dict[str, Stop], span: str) -> list[str]:
    """`stopped_lines` of the groups no line of ``lines`` names (a group starved or never heard is
    said once, by its own line)."""
    named = {line.split(":")[0] for line in lines}
    return [line for line in stopped_lines(stops, span) if line.split(":")[0] not in named]


@dataclass(frozen=True)
class Coverage:
    """A run's coverage in figures, not lines: block mode adds the blocks' and judges the log's by
    the rules of a log at once (`logscan.pipeline.block_fold`)."""

    filter: FilterCoverage
    share: JudgedShare | None  # what the [alarms] suspension left unjudged (None: nothing suspended)
    stopped: dict[str, Stop]
    judged_s: float  # the judged time of the run's own steps (a block's: from its first, not its lead-in)
    heard: frozenset[str]  # the groups heard in its own steps (`heard_groups`)
    log_end: tuple[str, ...]  # the lines of how the log ends (`ends_in_flight`): a block's, the last one's
    # the lines these figures and the detectors' results gave the run (block mode: a block's, which
    # the log's sum says instead); empty for a sum
    said: frozenset[str] = frozenset()

    def lines(self, results: Sequence, span: str) -> tuple[list[str], str]:
        """The lines of what could not be checked that these figures and the detectors' ``results``
        give (``span``: `judged_span`): how the log ends, the filter's, the statistics', the sensors
        stopped, the unjudged share when over the limit; and that share's line when it is only a
        warning ("": none). A log at once and block mode's sum say them alike."""
        lines = list(self.log_end) + self.filter.lines() + series_reasons(results, span)
        lines += unheard_stops(lines, self.stopped, span)
        if self.share is None:
            return lines, ""
        return ([*lines, self.share.line()], "") if self.share.over else (lines, self.share.line())


def judged_seconds(policy, run) -> float:
    """The judged time of a run's own steps (from the policy's ``alarms_from_s``), not suspended."""
    t = np.asarray(run.t)
    judged = np.zeros(t.size, dtype=bool)
    judged[0 if policy is None or policy.alarms_from_s is None else own_steps(t, policy.alarms_from_s) :] = True
    if policy is not None and policy.suspended is not None:
        judged &= ~np.asarray(policy.suspended, dtype=bool)
    return float(np.count_nonzero(judged)) * float(run.dt)


def own_steps(t: np.ndarray, from_s: float) -> int:
    """The first of a block's own steps (at ``from_s``, its first: a border on the grid, up to
    rounding), after its lead-in."""
    return int(np.searchsorted(t, from_s - BORDER_EPS_S, side="left"))


def _heard_steps(group) -> np.ndarray | None:
    """(N,) bool: steps where ``group`` holds a sample (within its staleness limit) or its gate is
    known closed (none expected); None when its samples are no longer held."""
    z = getattr(group, "z", None)
    if z is None:
        return None
    rows = getattr(z, "row", None)
    heard = rows >= 0 if rows is not None else ~np.isnan(np.asarray(z)).all(axis=1)
    closed = getattr(group, "gate_closed", None)
    return heard if closed is None else heard | closed


def unjudged_flight(policy, run) -> tuple[str, bool] | None:
    """What a suspending [alarms] policy (`AlarmPolicy.suspend` already applied) left unjudged of the
    model-based statistics, in one line, and whether it is more than MAX_UNJUDGED_FLIGHT of the
    flight (the log is then not fully checked: the line is its reason, else a warning). None: the
    policy suspended nothing."""
    share = judged_share(policy, run)
    return None if share is None else (share.line(), share.over)


@dataclass(frozen=True)
class JudgedShare:
    """What a suspending [alarms] policy left unjudged of a run, in seconds: of all its steps and of
    those in flight. Two runs' shares add (block mode: the blocks' shares make the log's, judged by
    the same rule as the log at once, `logscan.pipeline.block_fold`)."""

    suspended_s: float  # steps not judged
    total_s: float
    unjudged_air_s: float  # steps not judged while in flight
    air_s: float  # steps in flight (0: it never flew, or no ground channel says)
    ground_channel: str | None  # None: the policy has no ground channel (the whole run is the scope)
    reasons: tuple[str, ...]  # why: the filter converging, the ground time

    def __add__(self, other: JudgedShare) -> JudgedShare:
        return JudgedShare(
            self.suspended_s + other.suspended_s,
            self.total_s + other.total_s,
            self.unjudged_air_s + other.unjudged_air_s,
            self.air_s + other.air_s,
            self.ground_channel or other.ground_channel,
            tuple(dict.fromkeys(self.reasons + other.reasons)),
        )

    @property
    def flew(self) -> bool:
        return self.air_s > 0.0

    @property
    def over(self) -> bool:
        """More than MAX_UNJUDGED_FLIGHT of the flight (of everything, when it never flew) unjudged."""
        unjudged_s, scope_s = (self.unjudged_air_s, self.air_s) if self.flew else (self.suspended_s, self.total_s)
        return unjudged_s > MAX_UNJUDGED_FLIGHT * scope_s

    def line(self) -> str:
        total = f"{self.suspended_s:.1f} s of {self.total_s:.1f} s"
        if self.flew:
            share = f"{total} ({self.unjudged_air_s:.1f} s of the {self.air_s:.1f} s in flight)"
        elif self.ground_channel:
            share = f"{total} ({self.ground_channel} never says airborne: no flight to judge)"
        else:
            share = total
        line = f"not judged for {share}: {', '.join(self.reasons)}"
        if self.over:
            line = f"the model-based statistics (not the autopilot's own checks) were {line}"
        return line


def judged_share(policy, run) -> JudgedShare | None:
    """`JudgedShare` of a run whose [alarms] policy is applied (`AlarmPolicy.suspend`), counted from
    its ``alarms_from_s`` on (a block's first step: not its lead-in, which the block before judged).
    None: the policy suspended nothing (of a block: suspends nothing at all; a block it held back
    nowhere, all in flight, counts for the log's share)."""
    if policy is None or (policy.suspended is None and (policy.alarms_from_s is None or not policy.suspends)):
        return None
    if policy.suspended is None:
        suspended = np.zeros(np.size(run.t), dtype=bool)
    else:
        suspended = np.asarray(policy.suspended, dtype=bool)
    airborne = None if policy.airborne is None else np.asarray(policy.airborne, dtype=bool)
    if policy.alarms_from_s is not None:  # a block's own steps
        own = own_steps(np.asarray(run.t), policy.alarms_from_s)
        suspended, airborne = suspended[own:], None if airborne is None else airborne[own:]
    dt = float(run.dt)
    reasons = tuple(
        part
        for part, on in (
            (f"the first {policy.ignore_start_s:g} s (the filter converging)", policy.start_held),
            (
                f"on the ground ({policy.ground_channel}), {policy.after_ground_s:g} s after take-off"
                + (f" and {policy.before_ground_s:g} s before landing" if policy.before_ground_s else ""),
                bool(policy.ground_channel),
            ),
        )
        if on
    )
    flew = airborne is not None and bool(np.any(airborne))
    in_flight = airborne if flew and airborne is not None else np.zeros(suspended.size, dtype=bool)
    return JudgedShare(
        suspended_s=float(suspended.sum()) * dt,
        total_s=suspended.size * dt,
        unjudged_air_s=float(np.sum(suspended & in_flight)) * dt if flew else 0.0,
        air_s=float(np.sum(in_flight)) * dt if flew else 0.0,
        ground_channel=policy.ground_channel if airborne is not None else None,
        reasons=reasons,
    )
