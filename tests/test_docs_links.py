"""Messages point at the documentation by URL (`logscan.docs.doc_url`), never by a path in the
checkout: an installed logscan ships no docs/, README.md or bench/."""

from __future__ import annotations

import ast
import re
from pathlib import Path

from logscan.docs import DOCS_URL, doc_url

ROOT = Path(__file__).resolve().parents[1]
CHECKOUT_PATH = re.compile(r"(?<![\w/.])(docs/|bench/|README\b)")


def runtime_strings(source: str) -> list[tuple[int, str]]:
    """(line, text) of the string constants a module can show a user: every string but the
    docstrings of modules, classes and functions (a click command's docstring is its --help, so it
    counts)."""
    tree = ast.parse(source)
    docstrings = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef) and node.body:
            first = node.body[0]
            is_command = any("command" in ast.unparse(d) for d in getattr(node, "decorator_list", []))
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and not is_command:
                docstrings.add(id(first.value))
    return [
        (node.lineno, node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings
    ]


SOURCES = sorted(p for folder in ("logscan", "detectors") for p in (ROOT / folder).rglob("*.py"))


def checkout_paths(path: Path) -> list[str]:
    strings = runtime_strings(path.read_text(encoding="utf-8"))
    text = [(line, s.replace(DOCS_URL, "")) for line, s in strings]
    return [f"{path.relative_to(ROOT)}:{line}: {s[:80]!r}" for line, s in text if CHECKOUT_PATH.search(s)]


def test_no_message_names_a_path_of_the_checkout():
    bad = [hit for path in SOURCES for hit in checkout_paths(path)]
    templates = [p for p in (ROOT / "templates").iterdir() if p.is_file() and p.suffix != ".py"]
    bad += [p.name for p in templates if CHECKOUT_PATH.search(p.read_text(encoding="utf-8").replace(DOCS_URL, ""))]
    assert not bad, "use logscan.docs.doc_url(page) instead:\n" + "\n".join(bad)


def test_the_finder_sees_messages_and_help_but_not_docstrings_or_urls():
    source = '''
"""Module docstring: docs/algorithms.md."""
import click

def f():
    """docs/x.md"""
    raise ValueError("see docs/profiles.md")

@click.command()
def cmd():
    """Help text; README.md has more."""

URL = "https://github.com/logscan/logscan/blob/main/docs/cli.md"
'''
    found = [(line, CHECKOUT_PATH.search(s.replace(DOCS_URL, "")) is not None) for line, s in runtime_strings(source)]
    assert sorted(line for line, hit in found if hit) == [7, 11]


def test_every_page_a_message_links_to_is_in_the_docs_folder():
    pages = {m for path in SOURCES for m in re.findall(r"doc_url\(['\"]([^'\"]+)['\"]\)", path.read_text("utf-8"))}
    assert {"profiles.md", "algorithms.md"} <= pages, pages
    missing = [page for page in pages if not (ROOT / "docs" / page).exists()]
    assert not missing, missing
    assert doc_url("cli.md") == "https://github.com/logscan/logscan/blob/main/docs/cli.md"
