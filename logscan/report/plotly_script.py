"""plotly.js for one page (the training report, the evaluation page): inside it, or one shared copy
in a directory the page links to (``--plotlyjs DIR`` of `logscan train` and `logscan evaluate`; the
analysis reports do the same through `logscan.report.page.stage_report`)."""

from __future__ import annotations

import os
from pathlib import Path

from logscan.artifacts import Staged
from logscan.report.page_assets import plotly_js_src, stage_plotly_js

EMBED = "embed"  # --plotlyjs embed: plotly.js inside the page


def shared_directory(plotlyjs: str | None) -> str | None:
    """The directory of ``--plotlyjs``; None for ``embed`` or not given (plotly.js inside the page)."""
    return None if plotlyjs in (None, EMBED) else plotlyjs


def shared_plotly_js(
    page_path: str | os.PathLike, plotlyjs: str | None, token: str
) -> tuple[str | None, Staged | None]:
    """For ``--plotlyjs DIR``: the page's relative URL of DIR/plotly.min.js and that file staged
    (None when DIR already holds it: `stage_plotly_js`); (None, None) to embed plotly.js."""
    directory = shared_directory(plotlyjs)
    if directory is None:
        return None, None
    staged = stage_plotly_js(directory, token)
    return plotly_js_src(Path(directory), Path(page_path)), staged
