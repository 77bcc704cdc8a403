"""Regenerate the report screenshots in docs/images/ (shown by README.md and docs/reading-the-report.md).

Analyses two shipped sample logs with the installed logscan, renders each report in headless
Chromium at 1400 x 1800 px and writes ``docs/images/report_<log>.png``: the top of the report, as
a reader first sees it. With Pillow installed the PNGs are reduced to 256 colours (a few hundred
kilobytes each).

    .venv/bin/python docs/make_screenshots.py [--chromium PATH]
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
IMAGES = ROOT / "docs" / "images"
LOGS = ["quad_imu_bias", "quad_healthy"]
WINDOW = "1400,1800"


def find_chromium(given: str | None) -> str:
    for name in [given] if given else ["chromium", "chromium-browser", "google-chrome", "chrome"]:
        path = shutil.which(name)
        if path:
            return path
    sys.exit("make_screenshots: no Chromium found; give its path with --chromium")


def render(log: str, workdir: Path) -> Path:
    """The report of sample_logs/<log>.mcap, plotly.js beside it in ``workdir``."""
    html = workdir / f"{log}.html"
    command = [sys.executable, "-m", "logscan", "analyze", f"sample_logs/{log}.mcap"]  # shown as given
    command += ["-o", str(html), "--plotlyjs", str(workdir), "--exit-zero", "--quiet"]
    subprocess.run(command, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    return html


def screenshot(chromium: str, html: Path, png: Path) -> None:
    command = [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars"]
    command += [f"--window-size={WINDOW}", f"--screenshot={png}", html.as_uri()]
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120)
    if not png.is_file():
        sys.exit(f"make_screenshots: Chromium wrote no {png}")


def shrink(png: Path) -> None:
    """256 colours (the report is flat colours and thin lines: nothing visible is lost)."""
    try:
        from PIL import Image
    except ImportError:
        return
    with Image.open(png) as image:
        small = image.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT)
    small.save(png, optimize=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--chromium", help="path of the Chromium (or Chrome) binary")
    chromium = find_chromium(parser.parse_args().chromium)
    IMAGES.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for log in LOGS:
            png = IMAGES / f"report_{log}.png"
            screenshot(chromium, render(log, Path(tmp)), png)
            shrink(png)
            print(f"{png.relative_to(ROOT)}: {png.stat().st_size // 1024} KB")


if __name__ == "__main__":
    main()
