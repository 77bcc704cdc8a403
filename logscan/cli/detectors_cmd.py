"""`logscan detectors`: list the registered detectors (built-in and plugins) and any that failed to load."""

from __future__ import annotations

import click

from logscan.cli.options import json_option


@click.command(
    epilog="Examples:\n\n"
    "  logscan detectors\n\n"
    "  logscan detectors --json -"
)
@json_option
def detectors(json_path: str | None) -> None:
    """List the detectors logscan can run: name, origin (built-in or plugin package), description.

    Plugins come from the 'logscan.detectors' entry-point group of installed packages. A plugin
    that fails to load is listed with its problem and skipped; it never stops the others.
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


def render_detectors(entries: list[dict]) -> str:
    """Plain-text table of registry entries (``DetectorEntry.to_dict()`` rows)."""
    if not entries:
        return "no detectors registered"
    rows = [(e["name"], e["origin"], e["description"] if e["ok"] else "BROKEN") for e in entries]
    name_w = max(len("name"), *(len(r[0]) for r in rows))
    origin_w = max(len("origin"), *(len(r[1]) for r in rows))
    lines = [f"{'name':<{name_w}}  {'origin':<{origin_w}}  description"]
    lines += [f"{n:<{name_w}}  {o:<{origin_w}}  {d}" for n, o, d in rows]
    problems = [(e["name"], e["origin"], p) for e in entries for p in e["problems"]]
    if problems:
        lines.append("")
        lines.append("problems:")
        lines += [f"  {n} ({o}): {p}" for n, o, p in problems]
    return "\n".join(lines)
