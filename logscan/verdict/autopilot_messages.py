"""The autopilot's own messages of level WARNING and above during flight, each with its incident.

What PX4 told its pilot ("Attitude failure (roll)", "Failsafe activated", "Dangerous battery
level!, please land!") belongs beside logscan's verdict: a ULog's logged messages
(`logscan.report.run_context.logged_messages`) while the vehicle was armed (every message when the log does
not say when it was armed), repeated identical messages folded into one with a count (a message
PX4 repeats each second must not flood the summary), each placed in the incident whose span, widened
by ``SLACK_S``, holds it (the autopilot reports after the fact; the same second of slack as the
comparison with PX4's own estimator tests).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

from logscan.log import MESSAGE_LEVELS, logged_messages

SLACK_S = 1.0  # a message this close to an incident's span falls in it
MAX_SHOWN = 50  # distinct messages the report's table shows (the JSON has them all)


@dataclass
class AutopilotMessage:
    """One distinct message of the flight: level, text, first and last time (s since the log's time
    zero), how many times it was logged, and the incident (1-based, as listed) it falls in."""

    level: str
    text: str
    first: float
    last: float
    count: int = 1
    incident: int | None = None

    def to_dict(self, clock=None) -> dict:
        out = {
            "level": self.level,
            "text": self.text,
            "start": self.first,
            "end": self.last,
            "count": self.count,
            "incident": self.incident,
        }
        return clock.stamp(out) if clock is not None else out

    def line(self, clock=None) -> str:
        """ "ERROR at 3.2 s: [commander] Dangerous battery level!, please land! (x3, until 5.1 s; in incident 1)"."""
        at = clock.text(self.first) if clock is not None else f"{self.first:.1f} s"
        more = []
        if self.count > 1:
            until = clock.text(self.last) if clock is not None else f"{self.last:.1f} s"
            more.append(f"x{self.count}, until {until}")
        more.append(f"in incident {self.incident}" if self.incident is not None else "in no incident")
        return f"{self.level} at {at}: {self.text} ({'; '.join(more)})"


def _incident_of(t: float, incidents: Sequence) -> int | None:
    """The 1-based number of the incident whose span (widened by SLACK_S) holds ``t``, the nearest
    one's when several do."""
    best, distance = None, None
    for k, incident in enumerate(incidents):
        if incident.start - SLACK_S <= t <= incident.end + SLACK_S:
            d = 0.0 if incident.start <= t <= incident.end else min(abs(t - incident.start), abs(t - incident.end))
            if distance is None or d < distance:
                best, distance = k + 1, d
    return best


def _armed_at(t: float, armed: Sequence[tuple[float, float]] | None) -> bool:
    return armed is None or any(start <= t <= end for start, end in armed)


class FlightMessages(NamedTuple):
    """The autopilot's messages of WARNING and above as the verdict lists them."""

    listed: list[AutopilotMessage]  # distinct, in time order of their first occurrence
    disarmed: int  # logged while disarmed (within the window): counted, not listed
    outside: int  # logged outside the window (--start/--end): counted, not listed


def flight_messages(
    metadata: dict,
    start_ns: int,
    incidents: Sequence,
    armed: Sequence[tuple[float, float]] | None,
    window: tuple[float, float] | None = None,
) -> FlightMessages:
    """The distinct messages of WARNING and above logged while ``armed`` (intervals in s since
    ``start_ns``; None: unknown, every message) and within ``window`` (first and last time
    analysed, s since ``start_ns``; None: the whole log), with their incident; and how many were
    logged while disarmed, and outside the window. A window's verdict is about the window: a
    message logged before or after it is no part of what was judged."""
    found = logged_messages(metadata, start_ns, MESSAGE_LEVELS, limit=None)
    inside = [m for m in found if window is None or window[0] <= m.t <= window[1]]
    kept: dict[tuple[str, str, int | None], AutopilotMessage] = {}
    disarmed = 0
    for message in inside:
        if not _armed_at(message.t, armed):
            disarmed += 1
            continue
        incident = _incident_of(message.t, incidents)
        key = (message.level, message.text, incident)
        if key in kept:
            entry = kept[key]
            entry.count += 1
            entry.last = max(entry.last, message.t)
        else:
            kept[key] = AutopilotMessage(message.level, message.text, message.t, message.t, 1, incident)
    return FlightMessages(sorted(kept.values(), key=lambda m: m.first), disarmed, len(found) - len(inside))
