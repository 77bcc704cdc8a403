"""docs/csv-logs.md runs as written: from a folder of wide-CSV flights to a trained, tuned starter
profile that finds the injected faults without false alarms on healthy flights.

The page's ```sh blocks are its commands (each line starting with `logscan `, run in order through
the CLI in a folder holding the simulated flights of tests/csv_flights.py); the ```text block
after a ```sh block shows excerpts of its last command's output: each line must appear in that
output, in order, any number standing for any number (the figures are the page's run; `...` skips
lines). Then the page's claims: at least 80 % of the injected faults found within 2 s of their
onset, at most 5 false alarms per flight-hour on the healthy flights the training did not see.
"""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import pytest
from click.testing import CliRunner
from csv_flights import FLIGHTS, TRAIN, write_flights

from logscan.cli.main import cli
from logscan.profiles import load_profile

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "csv-logs.md"
FENCE = re.compile(r"^```([\w-]*)[^\n]*\n(.*?)^```[ \t]*$", re.S | re.M)
NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")
DURATION_S = 300.0
DETECT_WITHIN_S = 2.0
MAX_FALSE_PER_HOUR = 5.0


def page_steps() -> list[tuple[list[str], list[str]]]:
    """(commands of a ```sh block, output lines of the ```text block after it, or [])."""
    blocks = [(m.group(1), m.group(2)) for m in FENCE.finditer(PAGE.read_text(encoding="utf-8"))]
    steps = []
    for i, (language, body) in enumerate(blocks):
        if language != "sh":
            continue
        commands = [line.split(" #")[0].strip() for line in body.splitlines() if line.startswith("logscan ")]
        shown = blocks[i + 1][1].splitlines() if i + 1 < len(blocks) and blocks[i + 1][0] == "text" else []
        steps.append((commands, shown))
    return steps


def shape(line: str) -> str:
    """The line with numbers as `#` and whitespace collapsed."""
    return " ".join(NUMBER.sub("#", line).split())


def check_shown(command: str, shown: list[str], output: str) -> None:
    actual = [shape(line) for line in output.splitlines()]
    position = 0
    for line in shown:
        wanted = shape(line)
        if wanted in ("...", ""):
            continue
        for index in range(position, len(actual)):
            if wanted in actual[index]:
                position = index + 1
                break
        else:
            pytest.fail(f"`{command}` did not print {line.strip()!r} (in order); it printed:\n{output}")


def scores(summary: dict) -> tuple[int, int, int, float]:
    """(faults, found within DETECT_WITHIN_S of onset, false alarms on unseen healthy flights, their hours)."""
    by_name = {Path(log["file"]).stem: log for log in summary["logs"]}
    faults = found = false = 0
    hours = 0.0
    for name, _, injected in FLIGHTS:
        if name in TRAIN:
            continue
        alarms = [a for d in by_name[name]["detectors"] for a in d["alarms"]]
        for _, _, onset, _, _ in injected:
            faults += 1
            found += any(onset <= a["start"] <= onset + DETECT_WITHIN_S for a in alarms)
        if not injected:
            false += len(alarms)
            hours += DURATION_S / 3600.0
    return faults, found, false, hours


def test_the_page_runs_and_its_starter_profile_finds_the_faults(tmp_path, monkeypatch):
    write_flights(tmp_path / "flights", DURATION_S)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("COLUMNS", "100")
    steps = page_steps()
    commands = [c for cs, _ in steps for c in cs]
    assert any(c.startswith("logscan init-profile") for c in commands), commands
    assert any("--calibrate" in c and "--tune" in c for c in commands), commands
    assert any(c.startswith("logscan analyze") and "--tables" in c for c in commands), commands
    runner = CliRunner()
    for block, shown in steps:
        for command in block:
            done = runner.invoke(cli, shlex.split(command)[1:], catch_exceptions=False)
            assert done.exit_code in (0, 1), f"`{command}` exited {done.exit_code}:\n{done.output}"
        check_shown(block[-1], shown, done.output)
    profile = load_profile(tmp_path / "plane.toml")
    assert profile.vehicle.model == "linear"
    assert {g.fresh for g in profile.measurements.values()} == {"on_sample", "on_change"}
    faults, found, false, hours = scores(json.loads((tmp_path / "new.json").read_text(encoding="utf-8")))
    assert found >= 0.8 * faults, f"{found} of {faults} faults found within {DETECT_WITHIN_S} s"
    assert false / hours <= MAX_FALSE_PER_HOUR, f"{false} false alarms in {hours:.2f} h of healthy flights"
