"""The step line of one log on a terminal: a bar, the fraction done and an ETA for the step under
way and for the whole log ("logscan: f.mcap: reading [#####.......] 41% ETA 3 s, log 21 s").

What is measured: the bytes a reader has read of the file (`logscan.readers.read_log`'s
``progress``, called per block of the file, never per message) give the reading step its fraction;
the steps the EKF has filtered (counted by its kernel as it runs, `logscan.pipeline.step_counter`)
give the filtering step its own. The detectors are one call each: their fraction is estimated from
the time model below, and drawn with a "~".

The time model (`EtaModel`): every step of an analysis does work in proportion to the log's size
(bytes read, grid steps filtered and checked), so the shares of the whole analysis the steps take
are about the same for every log of a kind, whatever its length. `SHARES` are those shares as
measured on a 20-minute simulated quadcopter MCAP (54 MB, `SHARES`). A step that has finished,
or the reading step with its measured fraction, gives this log's seconds per share; the steps still
to come are estimated from it, refined each time a step ends.

Off a terminal (a file, a pipe) the line is not redrawn: each step gets one line with the time it
took, as before the bar existed.
"""

from __future__ import annotations

import shutil
import sys
import threading
import time
from typing import TextIO

_CLEAR = "\r\x1b[K"  # back to the start of the line, and erase it
BAR_WIDTH = 20

# The steps' shares of one analysis (see the module docstring): the step times of `logscan analyze`
# on a 20-minute simulated quadcopter MCAP (`logscan simulate quadcopter --duration 1200`, 54 MB),
# warm cache, in one run: reading 2.16 s, aligning 0.31 s, filtering 2.09 s, the four default
# detectors 8.55 s, the report 3.06 s, of 16.2 s. A phase is a step name's first word (`phase_of`).
SHARES: dict[str, float] = {"reading": 0.13, "aligning": 0.02, "filtering": 0.13, "detecting": 0.53, "report": 0.19}
_PHASES = tuple(SHARES)
MIN_MEASURED = 0.02  # a measured fraction below this says too little of the step's speed to extrapolate


def phase_of(step: str) -> str | None:
    """The phase of a step's name ("filtering loop x" -> filtering, "detector nis" -> detecting)."""
    word = step.split(" ", 1)[0]
    if word in ("detector", "recovery"):
        return "detecting"
    if word == "writing":
        return "report"
    return word if word in SHARES else None


class EtaModel:
    """Seconds left of the step under way and of the whole log (see the module docstring)."""

    def __init__(self, shares: dict[str, float] | None = None, skipped: frozenset[str] = frozenset()) -> None:
        """``skipped``: phases this run leaves out (no report: ``--no-report``), no share of the whole."""
        self.shares = {phase: 0.0 if phase in skipped else share for phase, share in (shares or SHARES).items()}
        self.spent: dict[str, float] = {}  # seconds of the steps ended, by phase

    def end(self, phase: str | None, seconds: float) -> None:
        if phase is not None:
            self.spent[phase] = self.spent.get(phase, 0.0) + seconds

    def rate(self, phase: str, elapsed: float, measured: float | None) -> float | None:
        """This log's seconds per share: from the phases ended before ``phase`` (a phase skipped,
        e.g. no filter for a filter-free detector, counts for neither) and from ``phase`` itself
        when its fraction is measured."""
        before = [p for p in _PHASES[: _PHASES.index(phase)] if self.spent.get(p)]
        seconds = sum(self.spent[p] for p in before)
        share = sum(self.shares[p] for p in before)
        if measured is not None and measured >= MIN_MEASURED:
            seconds += (self.spent.get(phase, 0.0) + elapsed) / measured
            share += self.shares[phase]
        return seconds / share if share > 0 else None

    def estimate(self, phase: str, elapsed: float, measured: float | None) -> tuple[float, float, float] | None:
        """(fraction of ``phase`` done, its seconds left, the log's seconds left), None before
        anything says how fast this log goes."""
        rate = self.rate(phase, elapsed, measured)
        if rate is None:
            return None
        done = self.spent.get(phase, 0.0) + elapsed
        if measured is not None and measured >= MIN_MEASURED:
            fraction, left = measured, elapsed * (1.0 - measured) / measured
        else:
            expected = rate * self.shares[phase]
            fraction = min(done / expected, 0.99) if expected > 0 else 0.99
            left = max(expected - done, 0.0)
        after = _PHASES[_PHASES.index(phase) + 1 :]
        return fraction, left, left + rate * sum(self.shares[p] for p in after)


def eta_text(seconds: float) -> str:
    seconds = int(round(seconds))
    return f"{seconds} s" if seconds < 60 else f"{seconds // 60} min {seconds % 60:02d} s"


def bar_text(fraction: float, measured: bool) -> str:
    filled = int(fraction * BAR_WIDTH)
    percent = int(fraction * 100)  # floored: 100 % only when done
    return f"[{'#' * filled}{'.' * (BAR_WIDTH - filled)}] {'' if measured else '~'}{percent}%"


class BarLine:
    """The step under way, on one line of ``stream`` (default: stderr, looked up at each write):
    redrawn in place every ``interval`` seconds on a terminal (a bar and ETAs once the model can
    tell, else the step's elapsed time), ended by the next step (or `close`) as
    "logscan: f.mcap: filtering (31.4 s)". Off a terminal only those ended lines are written."""

    def __init__(self, interval: float = 0.5, stream: TextIO | None = None, model: EtaModel | None = None):
        self.interval = interval
        self.model = model or EtaModel()
        self._stream = stream
        self._lock = threading.Lock()
        self._text: str | None = None
        self._phase: str | None = None
        self._start = 0.0
        self._measured: float | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def step(self, text: str, name: str = "") -> None:
        """A new step: ``text`` the whole line's label, ``name`` the step's own ("filtering")."""
        with self._lock:
            self._end_line()
            self._text, self._phase, self._start, self._measured = text, phase_of(name), time.monotonic(), None
            self.draw()
        if self._thread is None and self._terminal():
            self._thread = threading.Thread(target=self._tick, name="logscan-progress", daemon=True)
            self._thread.start()

    def fraction(self, done: int, total: int) -> None:
        """The step under way has done ``done`` of ``total`` (bytes read); drawn at the next tick."""
        if total > 0:
            self._measured = min(max(done / total, 0.0), 1.0)

    def clear(self) -> None:
        """Erase the line (it is drawn again at the next tick): a notice printed now gets a line of its own."""
        with self._lock:
            if self._text is not None and self._terminal():
                self._write(_CLEAR)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2 * self.interval)
        with self._lock:
            self._end_line()

    def line(self) -> str:
        """The line as drawn now."""
        elapsed = time.monotonic() - self._start
        if self._phase is not None:
            found = self.model.estimate(self._phase, elapsed, self._measured)
            if found is not None:
                fraction, left, whole = found
                measured = self._measured is not None and self._measured >= MIN_MEASURED
                tail = f" {bar_text(fraction, measured)} ETA {eta_text(left)}, log {eta_text(whole)}"
                return _fit(f"{self._text}", tail)
        return _fit(f"{self._text}", f"... {elapsed:.0f} s")

    def _tick(self) -> None:
        while not self._stop.wait(self.interval):
            with self._lock:
                if self._text is not None:
                    self.draw()

    def draw(self) -> None:
        """Redraw the line (the ticker's call, under its lock; a terminal only)."""
        if self._terminal():
            self._write(f"{_CLEAR}{self.line()}")

    def _end_line(self) -> None:
        if self._text is not None:
            seconds = time.monotonic() - self._start
            self.model.end(self._phase, seconds)
            self._write(f"{_CLEAR if self._terminal() else ''}{self._text} ({seconds:.1f} s)\n")
            self._text = None

    def _out(self) -> TextIO:
        return self._stream if self._stream is not None else sys.stderr

    def _terminal(self) -> bool:
        try:
            return bool(self._out().isatty())
        except (AttributeError, ValueError):
            return False

    def _write(self, text: str) -> None:
        try:
            out = self._out()
            out.write(text)
            out.flush()
        except (OSError, ValueError):
            pass  # stderr gone: progress is not worth an error


def _fit(label: str, tail: str) -> str:
    """``label`` + ``tail`` within the terminal's width (a wrapped line is not redrawn in place):
    the label shortened from its start, the bar and ETAs kept."""
    width = shutil.get_terminal_size((80, 24)).columns - 1
    room = width - len(tail)
    if len(label) > room:
        label = "..." + label[-max(room - 3, 0) :] if room > 3 else ""
    return label + tail
