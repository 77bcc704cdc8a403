"""logscan: offline model-based fault and attack detection for drone and ground-vehicle logs."""

from __future__ import annotations

import os
import signal
import sys
import tempfile
import threading
from pathlib import Path

__version__ = "0.2.0"


def cache_dir() -> Path:
    """logscan's per-user cache directory: $LOGSCAN_CACHE_DIR, else the platform's user cache
    (~/.cache/logscan or $XDG_CACHE_HOME/logscan, ~/Library/Caches/logscan, %LOCALAPPDATA%\\logscan)."""
    given = os.environ.get("LOGSCAN_CACHE_DIR")
    if given:
        return Path(given).expanduser()
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local")
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Caches"
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "logscan"


def _numba_cache_dir() -> str:
    """Where numba keeps the compiled kernels: <cache_dir>/numba, never beside the sources.

    Beside the sources (numba's default) the cache lands in site-packages, survives `pip
    uninstall` and the leftover folder then shadows a later editable install as a namespace
    package; in a checkout it dirties the tree. An explicit NUMBA_CACHE_DIR is kept unless
    LOGSCAN_CACHE_DIR is set; an unwritable directory falls back to the system temp directory.
    """
    if os.environ.get("NUMBA_CACHE_DIR") and not os.environ.get("LOGSCAN_CACHE_DIR"):
        return os.environ["NUMBA_CACHE_DIR"]
    for candidate in (cache_dir() / "numba", Path(tempfile.gettempdir()) / f"logscan-{_user()}" / "numba"):
        if writable_directory(candidate):
            return str(candidate)
    return str(cache_dir() / "numba")  # numba itself then says it cannot cache


def writable_directory(directory: Path) -> bool:
    """Whether ``directory`` exists (created with its parents when missing) and can be written."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError:
        return False
    return os.access(directory, os.W_OK)


def _user() -> str:
    try:
        return str(os.getuid())
    except AttributeError:  # Windows
        return os.environ.get("USERNAME", "user")


os.environ["NUMBA_CACHE_DIR"] = _numba_cache_dir()
if "numba" in sys.modules:  # imported before logscan: numba read its config already
    sys.modules["numba"].config.CACHE_DIR = os.environ["NUMBA_CACHE_DIR"]

# Run from a source checkout without an installed copy (e.g. `python -m logscan` in the checkout
# root, where the working directory shadows any install), the subpackages that live at the top
# level of the checkout (pyproject.toml maps detectors/ and templates/ to logscan.detectors and
# logscan.templates) are found through the package path.
_checkout = Path(__file__).resolve().parent.parent
if not (Path(__file__).resolve().parent / "detectors").is_dir() and (_checkout / "detectors" / "__init__.py").is_file():
    __path__.append(str(_checkout))  # noqa: F821 - the package's own __path__


def interrupted_while_loading(signum, frame) -> None:
    """Ctrl-C while the `logscan` command loads its modules, before `logscan.cli.main.main`
    installs its handler: nothing is written yet, so the run ends at once with exit 130 and one
    line, not Python's KeyboardInterrupt traceback and a death by SIGINT."""
    try:
        sys.stderr.write("logscan: interrupted\n")
        sys.stderr.flush()
    finally:
        os._exit(130)


def _run_as_the_command() -> bool:
    """Whether this process is the `logscan` command: its script, or `python -m logscan` (while
    the package imports, ``sys.argv[0]`` is still "-m"; ``sys.orig_argv`` names the module)."""
    name = os.path.basename(sys.argv[0]) if sys.argv else ""
    if name in ("logscan", "logscan.exe"):
        return True
    original = list(getattr(sys, "orig_argv", []))
    return any(a == "-m" and b == "logscan" for a, b in zip(original, original[1:]))


# only in the command's own process (a library user's or a test's Ctrl-C stays theirs)
if (
    _run_as_the_command()
    and threading.current_thread() is threading.main_thread()
    and signal.getsignal(signal.SIGINT) is signal.default_int_handler
):
    signal.signal(signal.SIGINT, interrupted_while_loading)
