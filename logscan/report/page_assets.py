"""What every logscan page loads besides its figures: plotly.js (inside the page, or one shared
copy in a directory the page links to), the jinja2 environment of ``templates/`` and the analysis
report's own script ``templates/report.js``."""

from __future__ import annotations

import functools
import os
import urllib.parse
from pathlib import Path

import logscan.templates
from logscan.artifacts import Staged, commit, stage
from logscan.errors import InputError

PLOTLY_JS_NAME = "plotly.min.js"


def script_safe(js: str) -> str:
    """``js`` safe inside an inline <script>: "</script" would end it early; "<\\/" is the same string in JS."""
    return js.replace("</script", "<\\/script").replace("</SCRIPT", "<\\/SCRIPT")


def plotly_js() -> str:
    """plotly.js, safe inside an inline <script>."""
    from plotly.offline import get_plotlyjs

    return script_safe(get_plotlyjs())


def plotly_js_target(directory: str | os.PathLike) -> Path:
    """Where ``--plotlyjs DIR`` puts plotly.js (the directory is created; InputError when it cannot be)."""
    directory = Path(directory)
    if directory.exists() and not directory.is_dir():
        raise InputError("--plotlyjs must be a directory", path=str(directory), hint="give a directory path or 'embed'")
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the plotly.js directory: {exc.strerror}", path=str(directory)) from None
    return directory / PLOTLY_JS_NAME


@functools.lru_cache(maxsize=1)
def _plotly_js_bytes() -> bytes:
    """plotly.min.js as it is written beside the reports, read and encoded once per process (4.6
    MB: 15 ms of every report of a run, which each check that the copy there is still it)."""
    from plotly.offline import get_plotlyjs

    return get_plotlyjs().encode("utf-8")


def stage_plotly_js(directory: str | os.PathLike, token: str = "") -> Staged | None:
    """plotly.min.js staged into ``directory`` (`logscan.artifacts.stage`); None when the file
    there already holds it."""
    payload = _plotly_js_bytes()
    target = plotly_js_target(directory)
    if target.is_file() and target.stat().st_size == len(payload) and target.read_bytes() == payload:
        return None
    return stage(target, payload, token=token)


def plotly_js_src(directory: Path, page_path: Path) -> str:
    """The URL of plotly.min.js in ``directory``, relative to the page."""
    relative = os.path.relpath((directory / PLOTLY_JS_NAME).resolve(), page_path.resolve().parent)
    return urllib.parse.quote(Path(relative).as_posix())


def install_plotly_js(directory: Path, page_path: Path) -> str:
    """Write plotly.min.js into ``directory`` (if absent or different); its URL relative to the page."""
    staged = stage_plotly_js(directory)
    if staged is not None:
        commit([staged])
    return plotly_js_src(directory, page_path)


@functools.lru_cache(maxsize=1)
def environment():
    """The jinja2 environment of ``templates/``: autoescaping on (names come from untrusted logs)."""
    import jinja2

    return jinja2.Environment(
        loader=jinja2.FileSystemLoader(Path(logscan.templates.__file__).parent),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        bytecode_cache=_compiled_templates(jinja2),
    )


def _compiled_templates(jinja2):
    """The templates compiled once per machine, not once per process (0.1-0.2 s of every report):
    jinja2's bytecode cache in logscan's cache directory, keyed on each template's source (an edited
    template compiles again); None (no cache) where that directory cannot be written."""
    directory = logscan.cache_dir() / "templates"
    return jinja2.FileSystemBytecodeCache(str(directory)) if logscan.writable_directory(directory) else None


def report_js() -> str:
    """templates/report.js (the report page's interactions), "" when absent; safe inside a <script>."""
    path = Path(logscan.templates.__file__).parent / "report.js"
    return script_safe(path.read_text(encoding="utf-8") if path.is_file() else "")
