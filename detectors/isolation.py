"""Plugin detectors' `fit` and `run` isolated from the analysis: nothing a plugin does can end or
corrupt the run of logscan.

Where ``fork`` exists (Linux, macOS), each call runs in a forked child process (the run, trace and
model are inherited, not copied up front; only the result comes back, pickled): ``os._exit``, a
segfault, an abort or an exhausted memory limit in plugin code end that child only, and the
analysis reports the detector as failed ("ended its process"), its other detectors' results kept.
In the child, file descriptor 1 is pointed at stderr, so whatever the plugin prints (Python's
``print``, C code writing to stdout) never reaches stdout, which may hold ``--json -``. The child
ignores Ctrl-C (the parent is interrupted and ends it) and ends with its parent
(`logscan.child_processes`). What `fit` learns (the detector's attributes) comes back with it.

Without ``fork`` the call runs in-process: stdout (Python's and file descriptor 1) goes to stderr
while it runs, and SystemExit or a KeyboardInterrupt the plugin raises itself become its failure;
``os._exit`` or a crash cannot be contained there.

Built-in detectors run in-process, unchanged (`Detector.plugin_origin` is None for them; the
registry sets it on every plugin class it loads).
"""

from __future__ import annotations

import contextlib
import os
import pickle
import signal
import sys
from collections.abc import Callable, Iterator
from typing import Any

from logscan.child_processes import exit_with_parent
from logscan.errors import InternalError


def call_isolated(detector: Any, method: str, call: Callable[[], Any]) -> Any:
    """``call()`` (the detector's unisolated ``method``, "fit" or "run") isolated as the module
    docstring says; its value, or its exception re-raised here; InternalError when the plugin
    ended its process or raised SystemExit/KeyboardInterrupt."""
    if hasattr(os, "fork") and sys.platform != "win32":
        return _in_child(detector, method, call)
    return _in_process(detector, method, call)


def _blame(detector: Any, method: str, what: str) -> InternalError:
    # the pipeline's failure line names the detector and its origin already
    return InternalError(
        f"{what} in {method}",
        hint="a bug in the plugin: report it to its authors, or remove the detector from the profile",
    )


def _in_child(detector: Any, method: str, call: Callable[[], Any]) -> Any:
    import multiprocessing

    context = multiprocessing.get_context("fork")
    reader, writer = context.Pipe(duplex=False)
    parent = os.getpid()

    def child() -> None:
        reader.close()
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and ends this child

        exit_with_parent(parent)
        _stdout_to_stderr()
        try:
            value = call()
            payload: tuple = ("value", value, detector.__dict__ if method == "fit" else None)
        except BaseException as exc:  # noqa: BLE001 - reported by the parent
            payload = ("raised", exc if _picklable(exc) else None, f"{type(exc).__name__}: {exc}")
        try:
            writer.send(payload)
        except Exception as exc:  # noqa: BLE001 - a result that cannot be pickled
            writer.send(("raised", None, f"its result cannot be sent back ({type(exc).__name__}: {exc})"))
        finally:
            sys.stderr.flush()
            os._exit(0)

    process = context.Process(target=child, name=f"logscan-plugin-{detector.name}", daemon=True)
    try:
        process.start()
        writer.close()
        try:
            payload = reader.recv()
        except EOFError:  # the child ended without a word: os._exit, a signal, a crash
            payload = None
        process.join()
    except BaseException:  # Ctrl-C or an error here: the child must not outlive the call
        if process.is_alive():
            process.kill()
        process.join()
        raise
    finally:
        reader.close()
    if payload is None:
        code = process.exitcode
        what = (
            f"was killed by signal {-code} ({_signal_name(-code)})"
            if code is not None and code < 0
            else f"ended its process (exit code {code})"
        )
        raise _blame(detector, method, what)
    if payload[0] == "value":
        if method == "fit":  # what it learnt, on the detector itself (fit returns self)
            detector.__dict__.update(payload[2])
            return detector
        return payload[1]
    exc, text = payload[1], payload[2]
    if isinstance(exc, Exception):
        raise exc
    raise _blame(detector, method, f"raised {text}")


def _in_process(detector: Any, method: str, call: Callable[[], Any]) -> Any:
    with _stdout_redirected():
        try:
            return call()
        except (SystemExit, GeneratorExit) as exc:
            raise _blame(detector, method, f"raised {type(exc).__name__}: {exc}") from None


def _picklable(exc: BaseException) -> bool:
    try:
        pickle.loads(pickle.dumps(exc))
    except Exception:  # noqa: BLE001 - any reason: sent as text
        return False
    return True


def _signal_name(number: int) -> str:
    try:
        return signal.Signals(number).name
    except ValueError:
        return "unknown"


def _stdout_to_stderr() -> None:
    """In the child: file descriptor 1 and Python's stdout lead to stderr for good."""
    with contextlib.suppress(OSError, ValueError, AttributeError):
        sys.stdout.flush()
    with contextlib.suppress(OSError):
        os.dup2(2, 1)
    sys.stdout = sys.stderr


@contextlib.contextmanager
def _stdout_redirected() -> Iterator[None]:
    """Python's stdout and file descriptor 1 lead to stderr inside the block."""
    with contextlib.suppress(OSError, ValueError, AttributeError):
        sys.stdout.flush()
    saved = None
    with contextlib.suppress(OSError):
        saved = os.dup(1)
        os.dup2(2, 1)
    try:
        with contextlib.redirect_stdout(sys.stderr):
            yield
    finally:
        if saved is not None:
            with contextlib.suppress(OSError, ValueError, AttributeError):
                sys.stderr.flush()
            os.dup2(saved, 1)
            os.close(saved)
