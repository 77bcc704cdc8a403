"""What a terminal shows while one log is analysed, and the verdict's colour.

The pipeline reports its steps (reading, aligning, filtering, detecting, writing the report) as
they begin, the reader the bytes it has read, a block of the file at a time, and the EKF the steps
it has filtered (`logscan.pipeline.step_counter`). One long log gets
one line per step, redrawn in place while the step runs with a bar, its fraction and the ETAs of
the step and the whole log (`logscan.cli.progress_bar`; a frozen "filtering..." for 30 s looks
like a hang), and the time it took once the next begins. Only on a terminal, and never under CI
or --quiet (`show_progress`).

Colour follows https://no-color.org and https://force-color.org: NO_COLOR (non-empty) turns it
off, else FORCE_COLOR (non-empty) turns it on, else it is on for a terminal only.
"""

from __future__ import annotations

import os
import sys

import click

from logscan.cli.progress_bar import BarLine, EtaModel
from logscan.cli.render import printable

_LINE: list[BarLine | None] = [None]
_SKIPPED: set[str] = set()  # the phases this run leaves out, for the ETA of the whole log (`plan_steps`)


def plan_steps(report: bool) -> None:
    """What the steps of this run's one log will be: with or without the report's."""
    _SKIPPED.clear()
    if not report:
        _SKIPPED.add("report")  # the step line of this process's one log (analyze, one log on a terminal)


def echo_step(message: str) -> None:
    """A step of the analysis of one log (``<log>: <step>``), on its redrawn line (`BarLine`);
    module-level, so a task that carries it still pickles."""
    line = _LINE[0]
    if line is None:
        line = _LINE[0] = BarLine(model=EtaModel(skipped=frozenset(_SKIPPED)))
    line.step(printable(f"logscan: {message}"), name=message.rpartition(": ")[2])


def echo_fraction(done: int, total: int) -> None:
    """The step under way has done ``done`` of ``total`` (the bytes a reader has read, the steps the
    EKF has filtered); drawn with the line's next tick. Module-level, as `echo_step`."""
    line = _LINE[0]
    if line is not None:
        line.fraction(done, total)


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
