"""Options shared by logscan's commands, defined once and reused by every command."""

from __future__ import annotations

import sys

import click


def _tables_file(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    """Read --tables before any log (exit 2 on a file that is not tables JSON)."""
    if value is not None:
        from logscan.training.tables import read_tables

        read_tables(value)
    return value


tables_option = click.option(
    "--tables",
    "tables_path",
    type=click.Path(dir_okay=False, path_type=str),
    default=None,
    callback=_tables_file,
    help="Trained tables written by `logscan train` for this profile. Default: the profile's `tables` key.",
)


def _detector_names(ctx: click.Context, param: click.Parameter, value: tuple[str, ...]) -> tuple[str, ...]:
    """Every --detector name known to the registry, before any profile or log is read (exit 2:
    "unknown detector 'nsi' (did you mean 'nis'? available: ...)")."""
    if value:
        from logscan.detectors.registry import default_registry

        registry = default_registry()
        for name in value:
            registry.get(name)
    return value


def complete_detectors(ctx: click.Context, param: click.Parameter, incomplete: str) -> list[str]:
    """Shell completion of detector names (built-in and plugins)."""
    from logscan.detectors.registry import default_registry

    return [name for name in default_registry().names() if name.startswith(incomplete)]


def detector_option(help_text: str):
    """-d/--detector NAME (repeatable), checked against the registry and completed by the shell."""
    return click.option(
        "--detector",
        "-d",
        "detector_names",
        multiple=True,
        metavar="NAME",
        callback=_detector_names,
        shell_complete=complete_detectors,
        help=help_text,
    )


profile_option = click.option(
    "--profile",
    "-p",
    "profile_path",
    type=click.Path(dir_okay=False, path_type=str),
    default=None,
    help="Profile (TOML) mapping log channels to a model and detectors. Default: the profile embedded in the log.",
)


def _output_target(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    """Refuse, before any work, an output that is a socket or a block device (exit 2); a FIFO or
    a character device such as /dev/null is written into (`logscan.artifacts.check_target`)."""
    if value is not None and value != "-":
        from logscan.artifacts import check_target

        check_target(value)
    return value


json_option = click.option(
    "--json",
    "json_path",
    type=click.Path(dir_okay=False, path_type=str),
    default=None,
    callback=_output_target,
    help="Write a machine-readable JSON summary to this file ('-' for stdout; a FIFO or a device "
    "such as /dev/null is written into, never replaced).",
)

output_option = click.option(
    "--output",
    "-o",
    "output_path",
    type=click.Path(dir_okay=False, path_type=str),
    default=None,
    help="Output file.",
)

header_stamp_option = click.option(
    "--header-stamp/--log-time",
    "use_header_stamp",
    default=False,
    show_default=True,
    help="Time MCAP messages by their header.stamp where present instead of log_time.",
)

quiet_option = click.option("--quiet", "-q", is_flag=True, default=False, help="No progress output on stderr.")

seed_option = click.option(
    "--seed", type=int, default=0, show_default=True, help="Random seed (same seed, same bytes)."
)

jobs_option = click.option(
    "--jobs",
    "-j",
    type=click.IntRange(min=1),
    default=1,
    show_default=True,
    help="Number of logs processed in parallel (local processes).",
)


def _scheduler_address(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    """Refuse, before any work, a malformed address or a missing dask extra (exit 2)."""
    if value is not None:
        from logscan.fleet import check_scheduler

        check_scheduler(value)
    return value


scheduler_option = click.option(
    "--scheduler",
    "scheduler",
    metavar="ADDRESS",
    default=None,
    callback=_scheduler_address,
    help="Process the logs on a Dask cluster: tcp://HOST:8786 (a running scheduler; its workers must see "
    "the logs and outputs at the same paths) or local:N (N local worker processes for this run). "
    "Same results as --jobs 1; needs the dask extra (pip install 'logscan[dask]').",
)


def check_parallelism(jobs: int, scheduler: str | None) -> None:
    """--scheduler and --jobs N > 1 are two ways to run logs in parallel: one at a time."""
    if scheduler is not None and jobs > 1:
        from logscan.errors import UsageError

        raise UsageError(f"--scheduler and --jobs {jobs} exclude each other: give one of them")


def window_options(verb: str, each: str, example: str):
    """--start/--end (seconds since a log's start) as ``verb`` uses them; a decorator for both."""
    start = click.option(
        "--start", "start_s", type=float, default=None,
        help=f"{verb} {each} from this time, in seconds since its start ({example}). Default: the log's start.",
    )  # fmt: skip
    end = click.option(
        "--end", "end_s", type=float, default=None,
        help=f"{verb} {each} up to this time, in seconds since its start. Default: the log's end.",
    )  # fmt: skip
    return lambda command: start(end(command))


window_option = window_options("Analyse", "the log", "e.g. to leave out a clock jump")


def show_progress(quiet: bool) -> bool:
    """Progress goes to stderr only when it is a terminal and --quiet is off."""
    return not quiet and sys.stderr.isatty()


def echo_notice(message: str) -> None:
    """A one-off note for the user (e.g. the first run's compile), on stderr."""
    click.echo(f"logscan: {message}", err=True)
