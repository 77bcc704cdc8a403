"""docs/cli.md is the commands' own help: regenerated here and compared, so it cannot drift; and
every `logscan COMMAND --option` the docs pages show exists in that command's help."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import click
import pytest

from logscan.cli.main import cli

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
FENCE = re.compile(r"^```([\w-]*)[^\n]*\n(.*?)^```[ \t]*$", re.S | re.M)


def load_generator():
    spec = importlib.util.spec_from_file_location("make_cli_md", DOCS / "make_cli_md.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


GENERATOR = load_generator()


def test_cli_md_is_what_the_commands_help_generates():
    page = (DOCS / "cli.md").read_text(encoding="utf-8")
    assert page == GENERATOR.render(), f"docs/cli.md differs from the commands' help: run `{GENERATOR.COMMAND}`"


def test_every_command_and_each_of_its_options_has_its_row():
    """The page has a section per command, and each section a row per option of its --help."""
    page = (DOCS / "cli.md").read_text(encoding="utf-8")
    ctx = click.Context(cli)
    commands = cli.list_commands(ctx)
    assert set(re.findall(r"^## logscan ([a-z-]+)$", page, re.M)) == set(commands)
    for name in commands:
        section = page.split(f"\n## logscan {name}\n", 1)[1].split("\n## ", 1)[0]
        for param in cli.get_command(ctx, name).params:
            if isinstance(param, click.Option) and not param.hidden:
                longest = max(param.opts, key=len)
                assert re.search(rf"^\| `[^`]*{re.escape(longest)}\b", section, re.M), f"`logscan {name}`: {longest}"


def test_check_mode_names_the_command_that_regenerates_the_page(tmp_path, monkeypatch):
    stale = tmp_path / "cli.md"
    stale.write_text("# out of date\n", encoding="utf-8")
    monkeypatch.setattr(GENERATOR, "PAGE", stale)
    monkeypatch.setattr("sys.argv", ["make_cli_md.py", "--check"])
    with pytest.raises(SystemExit) as stopped:
        GENERATOR.main()
    assert "python docs/make_cli_md.py" in str(stopped.value.code)


def test_markdown_escaping_keeps_code_spans_and_table_cells_intact():
    assert GENERATOR.escape("<log>.json a|b `x|<y>`") == r"\<log>.json a\|b `x|<y>`"
    assert GENERATOR.paragraphs("One\n    line.\n\n    Two.\f hidden") == ["One line.", "Two."]


def doc_invocations(text: str) -> list[list[str]]:
    """Every `logscan ...` command line in a markdown page's code blocks, split into words."""
    lines = []
    for language, block in FENCE.findall(text):
        if language not in ("sh", "console", "bash", "yaml", ""):
            continue
        for line in block.replace("\\\n", " ").splitlines():
            if language == "console" and not line.startswith("$ "):
                continue  # a console block's other lines are output
            line = re.sub(r"(^|\s)#.*", "", line)  # a shell comment
            for part in re.split(r"&&|\||;", line):
                words = part.split()
                for i, word in enumerate(words):
                    if word.endswith("logscan") and not word.startswith(("-", "logscan.")):
                        lines.append(words[i + 1 :])
                        break
    return lines


def unknown_options(text: str) -> list[str]:
    ctx = click.Context(cli)
    problems = []
    for words in doc_invocations(text):
        words = [w for w in words if w != "--debug"]
        if not words or words[0].startswith("-"):
            continue
        command = cli.get_command(ctx, words[0])
        if command is None:
            problems.append(f"unknown command: logscan {' '.join(words)}")
            continue
        known = {opt for param in command.params for opt in (*param.opts, *param.secondary_opts)} | {"--help"}
        options = [word for word in words[1:] if word.startswith("--")]
        problems += [f"logscan {words[0]} {word}" for word in options if word.split("=")[0] not in known]
    return problems


PAGES = [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]


@pytest.mark.parametrize("page", PAGES, ids=[p.name for p in PAGES])
def test_options_the_readme_and_docs_show_exist_in_the_commands_help(page):
    assert unknown_options(page.read_text(encoding="utf-8")) == []


def test_unknown_options_are_found():
    text = "```sh\nlogscan analyze x.mcap --no-such-option  # --not-an-option in a comment\nlogscan frobnicate\n```\n"
    assert unknown_options(text) == ["logscan analyze --no-such-option", "unknown command: logscan frobnicate"]
