"""`logscan init-profile`: write the profile a log gets (embedded, or built-in) as TOML to edit."""

from __future__ import annotations

from pathlib import Path

import click

from logscan.errors import UsageError


@click.command(
    "init-profile",
    epilog="Examples:\n\n  logscan init-profile flight.ulg -o px4.toml\n\n"
    "  logscan analyze flight.ulg --profile px4.toml",
)
@click.argument("log_path", metavar="LOG", type=click.Path(exists=True, dir_okay=False, path_type=str))
@click.option(
    "-o",
    "--output",
    "output_path",
    type=click.Path(dir_okay=False, path_type=str),
    default=None,
    help="Write the profile to this file (default: print it). An existing file is never replaced.",
)
def init_profile(log_path: str, output_path: str | None) -> None:
    """Write the profile `logscan analyze LOG` would use without --profile: the one the log embeds
    (logs of `logscan simulate`), else the built-in profile it gets (a PX4 ULog: `px4`, built from
    the topics it holds, with comments saying where each value comes from). Edit it and pass it
    with --profile; the documentation's profiles.md describes every key."""
    from logscan.pipeline import load_profile_for

    loaded = load_profile_for(log_path, None)
    text = loaded.text.rstrip("\n") + "\n"
    if loaded.notes:
        text = "".join(f"# {note}\n" for note in loaded.notes) + text
    if output_path is None:
        click.echo(text, nl=False)
        return
    target = Path(output_path)
    if target.exists():
        raise UsageError(f"{output_path} exists: init-profile never replaces a file", hint="choose another -o")
    from logscan.artifacts import write_atomic

    write_atomic(output_path, text)
    click.echo(f"{output_path}: profile ({loaded.source}) for {log_path}", err=True)
