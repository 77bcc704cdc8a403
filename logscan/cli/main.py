"""The `logscan` command group and the one place where errors become messages and exit codes."""

from __future__ import annotations

import os
import sys
import traceback

import click

from logscan import __version__
from logscan.errors import ExitCode, LogscanError


@click.group(
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
    epilog="Example: logscan analyze sample_logs/quad_imu_bias.mcap",
)
@click.option(
    "--version",
    is_flag=True,
    expose_value=False,
    is_eager=True,
    callback=lambda ctx, param, value: _print_version(ctx) if value else None,
    help="Show logscan's version, the versions of the libraries it computes with, and exit.",
)
@click.option("--debug", is_flag=True, default=False, help="Show tracebacks of errors.")
@click.pass_context
def cli(ctx: click.Context, debug: bool) -> None:
    """logscan: model-based fault and attack detection on drone and ground-vehicle logs."""
    ctx.ensure_object(dict)
    ctx.obj["debug"] = debug


# the libraries whose versions change results or speed: what a bug report needs
VERSION_PACKAGES = ("numpy", "scipy", "numba", "llvmlite", "pandas", "mcap", "plotly")


def _print_version(ctx: click.Context) -> None:
    import platform
    from importlib import metadata

    def version(name: str) -> str:
        try:
            return metadata.version(name)
        except metadata.PackageNotFoundError:
            return "not installed"

    click.echo(f"logscan {__version__} (Python {platform.python_version()}, {platform.system()} {platform.machine()})")
    click.echo(", ".join(f"{name} {version(name)}" for name in VERSION_PACKAGES))
    # set by `import logscan` (logscan/__init__.py): LOGSCAN_CACHE_DIR, NUMBA_CACHE_DIR or the user cache
    click.echo(f"compiled-kernel cache: {os.environ.get('NUMBA_CACHE_DIR', '?')}")
    ctx.exit(0)


# Each command lives in its own module of logscan.cli as "module:function"; one line per command.
_COMMANDS = [
    "logscan.cli.inspect_cmd:inspect",
    "logscan.cli.analyze_cmd:analyze",
    "logscan.cli.simulate_cmd:simulate",
    "logscan.cli.detectors_cmd:detectors",
    "logscan.cli.evaluate_cmd:evaluate",
]


def _register_commands() -> None:
    import importlib

    for spec in _COMMANDS:
        module_name, attr = spec.split(":")
        cli.add_command(getattr(importlib.import_module(module_name), attr))


_register_commands()


def main(argv: list[str] | None = None) -> None:
    """Console-script entry point: run the CLI and map every outcome to an exit code."""
    args = sys.argv[1:] if argv is None else list(argv)
    debug = "--debug" in args
    try:
        code = cli.main(args=args, prog_name="logscan", standalone_mode=False)
    except click.exceptions.Abort:
        click.echo("logscan: aborted", err=True)
        sys.exit(ExitCode.BAD_INPUT)
    except click.ClickException as exc:
        exc.show()
        sys.exit(ExitCode.BAD_INPUT)
    except click.exceptions.Exit as exc:
        sys.exit(exc.exit_code)
    except LogscanError as exc:
        if debug:
            traceback.print_exc()
        click.echo(f"logscan: error: {exc.one_line()}", err=True)
        sys.exit(exc.exit_code)
    except KeyboardInterrupt:
        click.echo("logscan: interrupted", err=True)
        sys.exit(ExitCode.INTERRUPTED)
    except BrokenPipeError:
        sys.exit(ExitCode.OK)
    except Exception as exc:  # noqa: BLE001 - the one place internal errors are mapped
        if debug:
            traceback.print_exc()
        click.echo(
            f"logscan: internal error: {type(exc).__name__}: {exc} "
            "(this is a bug in logscan; rerun with --debug for the traceback and report it)",
            err=True,
        )
        sys.exit(ExitCode.INTERNAL)
    sys.exit(int(code) if isinstance(code, int) else ExitCode.OK)


if __name__ == "__main__":
    main()
