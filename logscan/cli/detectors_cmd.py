"""`logscan detectors`: list the registered detectors (built-in and plugins) and any that failed to load."""

from __future__ import annotations

import click

from logscan.cli.options import json_option
from logscan.cli.render import render_detectors


@click.command(
    short_help="List the detectors logscan can run, with their parameters.",
    epilog="Examples:\n\n  logscan detectors\n\n  logscan detectors --json -",
)
@json_option
def detectors(json_path: str | None) -> None:
    """List the detectors logscan can run: name, origin (built-in or plugin package), description,
    and each detector's parameters with their defaults and allowed types and ranges (checked when
    a profile is read, before any log).

    Plugins come from the 'logscan.detectors' entry-point group of installed packages. A plugin
    that fails to load (an import error, an exit or interrupt raised while importing, not a
    detector class, a name already taken) is listed with its problem and skipped; it never stops
    the others. What a plugin prints while loading goes to stderr, never into --json -.
    """
    from logscan.detectors.registry import default_registry

    registry = default_registry()
    entries = [entry.to_dict() for entry in registry.entries()]
    if json_path:
        from logscan.artifacts import write_json

        write_json(json_path, {"detectors": entries, "warnings": registry.warnings()})
        if json_path == "-":
            return
    click.echo(render_detectors(entries))
