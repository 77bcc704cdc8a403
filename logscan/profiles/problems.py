"""How profile problems are reported: collected messages -> one ProfileError, suggestions, value names."""

from __future__ import annotations

import difflib
import heapq
import re
from typing import Any

from logscan.docs import doc_url
from logscan.errors import ProfileError

DOCS_HINT = f"see {doc_url('profiles.md')}"


def profile_error(problems: list[str], source: str, hint: str = DOCS_HINT) -> ProfileError:
    more = f" ({len(problems) - 1} more)" if len(problems) > 1 else ""
    err = ProfileError(f"invalid profile: {problems[0]}{more}", path=source, hint=hint)
    err.problems = list(problems)
    return err


def single_error(message: str, source: str | None, hint: str = DOCS_HINT) -> ProfileError:
    err = ProfileError(message, path=source, hint=hint)
    err.problems = [message]
    return err


def suggest(word: str, choices, label: str = "did you mean") -> str:
    close = difflib.get_close_matches(word, list(choices), n=3, cutoff=0.6)
    if close:
        return f" ({label} {', '.join(repr(c) for c in close)}?)"
    return ""


_UNIT = re.compile(r"\s*\[[^\[\]]*\]\s*$")  # a column's unit in its header: "x [m]", "time [s]"
MAX_SUGGESTED = 3


def _bare(name: str) -> str:
    return _UNIT.sub("", name)


def suggest_channel(word: str, names) -> str:
    """`suggest` for a channel name: each name also compared without a unit suffix on either side
    (a CSV header's "x [m]": a profile naming "/x", or "/sped [m/s]"); the closest first."""
    bare = _bare(word)
    scored = []
    for name in names:
        score = max(_ratio(word, name), _ratio(bare, _bare(name)))
        if score >= 0.6:  # difflib's cutoff, as `suggest`
            scored.append((score, name))
    close = [name for _, name in heapq.nlargest(MAX_SUGGESTED, scored)]  # ties as difflib orders them
    return f" (did you mean {', '.join(repr(c) for c in close)}?)" if close else ""


def _ratio(a: str, b: str) -> float:
    matcher = difflib.SequenceMatcher(None, a, b)
    # the cheap upper bounds first, as difflib.get_close_matches: most names are far off
    if matcher.real_quick_ratio() < 0.6 or matcher.quick_ratio() < 0.6:
        return 0.0
    return matcher.ratio()


def plural(n: int, noun: str) -> str:
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def type_name(value: Any) -> str:
    if isinstance(value, bool):
        return f"boolean {str(value).lower()}"
    if isinstance(value, str):
        return f"string {value!r}"
    if isinstance(value, (int, float)):
        return f"number {value!r}"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, dict):
        return "a table"
    return type(value).__name__


def is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)
