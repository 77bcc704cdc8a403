"""The README's quick start and its pointers agree with the CLI, the docs and CI (the options it
shows: tests/test_docs_cli.py)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import click
import pytest

from logscan.cli.main import cli

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def quick_start_commands() -> list[str]:
    section = README.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    block = re.search(r"```sh\n(.*?)```", section, re.S).group(1)
    return [line for line in block.splitlines() if line.strip()]


def readme_invocations() -> list[list[str]]:
    """Every `logscan ...` command line in the README's code blocks, split into words."""
    lines = []
    for block in re.findall(r"```(?:sh|console|bash)?\n(.*?)```", README, re.S):
        for line in block.splitlines():
            for part in re.split(r"&&|\|", line):
                words = part.split()
                for i, word in enumerate(words):
                    if word.endswith("logscan") and not word.startswith("-"):
                        lines.append(words[i + 1 :])
                        break
    return lines


def test_quick_start_has_exactly_two_commands_install_run_and_test():
    commands = quick_start_commands()
    assert len(commands) == 2, commands
    run_cmd, test_cmd = commands
    assert "pip install ." in run_cmd and "sample_logs/" in run_cmd
    assert "pytest" in test_cmd and "pip install -e '.[test]'" in test_cmd


def test_ci_runs_the_readme_test_command():
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    pattern = re.search(r"grep -m1 -E '([^']+)' README.md", ci).group(1)
    matches = [line for line in README.splitlines() if re.search(pattern, line)]
    assert matches and matches[0] == quick_start_commands()[1]


def test_the_readme_is_short_and_opens_with_the_quick_start():
    """A newcomer's page (under 250 lines) whose first commands are the quick start's two lines."""
    assert len(README.splitlines()) < 250, len(README.splitlines())
    first_block = re.search(r"```(?:sh|console|bash)?\n(.*?)```", README, re.S).group(1)
    assert [line for line in first_block.splitlines() if line.strip()] == quick_start_commands()


def test_every_command_is_in_the_readme_table_and_every_listed_command_exists():
    ctx = click.Context(cli)
    commands = set(cli.list_commands(ctx))
    listed = set(re.findall(r"^\| \[`logscan ([a-z-]+)[^`]*`\]\(docs/cli\.md#logscan-\1\)", README, re.M))
    assert commands == listed


def test_the_output_the_readme_shows_is_the_one_reading_the_report_runs():
    """The README's example summary lines are those docs/reading-the-report.md shows under the same
    command, which tests/test_docs_examples.py runs and compares with the real output."""
    shown = re.search(r"```text\n(.*?)```", README, re.S).group(1).splitlines()
    page = (ROOT / "docs" / "reading-the-report.md").read_text(encoding="utf-8")
    assert shown and all(line in page for line in shown), shown


def test_the_readme_links_every_docs_page_and_each_link_resolves():
    links = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", README)
    assert [target for target in links if "://" not in target and not (ROOT / target).exists()] == []
    pages = {p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").glob("*.md")}
    assert pages <= set(links), f"docs pages the README does not link: {sorted(pages - set(links))}"


def _copy_of_the_checkout(dest: Path) -> None:
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout.split(b"\0")
    for rel in filter(None, files):
        src = ROOT / rel.decode()
        if src.is_file():
            target = dest / rel.decode()
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, target)


@pytest.mark.slow
def test_quick_start_lines_one_after_the_other_in_one_copy(tmp_path):
    """The README's two lines verbatim, one after the other in one copy of the tracked files (a
    regular install, then an editable one over it), leave a working `logscan` and `python -m
    logscan` in and outside the checkout, and no compiled-kernel cache in the copy or the venv; the
    editable install runs on the kernels the regular one compiled (the same sources).

    Line 2's pytest run is narrowed with PYTEST_ADDOPTS (the line itself is unchanged) to two tests
    and the two files that hold them, so that it neither runs the whole suite, this test included, a
    second time nor collects it (20-30 s of CPU)."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("needs a git checkout to copy the tracked files")
    copy = tmp_path / "checkout"
    _copy_of_the_checkout(copy)
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHONPATH", "NUMBA_CACHE_DIR")}
    env["PATH"] = os.pathsep.join(
        p for p in env.get("PATH", "").split(os.pathsep) if ".venv" not in p and "/venv/" not in p
    )
    env["LOGSCAN_CACHE_DIR"] = str(tmp_path / "user-cache")
    env["PYTEST_ADDOPTS"] = (
        "-p no:cacheprovider tests/test_cli_errors.py tests/test_readme.py"
        " -k 'test_version or test_quick_start_has_exactly_two_commands'"
    )

    def shell(command: str, cwd: Path = copy) -> subprocess.CompletedProcess:
        command = command.replace("python3 ", f"{sys.executable} ", 1)
        return subprocess.run(["bash", "-c", command], cwd=cwd, env=env, capture_output=True, text=True, timeout=900)

    run_line, test_line = quick_start_commands()
    first = shell(run_line)
    assert first.returncode == 1, first.stderr[-3000:]  # the sample has an injected fault: alarms
    assert "Traceback" not in first.stderr
    assert "incident 1: accelerometer" in first.stdout
    assert "compiling numerical kernels" in first.stderr
    # a regular install, run from the checkout root (its logscan/ folder shadows the install)
    from_root = shell(".venv/bin/python -m logscan detectors")
    assert from_root.returncode == 0 and "nis" in from_root.stdout, from_root.stderr[-2000:]

    second = shell(test_line)
    assert second.returncode == 0, (second.stdout[-3000:], second.stderr[-3000:])
    assert " passed" in second.stdout

    for args, cwd in (("logscan --version", copy), ("python -m logscan --version", copy)):
        result = shell(f".venv/bin/{args}", cwd)
        assert result.returncode == 0 and result.stdout.startswith("logscan "), (args, result.stderr[-2000:])
    elsewhere = shell(f"{copy}/.venv/bin/python -m logscan --version", tmp_path)
    assert elsewhere.returncode == 0, elsewhere.stderr[-2000:]
    again = shell(".venv/bin/logscan analyze sample_logs/quad_imu_bias.mcap --no-report")
    assert again.returncode == 1 and "incident 1: accelerometer" in again.stdout, again.stderr[-3000:]
    # the editable install's sources are the regular one's: it loads the kernels line 1 compiled
    assert "compiling numerical kernels" not in again.stderr, again.stderr[-3000:]

    leftovers = [str(p) for p in copy.rglob("*.nb[ic]")]
    assert leftovers == [], leftovers[:5]
    assert list((tmp_path / "user-cache" / "numba").rglob("*.nbi")), "the kernels were cached elsewhere"
