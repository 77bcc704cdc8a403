"""Every text view of the CLI: the analyze summary, the evaluation tables, inspect and detectors.

Commands compute, this module renders; nothing here reads files or decides exit codes. Every
view goes through `printable`: names, messages and file names come from logs and profiles, and a
control character in them (an ESC sequence clearing the screen, a bidirectional override) must
reach the terminal as an escape, never as itself.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import TYPE_CHECKING

from logscan.docs import doc_url

if TYPE_CHECKING:
    from logscan.verdict.evaluation import Evaluation

# Warnings a log's screen shows; the rest are counted in one line (all are in the report and --json).
MAX_WARNINGS = 5
# C0 controls, DEL, C1 controls (CSI, OSC...), line/paragraph separators, bidirectional controls
_CONTROL_RE = re.compile("[\x00-\x1f\x7f-\x9f\u061c\u200e\u200f\u2028\u2029\u202a-\u202e\u2066-\u2069]")


def _analysed_span(analysis) -> str:
    """ "60.0 s" for a whole log; "25.0-45.0 s of 60.0 s" for a window (--start/--end), or a log
    whose grid misses more than its two end steps of it (outlying timestamps dropped)."""
    run = analysis.run
    start, end, whole = float(run.t[0]), float(run.t[-1]), analysis.log.duration_s
    # Without a window the grid runs from the profile's first sample to its last in steps of dt: it
    # may start a step after the log's time zero (a 10 Hz grid 3 ms after an unused IMU's first
    # sample) and end a step before its last, leaving nothing out. Only a shortfall beyond those
    # two steps (outlying timestamps dropped, inputs that start late) is a span worth showing.
    shortfall = max(start, 0.0) + max(whole - end, 0.0)
    if getattr(run, "window", None) is None and shortfall <= 2.0 * max(1e-6, float(run.dt)):
        return f"{end - start:.1f} s"
    start = max(start, 0.0) if start > -0.05 else start  # a grid step before time zero reads "0.0", not "-0.0"
    lead = analysis.prepared.lead_in  # a window's filter led in from the log before it (not judged there)
    led = f", filtered from {max(lead.start_s, 0.0):.1f} s" if lead is not None else ""
    return f"{start:.1f}-{end:.1f} s of {whole:.1f} s{led}"


def printable(text: object) -> str:
    """``text`` safe for a terminal: each control character as a ``\\x1b`` / ``\\u202e`` escape
    (newlines and tabs too: call it on one line or one name). Backslashes stay as they are, so an
    escaped text passes through unchanged."""
    return _CONTROL_RE.sub(_escape_char, str(text))


def _escape_char(match: re.Match) -> str:
    code = ord(match.group())
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"


def _lines(lines: list[str]) -> str:
    """The view's lines, each made printable, as one text."""
    return "\n".join(printable(line) for line in lines)


# --- analyze --------------------------------------------------------------------------------------


def _recovery_lines(recovery, clock) -> list[str]:
    """One line per recovered anomaly: checkpoint, roll-forward, hand-back, T_max and verdict."""
    lines = [f"  recovery ({recovery.settings.method}): {len(recovery.anomalies)} anomaly(ies)"]
    for k, a in enumerate(recovery.anomalies, 1):
        sensors = "every sensor (generic)" if a.targets is None else "; ".join(
            f"{loop} {', '.join(groups)}" for loop, groups in a.targets.items()
        )  # fmt: skip
        if a.t_checkpoint is None:
            lines.append(f"    {k}: detected {clock.text(a.t_detect)} ({sensors}): not recovered: {a.note}")
            continue
        t_max = ", ".join(f"{state} {v:.2f} s" for state, v in a.t_max.items() if v is not None)
        lines.append(
            f"    {k}: detected {clock.text(a.t_detect)} ({sensors}): from the checkpoint at "
            f"{clock.text(a.t_checkpoint)}, rolled forward {a.rollforward_s:.2f} s to {clock.text(a.t_recovered_end)}"
            + (f"; T_max {t_max}" if t_max else "")
            + (f": {a.verdict}" if a.verdict else "")
            + (f"; ended: {a.end_reason}" if a.end_reason else "")
        )
    return lines


def render_summary(analysis, report_path: str | None, max_rows: int = 12) -> str:
    """One screen per log: verdict, what could not be checked, the incidents in time order with the
    alarms behind each, scores against ground truth."""
    clock = analysis.clock
    lines = _verdict_lines(analysis)
    incident_lines, shown = _incident_lines(analysis.incidents, clock, max_rows)
    lines += incident_lines + _autopilot_lines(analysis, clock, max_rows)
    for name, loop in analysis.loops.items():  # a hierarchical profile's further loops
        lines.append(
            f"  loop {name}: {loop.verdict()}  (model {loop.model.name}, {loop.profile.vehicle.rate_hz:g} Hz, "
            f"detectors {', '.join(r.detector for r in loop.results)})"
        )
        lines += [f"    incident {k + 1}: {i.headline_in(clock)}" for k, i in enumerate(loop.incidents[:max_rows])]
        shown += sum(len(i.alarms) for i in loop.incidents[:max_rows])
    if len(analysis.alarms) > shown:
        lines.append(f"  ... {len(analysis.alarms) - shown} more alarm(s) (see the report / --json)")
    if analysis.recovery is not None:
        lines += _recovery_lines(analysis.recovery, clock)
    lines += _set_apart_lines(analysis, clock) + _truth_lines(analysis)
    lines += [f"  warning: {warning}" for warning in analysis.warnings[:MAX_WARNINGS]]
    if len(analysis.warnings) > MAX_WARNINGS:
        lines.append(f"  ... {len(analysis.warnings) - MAX_WARNINGS} more warning(s) (see the report / --json)")
    if report_path:
        lines.append(f"  report: {report_path}")
    return _lines(lines)


def _verdict_lines(analysis) -> list[str]:
    """The verdict line (log, verdict, span, model, detectors), the clock, what was not checked."""
    lines = [
        f"{analysis.path}: {analysis.verdict()}  "
        f"({_analysed_span(analysis)}, model {analysis.model.name}, "
        f"detectors {', '.join(r.detector for r in analysis.results)})"
    ]
    clock = analysis.clock
    if not clock.relative:  # seconds since the log's start, as the span above, need no line
        # the span above and --start/--end count from time zero, the clock's seconds do not: said
        # where both are seconds (PX4 boot time), or an incident's time given to --start misses it
        since_zero = "" if clock.utc else "; the span above and --start/--end count from time zero"
        lines.append(f"  times: {clock.describe()}{since_zero}")
    lines += [f"  not checked: {reason}" for reason in analysis.unchecked]
    lines += [f"  not checked ({analysis.skipped_heading}): {reason}" for reason in analysis.skipped_checks]
    lines += [f"  error: {failure.message}" for failure in analysis.failures]
    return lines


def _incident_lines(incidents, clock, max_rows: int) -> tuple[list[str], int]:
    """The first ``max_rows`` incidents' headlines and under them their alarms (``max_rows`` in all),
    in columns as wide as the longest detector and statistic shown (at least 12 and 16), then how
    many incidents are not listed; the lines and the alarms shown."""
    from logscan.report import overview
    from logscan.verdict.incidents import signal_label

    rows: list = []  # (incident, None for its headline or one of its alarms)
    left = max_rows
    for k, incident in enumerate(incidents[:max_rows]):  # a long log's thousands: the report lists them
        alarms = sorted(incident.alarms, key=lambda a: (a.start, a.signal))[:left]
        left -= len(alarms)
        rows += [(k, None), *((k, alarm) for alarm in alarms)]
    shown = [alarm for _, alarm in rows if alarm is not None]
    detector_w = max([12, *(len(printable(a.detector)) for a in shown)])
    signal_w = max([16, *(len(printable(a.signal)) for a in shown)])
    lines = []
    for k, alarm in rows:
        if alarm is None:
            lines.append(f"  incident {k + 1}: {incidents[k].headline_in(clock)}")
            continue
        ratio = "-" if alarm.peak_ratio is None else f"{alarm.peak_ratio:.3g}"
        note = overview.alarm_note(alarm)  # an indicator's ratio means nothing: its count, in words
        label = "" if note else signal_label(alarm.signal, alarm.detector)  # a note already says it in words
        lines.append(
            f"    {printable(alarm.detector):<{detector_w}} {printable(alarm.signal):<{signal_w}} "
            f"{_clock_time(clock, alarm.start)} {_clock_time(clock, alarm.end)} "
            + (f"  {note}" if note else f"{ratio:>9}")
            + (f"  {label}" if label else "")
        )
    if len(incidents) > max_rows:
        lines.append(f"  ... {len(incidents) - max_rows} more incident(s) (see the report / --json)")
    return lines, len(shown)


def _autopilot_lines(analysis, clock, max_rows: int) -> list[str]:
    """The autopilot's own messages (WARNING and above, armed, in the window), ``max_rows`` of them."""
    messages, disarmed, outside = analysis.autopilot_messages()
    lines = [f"  autopilot: {message.line(clock)}" for message in messages[:max_rows]]
    if len(messages) > max_rows:
        lines.append(f"  ... {len(messages) - max_rows} more autopilot message(s) (see the report / --json)")
    if disarmed:
        lines.append(f"  autopilot: {disarmed} more message(s) of WARNING and above while disarmed (in the report)")
    if outside:
        lines.append(f"  autopilot: {outside} message(s) of WARNING and above outside the window (not listed)")
    return lines


def _set_apart_lines(analysis, clock) -> list[str]:
    """Suppressed alarms (with their reason) and possible faults, three of each."""
    lines = [
        f"  suppressed: {alarm.detector} {alarm.signal} {clock.span_text(alarm.start, alarm.end)} ({reason})"
        for result in analysis.results
        for alarm, reason in result.suppressed[:3]
    ]
    possible = analysis.possible
    lines += [
        f"  possible fault: {p.detector} {p.signal} {clock.span_text(p.start, p.end)} "
        "(a warning: only the upper bound of the statistic crossed its threshold)"
        for p in possible[:3]
    ]
    if len(possible) > 3:
        lines.append(f"  ... {len(possible) - 3} more possible fault(s) (see the report / --json)")
    return lines


def _truth_lines(analysis) -> list[str]:
    """The scores against the log's ground truth, and against PX4's own estimator."""
    lines = []
    for name, score in analysis.scores.items():
        latency = "-" if score.mean_latency_s is None else f"{score.mean_latency_s:.2f} s"
        apart = [
            f"{count} {label}"
            for count, label in ((score.at_onset, "already on at a fault's onset"),
                                 (score.recovery_alarms, "in recovery after a fault"),
                                 (score.transient_alarms, "on healthy transients"))
            if count
        ]  # fmt: skip
        lines.append(
            f"  truth: {name}: detected {score.tp}/{score.tp + score.fn} events, "
            f"{score.fp} false alarm(s), mean latency {latency}"
            + (f" (alarms apart: {', '.join(apart)})" if apart else "")
        )
    versus = analysis.against_baseline()
    if versus is not None:
        lines.append(
            f"  against PX4's own estimator: {versus['also_flagged_by_px4']} of logscan's "
            f"{versus['logscan_alarms']} model-based alarm(s) also flagged by PX4; "
            f"{versus['px4_alone']} of PX4's {versus['px4_alarms']} seen by PX4 alone"
        )
    return lines


def _clock_time(clock, t: float) -> str:
    """An alarm table time in ``clock``: seconds right-aligned in 9, or a UTC time of day."""
    return f"{clock.short(t):>12}" if clock.utc else f"{clock.short(t, 2):>9}"


# --- evaluate -------------------------------------------------------------------------------------


def _num(value: float | None, fmt: str = "{:.2f}") -> str:
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) else fmt.format(value)


def render_scores(evaluation: Evaluation) -> str:
    """Per detector and per check: counts (the alarms that are neither detections nor false alarms
    apart), precision/recall/F1, latency, false alarms per hour; a legend of the apart columns."""
    from logscan.verdict.evaluation import CHECK_SEPARATOR  # here: that module loads the pipeline

    labels = {key: key if CHECK_SEPARATOR not in key else "  " + key for key in evaluation.keys()}
    w = _width("detector / check", labels.values())
    header = (
        f"{'detector / check':<{w}} {'logs':>4} {'events':>6} {'TP':>4} {'FN':>4} {'FP':>4} "
        f"{'at onset':>8} {'recovery':>8} {'transient':>9} "
        f"{'prec':>5} {'recall':>6} {'F1':>5} {'lat mean':>8} {'lat max':>8} {'FA/h healthy':>12}"
    )
    lines = [header, "-" * len(header)]
    for key, label in labels.items():
        s = evaluation.aggregate(key)
        lines.append(
            f"{label:<{w}} {s.n_logs:>4} {s.n_events:>6} {s.tp:>4} {s.fn:>4} {s.fp:>4} "
            f"{s.at_onset:>8} {s.recovery_alarms:>8} {s.transient_alarms:>9} "
            f"{_num(s.precision):>5} {_num(s.recall):>6} {_num(s.f1):>5} "
            f"{_num(s.mean_latency_s, '{:.2f} s'):>8} {_num(s.max_latency_s, '{:.2f} s'):>8} "
            f"{_num(s.false_alarms_per_hour_healthy, '{:.1f}'):>12}"
        )
    lines += [
        "at onset: events whose onset found an alarm already on (that alarm is no detection);",
        f"recovery: alarms starting within {evaluation.recovery_s:g} s after a detected fault's grace period;",
        "transient: alarms on a healthy transient listed in the truth. FP counts none of them.",
    ]
    return _lines(lines)


def render_kinds(evaluation: Evaluation) -> str:
    """Per fault kind (Table III view): detected/events, events with an alarm already on at their
    onset, and latency of each detector and check."""
    from logscan.verdict.evaluation import CHECK_SEPARATOR  # here: that module loads the pipeline

    kinds = evaluation.kinds()
    if not kinds:
        return "per fault kind: no fault events in the evaluated logs"
    keys = evaluation.keys()
    kind_w = _width("fault kind", kinds)
    w = _width("detector / check", ["  " + key for key in keys])
    header = (
        f"{'fault kind':<{kind_w}} {'detector / check':<{w}} {'detected':>8} {'at onset':>8} {'lat mean':>8} "
        f"{'lat max':>8}"
    )
    lines = [header, "-" * len(header)]
    per_key = {key: evaluation.by_kind(key) for key in keys}
    for kind in kinds:
        first = True
        for key in keys:
            stats = per_key[key].get(kind)
            if stats is None:
                continue
            label = key if CHECK_SEPARATOR not in key else "  " + key
            lines.append(
                f"{kind if first else '':<{kind_w}} {label:<{w}} {f'{stats.tp}/{stats.n_events}':>8} "
                f"{stats.at_onset:>8} "
                f"{_num(stats.mean_latency_s, '{:.2f} s'):>8} {_num(stats.max_latency_s, '{:.2f} s'):>8}"
            )
            first = False
    return _lines(lines)


def render_observability(evaluation: Evaluation) -> str:
    """Per fault kind with unobservable events (`logscan.verdict.observability`): per detector, the misses,
    those of them that lay wholly where the fault could not be seen, and the detection rate over the
    events that could be seen. Empty when no event was judged unobservable."""
    from logscan.verdict.evaluation import CHECK_SEPARATOR  # here: that module loads the pipeline

    keys = [key for key in evaluation.keys() if CHECK_SEPARATOR not in key]
    per_key = {key: evaluation.by_kind(key) for key in keys}
    kinds = [kind for kind in evaluation.kinds() if any(s.unobservable for k in keys if (s := per_key[k].get(kind)))]
    if not kinds:
        return ""
    kind_w, w = _width("fault kind", kinds), _width("detector", keys)
    header = (
        f"{'fault kind':<{kind_w}} {'detector':<{w}} {'events':>6} {'unobs.':>6} {'missed':>6} {'of them unobs.':>14} "
        f"{'detected / observable':>21}"
    )
    lines = [f"faults that could not be seen ({doc_url('algorithms.md')} section 10):", header, "-" * len(header)]
    for kind in kinds:
        for i, key in enumerate(k for k in keys if k in per_key and kind in per_key[k]):
            st = per_key[key][kind]
            seen = f"{st.tp - (st.unobservable - st.fn_unobservable)}/{st.n_events - st.unobservable}"
            lines.append(
                f"{kind if i == 0 else '':<{kind_w}} {key:<{w}} {st.n_events:>6} {st.unobservable:>6} {st.fn:>6} "
                f"{st.fn_unobservable:>14} {seen:>21}"
            )
    lines.append("unobs.: events whose whole span lay where a fault of their kind and size left no signature.")
    return _lines(lines)


def _width(title: str, names, least: int = 0) -> int:
    """A name column's width: its longest name (escaped as printed) or its title."""
    return max([least, len(title), *(len(printable(name)) for name in names)])


def render_evaluation(evaluation: Evaluation) -> str:
    """The one-screen text report of `logscan evaluate`."""
    n_healthy = sum(log.healthy for log in evaluation.logs)
    n_events = sum(len(log.events) for log in evaluation.logs)
    n_transients = sum(len(log.transients) for log in evaluation.logs)
    hours = sum(log.duration_s for log in evaluation.logs if log.healthy) / 3600.0
    parts = [
        f"evaluated {len(evaluation.logs)} log(s) with ground truth: {n_events} fault event(s), "
        f"{n_transients} healthy transient(s), {n_healthy} healthy log(s) ({hours * 60:.1f} min); "
        f"grace {evaluation.grace_s:g} s, recovery {evaluation.recovery_s:g} s",
    ]
    if evaluation.logs:
        parts += ["", render_scores(evaluation), "", render_kinds(evaluation)]
        blind = render_observability(evaluation)
        parts += ["", blind] if blind else []
    if evaluation.skipped:
        parts.append("")
        parts.append(
            printable(
                f"skipped {len(evaluation.skipped)} log(s) without ground truth: "
                + ", ".join(Path(p).name for p in evaluation.skipped)
            )
        )
    if evaluation.failures:
        parts.append("")
        parts.append(f"{len(evaluation.failures)} log(s) could not be evaluated (errors on stderr)")
    return "\n".join(parts)


# --- detectors ------------------------------------------------------------------------------------


def render_detectors(entries: list[dict], parameters: bool = True) -> str:
    """Plain-text table of registry entries (``DetectorEntry.to_dict()`` rows), then each
    detector's declared parameters with their defaults and allowed values."""
    if not entries:
        return "no detectors registered"
    rows = [(e["name"], e["origin"], e["description"] if e["ok"] else "BROKEN") for e in entries]
    name_w = max(len("name"), *(len(r[0]) for r in rows))
    origin_w = max(len("origin"), *(len(r[1]) for r in rows))
    lines = [f"{'name':<{name_w}}  {'origin':<{origin_w}}  description"]
    lines += [f"{n:<{name_w}}  {o:<{origin_w}}  {d}" for n, o, d in rows]
    problems = [(e["name"], e["origin"], p) for e in entries for p in e["problems"]]
    if problems:
        lines.append("")
        lines.append("problems:")
        lines += [f"  {n} ({o}): {p}" for n, o, p in problems]
    if parameters:
        for entry in entries:
            if entry.get("parameters"):
                lines += ["", f"{entry['name']} parameters ([detectors.{entry['name']}] in a profile):"]
                lines += _parameter_lines(entry["parameters"])
    return _lines(lines)


def _parameter_lines(rows: list[dict]) -> list[str]:
    """One line per declared parameter: name, default, allowed values."""
    import json

    shown = [(r["name"], json.dumps(r["default"]), r["constraints"]) for r in rows]
    name_w = max(len(n) for n, _, _ in shown)
    default_w = max(len(d) for _, d, _ in shown)
    return [f"  {n:<{name_w}}  default {d:<{default_w}}  {c}" for n, d, c in shown]


# --- inspect --------------------------------------------------------------------------------------
