"""What a terminal shows while one log is analysed, and the verdict's colour.

The pipeline reports its steps (reading, aligning, filtering, detecting, writing the report) as
they begin, not fractions of them: no reader counts its bytes to a callback and the filter's
compiled loop over the samples reports nothing until it ends. So one long log gets one line per
step with its elapsed time, ticking while the step runs (a frozen "filtering..." for 30 s looks
like a hang; "filtering... 12 s" does not), and the time it took once the next begins; there is
no bar and no ETA. Only on a terminal, and never under CI (`show_progress`).

Colour follows https://no-color.org and https://force-color.org: NO_COLOR (non-empty) turns it
off, else FORCE_COLOR (non-empty) turns it on, else it is on for a terminal only.
"""

from __future__ import annotations

import os
import sys
import threading
import time

import click

from logscan.cli.render import printable

_CLEAR = "\r\x1b[K"  # back to the start of the line, and erase it


class StepLine:
    """One line on stderr for the step under way: "logscan: flight.ulg: filtering... 12 s",
    redrawn every ``interval`` seconds by a daemon thread; a new step (or `close`) ends it as
    "logscan: flight.ulg: filtering (31.4 s)"."""

    def __init__(self, interval: float = 0.5):
        self.interval = interval
        self._lock = threading.Lock()
        self._text: str | None = None
        self._start = 0.0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def step(self, text: str) -> None:
        with self._lock:
            self._end_line()
            self._text, self._start = text, time.monotonic()
            self._draw()
        if self._thread is None:
            self._thread = threading.Thread(target=self._tick, name="logscan-progress", daemon=True)
            self._thread.start()

    def clear(self) -> None:
        """Erase the line (it is drawn again at the next tick): a notice printed now gets a line of its own."""
        with self._lock:
            if self._text is not None:
                _write(_CLEAR)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2 * self.interval)
        with self._lock:
            self._end_line()

    def _tick(self) -> None:
        while not self._stop.wait(self.interval):
            with self._lock:
                if self._text is not None:
                    self._draw()

    def _draw(self) -> None:
        _write(f"{_CLEAR}{self._text}... {time.monotonic() - self._start:.0f} s")

    def _end_line(self) -> None:
        if self._text is not None:
            _write(f"{_CLEAR}{self._text} ({time.monotonic() - self._start:.1f} s)\n")
            self._text = None


def _write(text: str) -> None:
    try:
        sys.stderr.write(text)
        sys.stderr.flush()
    except (OSError, ValueError):
        pass  # stderr gone: progress is not worth an error


_LINE: list[StepLine | None] = [None]  # the step line of this process's one log (analyze, one log on a terminal)


def echo_step(message: str) -> None:
    """A step of the analysis of one log (``<log>: <step>``), on its ticking line (`StepLine`);
    module-level, so a task that carries it still pickles."""
    line = _LINE[0]
    if line is None:
        line = _LINE[0] = StepLine()
    line.step(printable(f"logscan: {message}"))


def end_steps() -> None:
    """End the step line (its last step's time printed), before the summary."""
    line, _LINE[0] = _LINE[0], None
    if line is not None:
        line.close()


def clear_step_line() -> None:
    """Erase the step line, if any, so that a notice printed now starts at the line's beginning."""
    if _LINE[0] is not None:
        _LINE[0].clear()


def use_colour(err: bool = False) -> bool:
    """Colour for stdout (stderr when ``err``): NO_COLOR off, FORCE_COLOR on, else on a terminal."""
    if os.environ.get("NO_COLOR"):
        return False
    if os.environ.get("FORCE_COLOR"):
        return True
    stream = sys.stderr if err else sys.stdout
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False


_VERDICT_COLOURS = {0: "green", 1: "red", 2: "yellow"}  # by the log's exit code; 3 (a failure): red


def coloured_verdict(text: str, verdict: str, exit_code: int) -> str:
    """``text`` (a log's summary) with the verdict in its first line bold and coloured by the
    log's exit code: green no alarms, red alarms or a failure, yellow not fully checked."""
    first, newline, rest = text.partition("\n")
    shown = printable(verdict)
    styled = click.style(shown, fg=_VERDICT_COLOURS.get(exit_code, "red"), bold=True)
    return first.replace(f": {shown}  (", f": {styled}  (", 1) + newline + rest
