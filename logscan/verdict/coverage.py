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

import numpy as np

MIN_UPDATE_FRACTION = 0.5  # of the updates a group's nominal rate implies over the log
MAX_DIVERGED_FRACTION = 0.5  # of the grid steps
MIN_JUDGED_FRACTION = 0.5  # of a statistic's valid samples that are out of warm-up
# of the flight (the whole log without a ground channel, or when it never flew) that the [alarms]
# policy may leave unjudged (ground, take-off, landing, the filter converging) before the log is "not
# fully checked": beyond it the model-based statistics judged less of the flight than they skipped
MAX_UNJUDGED_FLIGHT = 0.5


WHOLE_LOG = "the log"


def judged_span(run) -> str:
    """What a log's coverage lines speak of: ``WHOLE_LOG``, or a window's "the --start/--end window"."""
    return WHOLE_LOG if getattr(run, "window", None) is None else "the --start/--end window"


def skipped_heading(span: str) -> str:
    """What the skipped checks' lines are headed with (`skipped_checks`): "nothing to judge in this
    log", or in a window (``span`` of `judged_span`) "... in the --start/--end window": there a check
    may have nothing to judge only because the window holds no sample of its topic."""
    return f"nothing to judge in {'this log' if span == WHOLE_LOG else span}"


def unchecked_reasons(prepared, results: Sequence) -> list[str]:
    """One line per part of the log that could not be checked (empty: everything was checked)."""
    reasons = []
    source = prepared.log.source
    if source.partial:
        reasons.append(f"the log was read only in part: {source.partial_reason}")
    profile = getattr(prepared, "profile", None)
    reasons += ends_in_flight(prepared.run, getattr(profile, "alarm_policy", None))
    trace = prepared.trace
    if trace is not None:
        reasons += _starved_groups(prepared.run, trace, getattr(profile, "measurements", None))
        reasons += _divergence(trace)
    span = judged_span(prepared.run)
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


def _starved_groups(run, trace, specs=None) -> list[str]:
    duration = float(run.t[-1] - run.t[0]) + float(run.dt)
    reasons = []
    for g, name in enumerate(trace.group_names):
        group = run.groups.get(name)
        rate = group.rate_hz if group is not None and group.rate_hz else 1.0 / float(run.dt)
        # none expected while its gate was closed (a GNSS without a 3D fix): said at alignment
        open_s = max(duration - float(getattr(group, "gated_s", 0.0) or 0.0), 0.0)
        expected = min(open_s * rate, float(run.n_steps))
        used = int(trace.updated[:, g].sum())
        spec = (specs or {}).get(name)
        gated = float(getattr(group, "gated_s", 0.0) or 0.0) > 0.0
        if used == 0 and gated and spec is not None and getattr(spec, "gate_channel", None):
            # closed whenever it was known: not one valid sample, the group's sensor was never checked
            reasons.append(
                f"measurement group {name!r}: its gate was closed all flight ({spec.gate_channel} below "
                f"{spec.gate_min:g}{', no 3D fix' if 'fix_type' in spec.gate_channel else ''}): no sample used"
            )
        elif used < MIN_UPDATE_FRACTION * expected:
            reasons.append(
                f"measurement group {name!r}: the filter used {used} of the ~{expected:.0f} updates its "
                f"{rate:g} Hz rate implies (no valid samples, non-finite values or a silent sensor)"
            )
    return reasons


def stopped_groups(run, suspended) -> list[str]:
    """One line per measurement group whose sensor stopped while the log was still judged: no sample
    held (none within its staleness limit, its gate not known closed) from some step to the last
    judged one (``suspended``: the steps the [alarms] policy holds back, None: none). Unlike a gap,
    nothing after it judged that sensor again: "no alarms" cannot be said of it there. A group
    never heard at all is `_starved_groups`' line."""
    n = int(run.n_steps)
    judged = np.ones(n, dtype=bool) if suspended is None else ~np.asarray(suspended, dtype=bool)
    if n == 0 or not judged.any():
        return []
    last_judged = int(np.flatnonzero(judged)[-1])
    span = judged_span(run)
    lines = []
    for name, group in run.groups.items():
        heard = _heard_steps(group)
        if heard is None or not heard.any():
            continue
        last = int(np.flatnonzero(heard)[-1])
        unjudged_s = float(np.count_nonzero(judged[last + 1 :])) * float(run.dt)
        if last < last_judged and unjudged_s > 0.0:
            lines.append(
                f"measurement group {name!r}: no sample after {float(run.t[last]):.1f} s, {unjudged_s:.1f} s of the "
                f"judged time before the end of {span} (its sensor stopped): not judged there"
            )
    return lines


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


def _divergence(trace) -> list[str]:
    steps = sum(episode.n_steps for episode in trace.divergence_episodes)
    fraction = steps / max(trace.n_steps, 1)
    if fraction > MAX_DIVERGED_FRACTION:
        return [f"the filter was diverged for {100 * fraction:.0f} % of the log"]
    return []


def unjudged_flight(policy, run) -> tuple[str, bool] | None:
    """What a suspending [alarms] policy (`AlarmPolicy.suspend` already applied) left unjudged of the
    model-based statistics, in one line, and whether it is more than MAX_UNJUDGED_FLIGHT of the
    flight (the log is then not fully checked: the line is its reason, else a warning). None: the
    policy suspended nothing."""
    if policy is None or policy.suspended is None:
        return None
    suspended = np.asarray(policy.suspended, dtype=bool)
    airborne = policy.airborne
    flew = airborne is not None and bool(np.any(airborne))
    scope = np.asarray(airborne, dtype=bool) if flew else np.ones(suspended.size, dtype=bool)
    dt = float(run.dt)
    unjudged_s, scope_s = float(np.sum(suspended & scope)) * dt, float(np.sum(scope)) * dt
    over = unjudged_s > MAX_UNJUDGED_FLIGHT * scope_s
    why = ", ".join(
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
    total = f"{float(suspended.sum()) * dt:.1f} s of {suspended.size * dt:.1f} s"
    if flew:
        share = f"{total} ({unjudged_s:.1f} s of the {scope_s:.1f} s in flight)"
    elif airborne is not None:
        share = f"{total} ({policy.ground_channel} never says airborne: no flight to judge)"
    else:
        share = total
    line = f"not judged for {share}: {why}"
    if over:
        line = f"the model-based statistics (not the autopilot's own checks) were {line}"
    return line, over
