"""The report's overview: what the verdict box says, the margin table, and the detector sections'
order and one-line summaries.

A reader should see in ten seconds whether something alarmed, when and on which sensor (the
incidents' headlines in the verdict box), and on a clean log how close each check came (the
margins). Detectors that alarmed come first and open; the others collapse to one line with their
closest margin.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from logscan.alarms import AlarmInterval
from logscan.report.context import number_text
from logscan.report.margins import Margin, peak_margin, ratio_text
from logscan.results import DetectorResult, Incident
from logscan.timebase.clock import Clock
from logscan.verdict.incidents import signal_label

REJECTED_PREFIX = "rejected."  # indicator statistics: 1 where the filter refused a sample
UNCAPPED = "uncapped peak"  # the alarm table's note where the figure holds the statistic at a cap


def rejected_words(n: int) -> str:
    """What a ``rejected.<group>`` alarm means, in plain words."""
    return f"{n} sample{'' if n == 1 else 's'} outside the physical range, the filter skipped them"


def is_rejected(signal: str) -> bool:
    return signal.startswith(REJECTED_PREFIX)


def alarm_note(alarm: AlarmInterval) -> str:
    """Plain words replacing peak / threshold for alarms whose ratio means nothing, or when the
    change began by a sequential test's estimate ("" otherwise)."""
    if is_rejected(alarm.signal):
        return rejected_words(int(alarm.n_exceed))
    if alarm.change_time is not None:
        return f"change estimated to begin {max(alarm.start - alarm.change_time, 0.0):.2f} s before the alarm"
    return ""


def uncapped_peak(alarm: AlarmInterval, info: Mapping) -> dict | None:
    """The uncapped peak a detector gives for an alarm whose statistic it holds at a cap (cusum:
    ``info["uncapped_peaks"][signal]``, one record per alarm it raised), the largest of those within
    the alarm (alarms merged later hold several); None when there is none."""
    records = (info.get("uncapped_peaks") or {}).get(alarm.signal) or []
    inside = [r for r in records if r["start"] >= alarm.start - 1e-9 and r["end"] <= alarm.end + 1e-9]
    return max(inside, key=lambda r: abs(r["peak_ratio"]), default=None)


def peak_cells(alarm: AlarmInterval, info: Mapping) -> dict:
    """The alarm table's peak, threshold at peak, peak / threshold and note: the uncapped peak where
    the detector gives one (the figure holds the statistic at its cap)."""
    note, peak = alarm_note(alarm), uncapped_peak(alarm, info)
    if peak is None:
        value, threshold, ratio = alarm.peak_value, alarm.peak_threshold, alarm.peak_ratio
    else:
        value, threshold, ratio = peak["peak_value"], peak["peak_threshold"], peak["peak_ratio"]
        note = f"{UNCAPPED}; {note}" if note else UNCAPPED
    cells = {"peak": number_text(value), "threshold": number_text(threshold), "ratio": number_text(ratio, 3)}
    return cells | {"note": note, "uncapped": peak is not None}


def closest_line(margins: Sequence[Margin], clock: Clock | None = None) -> str:
    """'closest to a threshold: nis.all peaked at 0.815 of its threshold (28.95 s)' ("" if none);
    the time in ``clock`` (default: seconds since the log's start)."""
    peak = peak_margin([m for m in margins if not is_rejected(m.statistic)])
    if peak is None:
        return ""
    when = "" if peak.time is None else f" ({(clock or Clock()).text(peak.time)})"
    return f"closest to a threshold: {peak.statistic} peaked at {ratio_text(peak.ratio)} of its threshold{when}"


def verdict_lines(incidents: Sequence[Incident], margins: Sequence[Margin], clock: Clock | None = None) -> list[str]:
    """Lines under the verdict: each incident's headline, or, with none, the closest margin."""
    if incidents:
        return [inc.headline_in(clock) for inc in incidents]
    line = closest_line(margins, clock)
    return [line[0].upper() + line[1:]] if line else []


def margin_rows(
    margins: Sequence[Margin],
    results: Sequence[DetectorResult] = (),
    sections: Mapping[str, str] | None = None,
    clock: Clock | None = None,
) -> list[dict]:
    """Rows of the margin table, in the order given; ``rejected.*`` statistics of ``results`` are
    given as the count of samples the filter skipped; ``sections``: detector -> its section's id;
    times in ``clock`` (default: seconds since the log's start)."""
    clock = clock or Clock()
    rejected = {
        (r.detector, name): int(np.nansum(values))
        for r in results
        for name, values in r.series.items()
        if is_rejected(name)
    }
    rows = []
    for m in margins:
        note = m.note
        if is_rejected(m.statistic):
            note = rejected_words(rejected.get((m.detector, m.statistic), 0))
        elif m.ratio is not None and m.ratio > 1 and not m.n_alarms:
            note = "above 1 too briefly to raise an alarm"
        rows.append({
            "detector": m.detector,
            "statistic": m.statistic,
            "label": signal_label(m.statistic, m.detector),
            "kind": m.kind or "—",
            "ratio": "—" if is_rejected(m.statistic) else ratio_text(m.ratio),
            "time": "—" if m.time is None or is_rejected(m.statistic) else clock.short(m.time),
            "t": "" if m.time is None or is_rejected(m.statistic) else repr(clock.axis_value(m.time)),
            "section": (sections or {}).get(m.detector, ""),
            "value": "—" if m.value is None or is_rejected(m.statistic) else f"{m.value:.4g}",
            "n_alarms": m.n_alarms,
            "level": _level(m),
            "note": note,
        })  # fmt: skip
    return rows


MIN_MARGINS_SHOWN = 3  # the closest checks shown even when none came near its threshold


def fold_margins(margins: Sequence[Margin], rows: list[dict]) -> dict:
    """The margin table folded to the checks that matter: those that alarmed or came above 0.8 of
    their threshold, and at least the MIN_MARGINS_SHOWN closest; the rest (``folded``, with a line
    saying how close they came at most) behind a toggle. ``rows``: `margin_rows` of ``margins``."""
    matter = {i for i, row in enumerate(rows) if row["level"] or row["n_alarms"]}
    ratios = {
        i: float(m.ratio)
        for i, m in enumerate(margins)
        if m.ratio is not None and not math.isnan(m.ratio) and not is_rejected(m.statistic)
    }
    rated = sorted(ratios, key=lambda i: -ratios[i])
    for i in rated:
        if len(matter) >= MIN_MARGINS_SHOWN:
            break
        matter.add(i)
    folded = [i for i in range(len(rows)) if i not in matter]
    closest = max((ratios[i] for i in folded if i in ratios), default=None)
    line = "none with a ratio" if closest is None else f"each at most {ratio_text(closest)} of its threshold"
    return {
        "shown": [row for i, row in enumerate(rows) if i in matter],
        "folded": [rows[i] for i in folded],
        "folded_line": line,
    }


def _level(margin: Margin) -> str:
    """CSS class of a margin row: "over" (alarmed or above 1), "near" (above 0.8), "" otherwise."""
    if margin.n_alarms or (margin.ratio is not None and margin.ratio > 1):
        return "over"
    if margin.ratio is not None and not math.isnan(margin.ratio) and margin.ratio > 0.8:
        return "near"
    return ""


def section_line(n_alarms: int, margins: Sequence[Margin], clock: Clock | None = None) -> str:
    """One line for a detector section's heading: its alarms, or its closest margin."""
    if n_alarms:
        return f"{n_alarms} alarm{'' if n_alarms == 1 else 's'}"
    closest = closest_line(margins, clock)
    return "no alarms" + (f"; {closest}" if closest else "")


def order_sections(sections: list[dict]) -> list[dict]:
    """Sections of detectors that alarmed first (each group in its original order), each given its
    element id "detector-<n>" in that order."""
    ordered = sorted(sections, key=lambda s: s["n_alarms"] == 0)
    for i, section in enumerate(ordered, 1):
        section["id"] = f"detector-{i}"
    return ordered
