"""Every example in docs/*.md runs on the shipped sample logs and prints what the page shows.

What the pages may contain, and how each is run (one temporary directory per page, holding a copy
of sample_logs/; a page's blocks run in order, so a later command sees the files an earlier one
wrote):

- ```console blocks: `$ command` lines (a line ending in `\\` continues on the next) are run with
  bash, `logscan` being `python -m logscan` of this checkout. The other lines are output the
  command must print (stdout and stderr together, as a terminal shows them): each must be
  contained, whitespace collapsed, in a line of the output, in the page's order (numbers may
  differ from the page's in their last digits, relative 1e-6); a `...` line stands for any lines.
  A command must exit 0, unless the next command is `echo $?`, whose output line is then the exit
  code it must have.
- ```toml blocks whose first line is `# profile NAME.toml for sample_logs/LOG`: written to NAME.toml
  where the page shows it (a later block of the same name replaces it); `logscan analyze LOG
  --profile NAME.toml` must accept it (exit 0 or 1, never a profile error). A ```toml block
  without that line fails the test, so no profile example goes unchecked.
- ```yaml blocks: GitHub Actions workflows; see tests/test_docs_ci.py.
- ```python blocks: docs/extending.md's are run by tests/test_extending.py, docs/algorithms.md's
  appendix script here (on two of the logs of its table).

Also checked here: the figures of bring-your-own-vehicle.md's mean-NIS table and NIS threshold,
the first-run note quoted by troubleshooting.md, and that every relative link of docs/ resolves.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from logscan.profiles import parse_profile

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
SAMPLES = ROOT / "sample_logs"
FENCE = re.compile(r"^```([\w-]*)[^\n]*\n(.*?)^```[ \t]*$", re.S | re.M)
PROFILE_MARKER = re.compile(r"^# profile (?P<name>[\w.-]+\.toml) for (?P<log>sample_logs/\S+)\s*$")


@dataclass
class Command:
    line: str
    expected: list[str] = field(default_factory=list)
    exit_code: int = 0
    where: str = ""


@dataclass
class Profile:
    name: str
    log: str
    text: str
    where: str


def fenced_blocks(path: Path) -> list[tuple[str, str, int]]:
    """(language, body, line number) of every fenced block of a markdown file."""
    text = path.read_text(encoding="utf-8")
    return [(m.group(1), m.group(2), text.count("\n", 0, m.start()) + 1) for m in FENCE.finditer(text)]


def console_commands(body: str, where: str) -> list[Command]:
    """The commands of one console block with the output lines shown under each."""
    commands: list[Command] = []
    lines = body.splitlines()
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("$ "):
            command = line[2:]
            while command.endswith("\\") and i + 1 < len(lines):
                i += 1
                command = command[:-1].rstrip() + " " + lines[i].strip()
            commands.append(Command(command.strip(), where=where))
        elif commands and line.strip():
            commands[-1].expected.append(line)
        i += 1
    runnable: list[Command] = []
    for command in commands:
        if command.line == "echo $?":
            assert runnable, f"{where}: `echo $?` without a command before it"
            runnable[-1].exit_code = int(command.expected[0].strip())
        else:
            runnable.append(command)
    return runnable


Example = Profile | Command


def page_examples(path: Path) -> list[Example]:
    """The page's profiles and commands, in the page's order."""
    examples: list[Example] = []
    for language, body, line in fenced_blocks(path):
        where = f"{path.relative_to(ROOT)}:{line}"
        if language == "console":
            examples.extend(console_commands(body, where))
        elif language == "toml":
            marker = PROFILE_MARKER.match(body.splitlines()[0] if body.strip() else "")
            if marker:
                examples.append(Profile(marker["name"], marker["log"], body, where))
    return examples


def unmarked_profiles() -> list[str]:
    """Where a ```toml block of docs/ lacks the line that says which sample log it is for."""
    return [
        f"{path.relative_to(ROOT)}:{line}"
        for path in sorted(DOCS.glob("*.md"))
        for language, body, line in fenced_blocks(path)
        if language == "toml" and not PROFILE_MARKER.match(body.splitlines()[0] if body.strip() else "")
    ]


PAGES = sorted(p for p in DOCS.glob("*.md") if page_examples(p))
NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")


def collapse(text: str) -> str:
    return " ".join(text.split())


def line_matches(wanted: str, actual: str) -> bool:
    """``wanted`` is in ``actual``; numbers may differ in their last digits (relative 1e-6), as
    floating point does between machines."""
    if wanted in actual:
        return True
    parts = NUMBER.split(wanted)
    pattern = "(" + NUMBER.pattern + ")"
    match = re.search(pattern.join(re.escape(part) for part in parts), actual)
    if match is None:
        return False
    shown = [float(n) for n in NUMBER.findall(wanted)]
    found = [float(n) for n in match.groups()]
    return all(abs(a - b) <= 1e-6 * max(abs(a), abs(b)) + 1e-12 for a, b in zip(shown, found, strict=True))


def check_output(command: Command, output: str) -> None:
    """Each shown line is in the output, in order; `...` skips any lines."""
    actual = [collapse(line) for line in output.splitlines()]
    position = 0
    for shown in command.expected:
        wanted = collapse(shown)
        if wanted == "...":
            continue
        for index in range(position, len(actual)):
            if line_matches(wanted, actual[index]):
                position = index + 1
                break
        else:
            where = f"{command.where}: `{command.line}`"
            pytest.fail(f"{where} did not print {shown.strip()!r} (in order); it printed:\n{output}")


@pytest.fixture(scope="module")
def shim(tmp_path_factory) -> dict:
    """An environment whose `logscan` is this checkout's `python -m logscan`."""
    bin_dir = tmp_path_factory.mktemp("bin")
    script = bin_dir / "logscan"
    script.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m logscan "$@"\n', encoding="utf-8")
    script.chmod(0o755)
    env = dict(os.environ)
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = str(ROOT)
    env["PYTHONUNBUFFERED"] = "1"  # stdout and stderr interleaved as on a terminal
    env["COLUMNS"] = "100"
    return env


def run(command: str, cwd: Path, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["bash", "-c", command],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        timeout=300,
    )


def test_every_toml_block_names_its_file_and_sample_log():
    assert not unmarked_profiles(), (
        "toml blocks that do not start with '# profile NAME.toml for sample_logs/LOG' (so they are not run): "
        + ", ".join(unmarked_profiles())
    )


def test_the_pages_have_examples_to_run():
    names = {p.name for p in PAGES}
    assert {"bring-your-own-vehicle.md", "troubleshooting.md", "evaluation.md"} <= names, names


@pytest.mark.parametrize("page", PAGES, ids=[p.name for p in PAGES])
def test_page_examples_run_on_the_sample_logs(page, tmp_path, shim):
    shutil.copytree(SAMPLES, tmp_path / "sample_logs", ignore=shutil.ignore_patterns("*.py", "__pycache__"))
    examples = page_examples(page)
    with ThreadPoolExecutor(max_workers=2) as pool:  # profiles checked beside the page's commands
        checks = []
        for index, example in enumerate(examples):
            if isinstance(example, Profile):
                parse_profile(example.text, source=example.where)
                (tmp_path / example.name).write_text(example.text, encoding="utf-8")
                later = " ".join(e.line for e in examples[index + 1 :] if isinstance(e, Command))
                if f"--profile {example.name}" not in later:  # else that command checks it
                    checks.append(pool.submit(check_profile, example, tmp_path, index, shim))
            else:
                check_command(example, tmp_path, shim)
        for check in checks:
            check.result()


def check_profile(profile: Profile, cwd: Path, index: int, env: dict) -> None:
    """`logscan analyze` accepts the profile on its sample log (in a folder of its own, so that a
    later block of the same name cannot replace it meanwhile)."""
    folder = cwd / f".profile-{index}"
    folder.mkdir()
    (folder / profile.name).write_text(profile.text, encoding="utf-8")
    done = run(f"logscan analyze ../{profile.log} --profile {profile.name} --no-report -q", folder, env)
    assert done.returncode in (0, 1), f"{profile.where}: {profile.name} on {profile.log}:\n{done.stdout}"


def check_command(command: Command, cwd: Path, env: dict) -> None:
    if re.search(r"(^|\|)\s*jq\b", command.line) and shutil.which("jq") is None:
        pytest.skip("jq is not installed")
    done = run(command.line, cwd, env)
    assert "Traceback" not in done.stdout, f"{command.where}: `{command.line}`:\n{done.stdout}"
    assert done.returncode == command.exit_code, (
        f"{command.where}: `{command.line}` exited {done.returncode}, the page says {command.exit_code}:\n{done.stdout}"
    )
    check_output(command, done.stdout)


def test_troubleshooting_quotes_the_first_run_note():
    from logscan.filters.warmup import COMPILING_NOTE

    assert f"logscan: {COMPILING_NOTE}" in (DOCS / "troubleshooting.md").read_text(encoding="utf-8")


def test_console_parser_reads_commands_output_and_exit_codes():
    body = "$ logscan analyze a \\\n    --no-report\nline 1\n...\nline 2\n$ echo $?\n1\n$ logscan inspect b\n"
    first, second = console_commands(body, "x")
    assert (first.line, first.expected, first.exit_code) == (
        "logscan analyze a --no-report",
        ["line 1", "...", "line 2"],
        1,
    )
    assert (second.line, second.expected, second.exit_code) == ("logscan inspect b", [], 0)


# ------------------------------------------------------------------------------------------------
# bring-your-own-vehicle.md: the table of mean NIS per group after one change to quad.toml
# ------------------------------------------------------------------------------------------------

BYOV = DOCS / "bring-your-own-vehicle.md"
ATTITUDE = '"/attitude/roll", "/attitude/pitch", "/attitude/yaw"'
CHANGES = {  # the table's first cell (its start) -> (text of the tuned quad.toml, replaced by)
    "none": ("", ""),
    "accel `noise_std = 0.01`": ("noise_std = 0.1 ", "noise_std = 0.01 "),
    "`params = { mass = 2.0 }`": ("rate_hz = 100\n\n[inputs]", "rate_hz = 100\nparams = { mass = 2.0 }\n\n[inputs]"),
    "roll and pitch channels swapped": (ATTITUDE, '"/attitude/pitch", "/attitude/roll", "/attitude/yaw"'),
    "attitude mapped to the on-board estimate": (ATTITUDE, '"/ekf/state/roll", "/ekf/state/pitch", "/ekf/state/yaw"'),
}


def byov_table() -> list[tuple[str, dict[str, str]]]:
    """(change, {group: mean NIS as written}) of each row of the page's mean-NIS table."""
    text = BYOV.read_text(encoding="utf-8")
    rows = []
    for line in text.split("| change | mean NIS per group |", 1)[1].splitlines()[2:]:
        if not line.startswith("|"):
            break
        change, values = (cell.strip() for cell in line.strip().strip("|").split("|"))
        rows.append((change, dict(re.findall(r"(\w+) ([\d,.]+)", values))))
    return rows


def test_the_mean_nis_table_has_a_known_change_per_row():
    rows = byov_table()
    assert len(rows) == len(CHANGES)
    assert all(any(change.startswith(key) for key in CHANGES) for change, _ in rows), rows


@pytest.mark.parametrize("key", list(CHANGES))
def test_mean_nis_table_row_is_measured(key, tmp_path):
    from logscan.pipeline import analyze_log

    profiles = [e for e in page_examples(BYOV) if isinstance(e, Profile) and e.name == "quad.toml"]
    tuned = profiles[-1].text
    old, new = CHANGES[key]
    assert old in tuned, f"quad.toml of the page no longer contains {old!r}"
    (tmp_path / "p.toml").write_text(tuned.replace(old, new, 1), encoding="utf-8")
    row = next(values for change, values in byov_table() if change.startswith(key))
    analysis = analyze_log(SAMPLES / "quad_healthy.mcap", profile_path=tmp_path / "p.toml", detector_names=["nis"])
    measured = analysis.summary()["filter"]["mean_nis"]
    for group, shown in row.items():
        value = float(shown.replace(",", ""))
        decimals = len(shown.split(".")[1]) if "." in shown else 0
        assert abs(measured[group] - value) <= 0.5 * 10**-decimals + 0.005 * value, (key, group, measured[group], shown)


def test_the_nis_threshold_figures_of_bring_your_own_vehicle():
    """'about 90 for 30 degrees of freedom', 'about once an hour' at 1.2 m, 'about 140' at 1.5 m:
    the NIS test's alpha on quad_healthy, windows of 10 updates of 3 outputs at 100 Hz."""
    from scipy.stats import chi2

    from logscan.pipeline import analyze_log

    text = collapse(BYOV.read_text(encoding="utf-8"))
    assert "about 90 for 30 degrees of freedom" in text
    assert "about once an hour, at 1.5 m about 140 times" in text
    analysis = analyze_log(SAMPLES / "quad_healthy.mcap", detector_names=["nis"])
    (nis,) = analysis.summary()["detectors"]
    threshold = chi2.ppf(1 - nis["info"]["alpha"], 30)
    assert round(threshold / 10) * 10 == 90
    per_hour = {k: chi2.sf(threshold / k, 30) * 100 * 3600 for k in (1.2, 1.5)}
    assert round(per_hour[1.2]) == 1 and round(per_hour[1.5], -1) == 140, per_hour


def test_every_relative_link_of_the_docs_resolves():
    broken = []
    for page in sorted(DOCS.glob("*.md")):
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", page.read_text(encoding="utf-8")):
            if "://" not in target and not (page.parent / target).exists():
                broken.append(f"{page.name}: {target}")
    assert not broken, broken


def test_the_appendix_script_of_algorithms_reproduces_its_table(tmp_path):
    """docs/algorithms.md's appendix script, run on two of the logs of its table, prints the
    table's figures for them."""
    text = (DOCS / "algorithms.md").read_text(encoding="utf-8")
    appendix = text.split("## Appendix: figures measured for this page", 1)[1]
    script = next(body for language, body, _ in fenced_blocks_of(appendix) if language == "python")
    (tmp_path / "figs.py").write_text(script, encoding="utf-8")
    logs = ("quad_healthy.mcap", "sbw_yaw_rate_bitflip.mcap")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, "figs.py", *(str(SAMPLES / name) for name in logs)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    printed = done.stdout.split(str(SAMPLES))[1:]
    for name, output in zip(logs, printed, strict=True):
        row = next(line for line in appendix.splitlines() if line.startswith(f"| `{name}`"))
        std, persist, nis, masked = (cell.strip() for cell in row.strip("|").split("|")[1:])
        persist, nis, masked = (re.findall(r"\d+", cell) for cell in (persist, nis, masked))
        assert f"std ratio paper/ours {std}" in output, (name, output)
        for n, count in zip((1, 2, 3), persist, strict=True):
            assert f"e_x alarms, n_persist {n}: {count}\n" in output, (name, output)
        assert f"nis {{}} {nis[0]} alarms" in output and f"0.01}} {nis[1]} alarms" in output, (name, output)
        assert f"e_x alarms masked {masked[0]}, unmasked {masked[1]}" in output, (name, output)


def fenced_blocks_of(text: str) -> list[tuple[str, str, int]]:
    return [(m.group(1), m.group(2), text.count("\n", 0, m.start()) + 1) for m in FENCE.finditer(text)]


USER_PAGES = ("bring-your-own-vehicle", "reading-the-report", "ci", "models", "troubleshooting", "evaluation")
USER_PAGES += ("inputs", "detectors")


@pytest.mark.parametrize("name", USER_PAGES)
def test_user_pages_name_no_commits(name):
    """User pages describe the installed logscan: no commit hashes (lab notes go to bench/)."""
    text = (DOCS / f"{name}.md").read_text(encoding="utf-8")
    assert not re.findall(r"\bcommit\b|\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*\d)[0-9a-f]{7,40}\b", text), name
