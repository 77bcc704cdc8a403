"""Options shared by logscan's commands, defined once and reused by every command."""

from __future__ import annotations

import os
import sys

import click


class GroupedCommand(click.Command):
    """A command whose --help lists its options in titled groups (click has none): each option
    carries its group's title in ``help_group`` (set by `help_groups`); the untagged ones, --help
    among them, come last under "Other options"."""

    def format_options(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        groups: dict[str, list[tuple[str, str]]] = {}
        for param in self.get_params(ctx):
            record = param.get_help_record(ctx) if isinstance(param, click.Option) else None
            if record is not None:
                groups.setdefault(getattr(param, "help_group", "Other options"), []).append(record)
        order = getattr(self, "help_group_order", ())
        titles = sorted(groups, key=lambda t: (t == "Other options", order.index(t) if t in order else len(order)))
        for title, rows in ((t, groups[t]) for t in titles):
            if rows:
                with formatter.section(title):
                    formatter.write_dl(rows)


def help_groups(groups: dict[str, tuple[str, ...]]):
    """Decorator above a `GroupedCommand`'s @click.command: ``{title: (parameter names)}``, in the
    order --help shows them; a name that is no parameter of the command is a bug (ValueError)."""

    def tag(command: click.Command) -> click.Command:
        params = {param.name: param for param in command.params}
        for title, names in groups.items():
            for name in names:
                if name not in params:
                    raise ValueError(f"{command.name}: no parameter {name!r} for help group {title!r}")
                params[name].help_group = title  # type: ignore[attr-defined]
        command.help_group_order = tuple(groups)  # type: ignore[attr-defined]
        return command

    return tag


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


def plotlyjs_option(help_text: str):
    """--plotlyjs DIR|embed (analyze, train, evaluate): plotly.js once in DIR, linked from the pages,
    or inside each page (`logscan.report.plotly_script`)."""
    return click.option(
        "--plotlyjs",
        "plotlyjs_dir",
        type=click.Path(file_okay=False, path_type=str),
        default=None,
        metavar="DIR|embed",
        help=help_text,
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


def check_profile(profile_path: str | None, detector_names: tuple[str, ...] | None) -> None:
    """One --profile for every log: it and its detectors' settings checked once, before any log is
    read (exit 2), not once per log."""
    if profile_path is not None:
        from logscan.pipeline import create_detectors, load_profile_for

        create_detectors(load_profile_for(None, profile_path), detector_names)


def window_options(verb: str, each: str, example: str):
    """--start/--end (seconds since a log's start) as ``verb`` uses them; a decorator for both."""
    start = click.option(
        "--start", "start_s", type=float, default=None,
        help=f"{verb} {each} from this time, in seconds since its start ({example}); the filter is "
        "started from up to 240 s of the log before it, not judged there. Default: the log's start.",
    )  # fmt: skip
    end = click.option(
        "--end", "end_s", type=float, default=None,
        help=f"{verb} {each} up to this time, in seconds since its start. Default: the log's end.",
    )  # fmt: skip
    return lambda command: start(end(command))


window_option = window_options("Analyse", "the log", "e.g. to leave out a clock jump")
block_option = click.option(
    "--block-s",
    "block_s",
    type=click.FloatRange(min=0),
    default=None,
    metavar="SECONDS",
    help="Analyse a long log in consecutive equal windows of at most this many seconds, each "
    "freed once its alarms, counts and the report's series are kept, so memory is bounded by the block, "
    "not the log; 0: never. Default: in blocks of at most 180,000 grid steps (30 min at 100 Hz) when the "
    "log holds more "
    "than 269,683 (44.9 min at 100 Hz: the longest whose analysis at once stays within 450 MB). An indexed "
    "MCAP log reads each block alone; a ULog or ROS bag its built-in profile reads whole is held once and "
    "cut into blocks; a log analysed with --profile that is not an indexed MCAP is analysed at once (a "
    "warning says so).",
)


def show_progress(quiet: bool) -> bool:
    """Progress goes to stderr only when it is a terminal, --quiet is off and no CI runs us
    (CI=true, as GitHub Actions, GitLab CI and most CI servers set it)."""
    in_ci = os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")
    return not quiet and not in_ci and sys.stderr.isatty()


def echo_notice(message: str) -> None:
    """A one-off note for the user (e.g. the first run's compile), on stderr, on a line of its own
    (a step line being drawn is erased first: `logscan.cli.progress`)."""
    from logscan.cli.progress import clear_step_line

    clear_step_line()
    click.echo(f"logscan: {message}", err=True)
