"""Regenerate docs/cli.md, the command-line reference, from the click commands' own help.

Every command's usage, description, options (with their defaults, choices and ranges, as
`logscan COMMAND --help` shows them) and examples are taken from the commands themselves, so the
page says what the installed logscan accepts; tests/test_docs_cli.py regenerates it and fails
when the file differs.

    .venv/bin/python docs/make_cli_md.py          # rewrite docs/cli.md
    .venv/bin/python docs/make_cli_md.py --check  # exit 1 when docs/cli.md is out of date
"""

from __future__ import annotations

import argparse
import inspect
import re
import sys
from pathlib import Path

import click

from logscan.cli.main import cli

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "cli.md"
COMMAND = "python docs/make_cli_md.py"

HEADER = f"""# Command-line reference

Generated from the commands' own `--help` by `{COMMAND}`; do not edit by hand
(tests/test_docs_cli.py fails when this page and the help differ). What the commands are for, with
examples on the sample logs: [the README](../README.md) and the pages it links. Exit codes:
[ci.md](ci.md#exit-codes).
"""


def escape(text: str) -> str:
    """Markdown-safe text: `<`, `*` and `|` outside backtick spans are escaped."""
    parts = re.split(r"(`[^`]*`)", text)
    for i in range(0, len(parts), 2):
        parts[i] = re.sub(r"([<*|])", r"\\\1", parts[i])
    return "".join(parts)


def paragraphs(text: str) -> list[str]:
    """A help text's paragraphs, each on one line (click wraps them itself on the terminal)."""
    text = inspect.cleandoc(text).split("\f", 1)[0]
    return [" ".join(block.split()) for block in re.split(r"\n\s*\n", text) if block.strip()]


def examples(epilog: str | None) -> list[str]:
    """The command lines of an `Examples:` epilog."""
    if not epilog:
        return []
    return [line.strip() for line in epilog.splitlines() if line.strip().startswith("logscan ")]


def options_table(command: click.Command, ctx: click.Context) -> list[str]:
    rows = ["| option | meaning |", "|---|---|"]
    for param in command.get_params(ctx):
        record = param.get_help_record(ctx) if isinstance(param, click.Option) else None
        if record is None or getattr(param, "hidden", False):
            continue
        names, meaning = record
        cells = (f"`{names}`", escape(" ".join(meaning.split())))
        rows.append("| " + " | ".join(re.sub(r"(?<!\\)\|", r"\\|", cell) for cell in cells) + " |")
    return rows


def command_section(name: str, command: click.Command, parent: click.Context) -> list[str]:
    ctx = click.Context(command, info_name=name, parent=parent, **command.context_settings)
    usage = " ".join(["logscan", name, *command.collect_usage_pieces(ctx)])
    lines = [f"## logscan {name}", "", "```text", f"Usage: {usage}", "```", ""]
    for paragraph in paragraphs(command.help or ""):
        lines += [escape(paragraph), ""]
    lines += options_table(command, ctx) + [""]
    if examples(command.epilog):
        lines += ["Examples:", "", "```sh", *examples(command.epilog), "```", ""]
    return lines


def render() -> str:
    root = click.Context(cli, info_name="logscan", **cli.context_settings)
    names = cli.list_commands(root)
    lines = [HEADER, "## logscan", "", "```text", "Usage: logscan [OPTIONS] COMMAND [ARGS]...", "```", ""]
    lines += [escape(p) for p in paragraphs(cli.help or "")] + [""]
    lines += options_table(cli, root) + [""]
    lines += ["Commands: " + ", ".join(f"[`{n}`](#logscan-{n})" for n in names) + ".", ""]
    for name in names:
        lines += command_section(name, cli.get_command(root, name), root)
    return "\n".join(lines).rstrip("\n") + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only compare; exit 1 when docs/cli.md differs")
    text = render()
    if parser.parse_args().check:
        if PAGE.read_text(encoding="utf-8") != text:
            sys.exit(f"docs/cli.md is out of date: run `{COMMAND}`")
        return
    PAGE.write_text(text, encoding="utf-8")
    print(f"{PAGE.relative_to(ROOT)}: {text.count(chr(10))} lines")


if __name__ == "__main__":
    main()
