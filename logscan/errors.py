"""Typed errors of logscan and the one exit-code enum: each error carries the code the CLI maps it to."""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from enum import IntEnum

from logscan.docs import doc_url

# set by the CLI's Ctrl-C handler (logscan.cli.main): a Ctrl-C whose exception Python swallowed
# (raised while a finalizer ran, e.g. llvmlite's ObjectRef.__del__: "Exception ignored in ...")
# still stops the run before its outputs are committed (`logscan.artifacts.commit`)
INTERRUPT_SEEN = [False]


class ExitCode(IntEnum):
    """The exit codes of every logscan command."""

    OK = 0  # no alarm
    ALARMS = 1  # at least one alarm (0 with --exit-zero)
    BAD_INPUT = 2  # bad usage or input: one line on stderr says which file and what to do
    INTERNAL = 3  # a bug in logscan: rerun with --debug for the traceback
    INTERRUPTED = 130  # Ctrl-C


class LogscanError(Exception):
    """Base of every error logscan expects; the CLI turns it into one line and an exit code.

    ``message`` should name the file (when there is one), what is wrong and what to do.
    """

    exit_code = ExitCode.BAD_INPUT

    def __init__(self, message: str, *, path: str | None = None, hint: str | None = None):
        super().__init__(message)
        self.message = message
        self.path = path
        self.hint = hint

    def one_line(self) -> str:
        parts = []
        if self.path:
            parts.append(f"{self.path}:")
        parts.append(self._every_problem())
        text = " ".join(parts)
        if self.hint:
            text = f"{text} ({self.hint})"
        return " ".join(text.split())

    def _every_problem(self) -> str:
        """The message with every problem an error collected (``problems``) listed: "invalid
        profile: 3 problems: a; b; c" for its "invalid profile: a (2 more)"."""
        problems = getattr(self, "problems", None) or []
        folded = f"{problems[0]} ({len(problems) - 1} more)" if len(problems) > 1 else None
        if folded is None or folded not in self.message:
            return self.message
        return self.message.replace(folded, f"{len(problems)} problems: " + "; ".join(problems))


class UsageError(LogscanError):
    """The command line asks for something impossible."""


class InputError(LogscanError):
    """An input file cannot be read: missing, unknown format, corrupt or empty."""

    # set when a built-in profile the log cannot complete is why: its TOML text, to edit (read with
    # getattr by `logscan profile`)
    profile_text: str


class UnsupportedFormatError(InputError):
    """The file's content matches none of the readers."""


class CorruptLogError(InputError):
    """The file's structure is broken beyond what a partial read can recover."""


class ProfileError(LogscanError):
    """A profile is invalid: unknown key, wrong type, unknown channel or model."""

    problems: list[str]  # every problem found, when more than the message's first (`profiles.problems`)


class ModelError(LogscanError):
    """A vehicle model cannot be built from the given name or parameters."""

    problems: list[str]  # every problem found, when more than the message's first (`models.base.model_error`)


class NotTrainedError(LogscanError):
    """A detector needs trained state that is missing: run `logscan train`."""


class InternalError(LogscanError):
    """A bug in logscan; exit code 3 and a hint to rerun with --debug."""

    exit_code = ExitCode.INTERNAL


# --start/--end cut the analysis after the whole log is read, but for an indexed MCAP file (read in
# part, `logscan.readers.mcap.window`): a window saves the later steps' memory, not the reading's
OUT_OF_MEMORY = (
    "the log needs more memory than is available (logscan reads a whole log, also for a --start/--end window, "
    "except an MCAP file with message indexes): analyse it on a machine with more memory, or cut the part you "
    "need out of it first "
    f"({doc_url('troubleshooting.md')}#a-log-does-not-fit-in-memory)"
)


class OutOfMemoryError(LogscanError):
    """A MemoryError met while working on a log: the machine is too small for it, not a bug (exit 2)."""

    def __init__(self, path: str | None = None):
        super().__init__(OUT_OF_MEMORY, path=path)


def where_in_text(exc: BaseException) -> str:
    """ " (line 3, column 9)" for a parser's error that knows where it stopped (json's
    JSONDecodeError), "" for one that does not: a message names the place, not the parser's words."""
    line, column = getattr(exc, "lineno", None), getattr(exc, "colno", None)
    return f" (line {line}, column {column})" if line is not None and column is not None else ""


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """ "did you mean 'nis'? " (with its trailing space, to open a hint) when one of ``choices`` is
    close to the misspelt ``word`` (difflib's ratio >= 0.6, up to three names); "" when none is."""
    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=3, cutoff=0.6)
    return f"did you mean {' or '.join(repr(c) for c in close)}? " if close else ""
