"""`logscan init-profile`: write the profile a log gets (embedded, or built-in) as TOML to edit;
a CSV log that has neither gets a starter profile (`logscan.profiles.starter`)."""

from __future__ import annotations

from pathlib import Path

import click

from logscan.errors import InputError, ProfileError, UsageError


@click.command(
    "init-profile",
    short_help="Write the profile a log gets (embedded, built-in or a starter) as TOML to edit.",
    epilog="Examples:\n\n  logscan init-profile flight.ulg -o px4.toml\n\n"
    "  logscan analyze flight.ulg --profile px4.toml\n\n"
    "  logscan init-profile flights/flight_1.csv -o plane.toml",
)
@click.argument("log_path", metavar="LOG", type=click.Path(exists=True, path_type=str))
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
    the topics it holds, with comments saying where each value comes from). A CSV log (a wide file,
    or a folder of per-topic CSVs) with neither gets a starter profile: one mean-reverting state
    per numeric column, its noise read from the column itself, the columns left out listed with
    why. Edit it and pass it with --profile; the documentation's profiles.md describes every key,
    csv-logs.md the starter."""
    from logscan.pipeline import load_profile_for

    try:
        loaded = load_profile_for(log_path, None)
        text, notes, source = loaded.text, loaded.notes, loaded.source
    except InputError as error:
        incomplete = getattr(error, "profile_text", None)  # a built-in profile the log cannot complete
        if incomplete is None:
            raise
        text, notes, source = incomplete, [], "built-in, incomplete"
        click.echo(f"logscan: warning: {log_path}: {error.message}: complete the profile it writes", err=True)
    except ProfileError:
        built = _starter(log_path)
        if built is None:
            raise
        text, notes, source = built.text, built.notes, "starter"
    text = text.rstrip("\n") + "\n"
    if notes and source.startswith("built-in "):
        text = _notes_key(notes) + text
    elif notes and source != "embedded":  # an embedded profile's are in its text
        text = "".join(f"# {note}\n" for note in notes) + text
    if output_path is None:
        click.echo(text, nl=False)
        return
    target = Path(output_path)
    if target.exists():
        raise UsageError(f"{output_path} exists: init-profile never replaces a file", hint="choose another -o")
    from logscan.artifacts import write_atomic

    write_atomic(output_path, text)
    click.echo(f"{output_path}: profile ({source}) for {log_path}", err=True)


def _notes_key(notes: list[str]) -> str:
    """A built-in profile's notes as the profile's ``notes``: analysing with the file says them as
    analysing without it does (what the profile left out: an altitude not checked, a missing GNSS)."""
    from logscan.profiles.toml_writer import dumps_toml

    why = "# what the built-in profile left out or chose: analyze says each as a warning (drop one no longer true)\n"
    return why + dumps_toml({"notes": list(notes)})


def _starter(log_path: str):
    """The starter profile (`logscan.profiles.starter.StarterProfile`) of a CSV log, or an MCAP of
    numeric channels, that embeds no profile and gets no built-in one, else None; an InputError when
    no channel can be a state."""
    from logscan.docs import doc_url
    from logscan.profiles.starter import STARTER_FORMATS, starter_profile
    from logscan.readers import detect_format, read_embedded_profile, read_log

    if detect_format(log_path) not in STARTER_FORMATS or read_embedded_profile(log_path):
        return None
    log = read_log(log_path)
    if not log.channels:
        raise InputError(
            "the log holds no numeric channel: there is nothing a profile could check",
            path=log_path,
            hint="`logscan inspect LOG` lists its topics and why their fields were skipped",
        )
    built = starter_profile(log)
    if not built.kept:
        why = "; ".join(f"{name}: {reason}" for name, reason in built.dropped[:6])
        raise InputError(
            f"no column varies enough to be a state ({why})",
            path=log_path,
            hint=f"a starter profile needs numeric columns that change; write one by hand ({doc_url('profiles.md')})",
        )
    return built
