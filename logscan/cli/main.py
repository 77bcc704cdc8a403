"""The `logscan` command group and the one place where errors become messages and exit codes."""

from __future__ import annotations

import contextlib
import errno
import inspect
import os
import re
import signal
import sys
import threading
import traceback
import warnings
from contextlib import contextmanager

import click

from logscan import __version__, interrupted_while_loading
from logscan.cli.render import printable
from logscan.errors import INTERRUPT_SEEN, OUT_OF_MEMORY, ExitCode, LogscanError


class _CommandList(click.Group):
    """The top-level group: its --help lists each command with the whole first sentence of its
    help, wrapped (click cuts it to the width left, with "..."); a command whose stdout or stderr
    reader left (`| head`) ends with exit 2, an output not written (click's own answer is exit 1,
    which says "alarms")."""

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except BrokenPipeError:
            raise click.exceptions.Exit(ExitCode.BAD_INPUT) from None

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = []
        for name in self.list_commands(ctx):
            command = self.get_command(ctx, name)
            if command is not None and not command.hidden:
                rows.append((name, command.short_help or _first_sentence(command.help or "")))
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)


def _first_sentence(help_text: str) -> str:
    paragraph = " ".join(inspect.cleandoc(help_text).split("\f", 1)[0].split("\n\n", 1)[0].split())
    match = re.match(r"(.+?\.)(?:\s|$)", paragraph)
    return match.group(1) if match else paragraph


@click.group(
    cls=_CommandList,
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
    "logscan.cli.train_cmd:train",
    "logscan.cli.profile_cmd:init_profile",
]


def _register_commands() -> None:
    import importlib

    for spec in _COMMANDS:
        module_name, attr = spec.split(":")
        cli.add_command(getattr(importlib.import_module(module_name), attr))


_register_commands()


class Interrupted(BaseException):
    """Ctrl-C (SIGINT), raised by logscan's handler instead of KeyboardInterrupt, which click would
    turn into its Abort; like KeyboardInterrupt no ``except Exception`` catches it, so every
    ``finally`` and cleanup on the way runs (temporary files removed, worker processes stopped)."""


# OSErrors that say the environment is wrong (exit 2), not logscan: permissions, a read-only or full
# file system, quotas, size limits, missing or unusable paths, too many open files, no memory
_ENVIRONMENT_ERRNOS = frozenset(
    getattr(errno, name)
    for name in ("EACCES", "EPERM", "EROFS", "ENOSPC", "EDQUOT", "EFBIG", "ENOENT", "ENOTDIR", "EISDIR",
                 "ENAMETOOLONG", "ELOOP", "EIO", "EMFILE", "ENFILE", "ENOMEM", "EBUSY", "ETXTBSY", "EXDEV")
    if hasattr(errno, name)
)  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    """Console-script entry point: run the CLI and map every outcome to an exit code."""
    args = sys.argv[1:] if argv is None else list(argv)
    debug = "--debug" in args
    previous = _install_signal_handlers()
    code: int = ExitCode.INTERNAL
    try:
        with _warnings_as_lines(debug):
            code = _run(args, debug)
    except BrokenPipeError:  # a line `_run` wrote outside its handlers (they keep their code, `_say`)
        code = ExitCode.BAD_INPUT
    finally:
        if argv is None and previous.pop(signal.SIGINT, None) is not None:
            # the process's own run: Ctrl-C stays logscan's until the process ends
            signal.signal(signal.SIGINT, _interrupted_at_exit)
        if argv is None and code == ExitCode.INTERRUPTED:
            # and so does the finalizers' quiet (`_unraisable`, the flag kept): one the
            # interruption left half-done may fail as the process ends
            previous.pop("unraisablehook", None)
            _INTERRUPT_SEEN[0] = True
        _restore_signal_handlers(previous)
    if argv is None:
        _exit_process(int(code))
    sys.exit(code)


def _exit_process(code: int) -> None:
    """End the `logscan` process with ``code``: exit handlers run, streams flushed, then
    ``os._exit``. A Ctrl-C until then (the work done, Python tearing down its modules) still gives
    exit 130 and one line (`_interrupted_at_exit`): after Python's own shutdown has begun it would
    kill the process by SIGINT, with no line."""
    import atexit

    try:
        shutdown = getattr(threading, "_shutdown", None)  # what Python's own exit does first:
        if shutdown is not None and threading.current_thread() is threading.main_thread():
            shutdown()  # join the non-daemon threads, run the threads' exit hooks
        atexit._run_exitfuncs()
        _flush_streams()
    finally:
        os._exit(code)


def _interrupted_at_exit(signum, frame) -> None:
    _flush_streams()
    try:
        sys.stderr.write(_interrupted_line() + "\n")
        sys.stderr.flush()
    except (OSError, ValueError):
        pass
    os._exit(ExitCode.INTERRUPTED)


def _flush_streams() -> None:
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):
            pass


def _run(args: list[str], debug: bool) -> int:
    """Run the CLI; the exit code of every outcome, with its one line on stderr."""
    try:
        try:
            code = cli.main(args=args, prog_name="logscan", standalone_mode=False)
        except SystemExit as exc:  # a command's own code (`sys.exit`, as CliRunner reads it): the
            # process still ends by `_exit_process`, not by Python's teardown (0.2-0.35 s after a long log)
            code = ExitCode.OK if exc.code is None else exc.code
            if not isinstance(code, int):  # ``sys.exit("why")`` (a library's): its words said, as Python
                _say(f"logscan: error: {printable(str(code))}")  # would, but exit 3: Python's 1 reads as alarms
                code = ExitCode.INTERNAL
        if _INTERRUPT_SEEN[0]:  # a Ctrl-C whose exception a finalizer swallowed: still Ctrl-C
            return _interrupted()
    except (Interrupted, KeyboardInterrupt):
        return _interrupted()
    except click.exceptions.Abort as exc:
        if isinstance(exc.__context__, (Interrupted, KeyboardInterrupt)):
            return _interrupted()
        _say("logscan: aborted")
        return ExitCode.BAD_INPUT
    except click.ClickException as exc:
        with contextlib.suppress(BrokenPipeError):
            exc.show()
        return ExitCode.BAD_INPUT
    except click.exceptions.Exit as exc:
        return exc.exit_code
    except LogscanError as exc:
        if debug:
            traceback.print_exc()
        _say(f"logscan: error: {printable(exc.one_line())}")
        return exc.exit_code
    except BrokenPipeError:  # the reader of stdout or stderr left (`| head`): an output not written
        return ExitCode.BAD_INPUT
    except MemoryError:  # anywhere in a command: the log is too big for this machine, not a bug
        if debug:
            traceback.print_exc()
        _say(f"logscan: error: {OUT_OF_MEMORY}")
        return ExitCode.BAD_INPUT
    except OSError as exc:
        if debug:
            traceback.print_exc()
        if not _is_environment_error(exc):
            return _internal_error(exc)
        _say(f"logscan: error: {printable(_os_error_line(exc))}")
        return ExitCode.BAD_INPUT
    except Exception as exc:  # noqa: BLE001 - the one place internal errors are mapped
        if _INTERRUPT_SEEN[0]:
            # Ctrl-C landed inside a C callback (numba's compiler calling back into Python): the
            # interruption was swallowed there and surfaced as this error; it is still Ctrl-C
            return _interrupted()
        if debug:
            traceback.print_exc()
        return _internal_error(exc)
    return int(code) if isinstance(code, int) else ExitCode.OK


@contextmanager
def _warnings_as_lines(debug: bool):
    """Python warnings printed as one line of logscan's own, instead of Python's file:line and
    source line (with --debug: as Python prints them). Worker processes (--jobs, forked) inherit
    it. Not a filter: every warning still shows, once per place as Python's default filter has it.
    logscan handles the numeric edge cases it knows where they arise (numpy's and scipy's
    "overflow encountered in ..."); one that still shows here means a result there may be inf or
    NaN, and is worth reporting."""
    if debug:
        yield
        return
    with warnings.catch_warnings():
        warnings.showwarning = _show_warning
        yield


_NUMERIC = re.compile(r"(overflow|underflow|invalid value|divide by zero) encountered")


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """``warnings.showwarning`` as one line: "logscan: warning: numeric problem in
    detectors/nis.py line 104: overflow encountered in cast (a result there may be inf or NaN)".
    A warning from a library names logscan's line that called it, then the library's file."""
    text = printable(str(message))
    where = f"{_source_name(filename)} line {lineno}"
    caller = _logscan_caller()
    if caller is not None and os.path.abspath(filename or "?") != caller[0]:
        where = f"{_source_name(caller[0])} line {caller[1]} ({_source_name(filename)})"
    if issubclass(category, RuntimeWarning) and _NUMERIC.match(text):
        out = f"logscan: warning: numeric problem in {where}: {text} (a result there may be inf or NaN)"
    else:
        out = f"logscan: warning: {category.__name__} in {where}: {text}"
    stream = file if file is not None else sys.stderr
    try:
        stream.write(out + "\n")
        stream.flush()
    except (OSError, ValueError, AttributeError):
        pass  # stderr closed or gone: a warning is not worth an error


def _logscan_caller() -> tuple[str, int] | None:
    """(file, line) of the innermost frame of logscan's own code (its package or its built-in
    detectors) on the stack of a warning, this module's frames aside; None when there is none."""
    roots = [os.path.dirname(os.path.dirname(os.path.abspath(__file__)))]
    detectors = sys.modules.get("logscan.detectors")
    if detectors is not None and getattr(detectors, "__file__", None):
        roots.append(os.path.dirname(os.path.abspath(detectors.__file__)))
    this = os.path.abspath(__file__)
    frame = sys._getframe(1)
    while frame is not None:
        name = os.path.abspath(frame.f_code.co_filename)
        if name != this and any(name.startswith(root + os.sep) for root in roots):
            return name, frame.f_lineno
        frame = frame.f_back
    return None


def _source_name(filename: str) -> str:
    """A warning's file, short: from the package directory on for a library
    (scipy/linalg/_matfuncs.py), from logscan's source tree for its own modules (detectors/nis.py)."""
    path = os.path.abspath(filename or "?")
    marker = f"{os.sep}site-packages{os.sep}"
    if marker in path:
        return path.rsplit(marker, 1)[1]
    tree = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    try:
        if os.path.commonpath([tree, path]) == tree:
            return os.path.relpath(path, tree)
    except ValueError:
        pass
    return os.path.basename(path)


def _interrupted() -> int:
    _say(_interrupted_line())
    return ExitCode.INTERRUPTED


def _say(line: str) -> None:
    """An outcome's line on stderr; a reader of stderr that left (`| head`) keeps the outcome's
    exit code (an internal error's 3, Ctrl-C's 130), not a broken pipe's."""
    with contextlib.suppress(BrokenPipeError):
        click.echo(line, err=True)


def _interrupted_line() -> str:
    """The interruption's line; on a terminal on a line of its own (a progress bar may hold the
    current one, without its newline)."""
    try:
        on_terminal = sys.stderr.isatty()
    except (AttributeError, ValueError):
        on_terminal = False
    return ("\n" if on_terminal else "") + "logscan: interrupted"


def _internal_error(exc: BaseException) -> int:
    _say(
        f"logscan: internal error: {type(exc).__name__}: {printable(exc)} "
        "(this is a bug in logscan; rerun with --debug for the traceback and report it)"
    )
    return ExitCode.INTERNAL


def _is_environment_error(exc: OSError) -> bool:
    """An OSError the user's environment causes: a known errno, on a file outside logscan's own
    installation (a template or module of logscan that cannot be read is a broken install: a bug)."""
    if exc.errno not in _ENVIRONMENT_ERRNOS:
        return False
    if exc.filename is None:
        return exc.errno in (errno.ENOSPC, errno.EMFILE, errno.ENFILE, errno.ENOMEM, errno.EDQUOT)
    package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    try:
        return os.path.commonpath([package, os.path.abspath(os.fsdecode(exc.filename))]) != package
    except (TypeError, ValueError):
        return True


def _os_error_line(exc: OSError) -> str:
    from logscan.artifacts import describe_os_error

    what, hint = describe_os_error(exc)
    where = f"{os.fsdecode(exc.filename)}: " if exc.filename is not None else ""
    return f"{where}{what} ({hint or 'check the path and the system, then rerun'})"


def _raise_interrupted(signum, frame) -> None:
    if os.getpid() != _OWNER[0]:
        # a forked child (the background compile) that kept this handler: end it quietly; the
        # parent reports the interruption
        os._exit(ExitCode.INTERRUPTED)
    _INTERRUPT_SEEN[0] = True
    raise Interrupted()


_OWNER = [0]  # the process whose Ctrl-C is reported
_INTERRUPT_SEEN = INTERRUPT_SEEN  # set by the handler: an error that follows it is the interruption


def _install_signal_handlers() -> dict:
    """Ctrl-C raises Interrupted (unless SIGINT is ignored, as for a background job), and
    exceeding the file-size limit (ulimit -f) is an EFBIG error on the write instead of a kill
    by SIGXFSZ that would leave a temporary file behind. Returns the handlers to restore."""
    previous = {}
    if threading.current_thread() is not threading.main_thread():
        return previous
    _OWNER[0] = os.getpid()
    _INTERRUPT_SEEN[0] = False
    if signal.getsignal(signal.SIGINT) in (signal.default_int_handler, interrupted_while_loading):
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, _raise_interrupted)
    if hasattr(signal, "SIGXFSZ"):
        previous[signal.SIGXFSZ] = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    previous["unraisablehook"] = _HOOK[0] = sys.unraisablehook
    sys.unraisablehook = _unraisable
    return previous


_HOOK = [sys.unraisablehook]  # the unraisable hook `_unraisable` passes everything else to


def _unraisable(unraisable) -> None:
    """Python's hook for an exception it cannot raise (one raised while a finalizer runs): a
    Ctrl-C there is not printed as a traceback; the handler's flag carries it (`_run`). Nor is any
    error of a finalizer after a Ctrl-C: the interruption may have left an object half-closed
    (llvmlite's ObjectRef.detach stopped between deleting its pointer and marking itself closed
    fails in its ``__del__`` with "AttributeError: ... '_as_parameter_'"), and the run ends with
    its one line and exit 130 (the process's own run: until the process ends, `main`)."""
    if _INTERRUPT_SEEN[0] or isinstance(unraisable.exc_value, (Interrupted, KeyboardInterrupt)):
        return
    _HOOK[0](unraisable)


def _restore_signal_handlers(previous: dict) -> None:
    hook = previous.pop("unraisablehook", None)
    if hook is not None:
        sys.unraisablehook = hook
    for signum, handler in previous.items():
        signal.signal(signum, handler)
    if hook is not None:  # the main thread's run is over: its Ctrl-C is reported
        _INTERRUPT_SEEN[0] = False


if __name__ == "__main__":
    main()
