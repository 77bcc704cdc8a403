"""Where a message sends the user for more: the documentation pages' URLs (an installed logscan
ships no docs/ folder, so a message never names a path in the checkout)."""

from __future__ import annotations

#: docs/ of the project (pyproject.toml's Source URL), as the repository's web view shows it
DOCS_URL = "https://github.com/logscan/logscan/blob/main/docs/"


def doc_url(page: str) -> str:
    """The URL of ``page`` of docs/, e.g. ``doc_url("profiles.md")``."""
    return DOCS_URL + page
