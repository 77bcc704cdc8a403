"""Processes end when they should and leave nothing behind: `--jobs` workers end with their parent,
temporary files of dead processes are removed from any folder written to, Ctrl-C is exit 130 at
every step of `train` and `evaluate`, `simulate -o` never silently replaces a log, and several logs
never make a directory of a report's name (issue 31)."""

from __future__ import annotations

import os
import pty
import select
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from logscan.artifacts import ORPHAN_AGE_S, remove_dead_temporaries, stage, write_atomic

POLL_LIMIT_S = 120.0  # a generous bound on waiting for a process to appear or end (no speed is asserted)


def _children(pid: int) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if int(fields[1]) == pid:
            found.append(int(entry.name))
    return found


def _alive(pid: int) -> bool:
    """A process that exists and is not a zombie (a zombie has ended; only its exit status is left)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X")


def _poll(condition, limit_s: float = POLL_LIMIT_S) -> bool:
    deadline = time.monotonic() + limit_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.1)
    return condition()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_jobs_workers_end_when_only_their_parent_is_killed(sample, tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    for i in range(8):  # more logs than workers: the run is still going when its parent is killed
        shutil.copy(sample("quad_healthy.mcap"), logs / f"flight{i}.mcap")
    parent = subprocess.Popen(
        [sys.executable, "-m", "logscan", "analyze", str(logs), "--jobs", "2", "--no-report", "-q"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    workers: list[int] = []
    try:
        assert _poll(lambda: len(_children(parent.pid)) >= 2), "the two workers never started"
        workers = _children(parent.pid)
        assert parent.poll() is None, "the run ended before its parent could be killed"
        parent.kill()  # SIGKILL: the parent cannot stop its workers itself
        parent.wait()
        assert _poll(lambda: not any(_alive(pid) for pid in workers)), "a worker outlived its parent"
    finally:
        for pid in workers:  # the workers this test started, should they have survived
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
        if parent.poll() is None:
            parent.kill()


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def _temporary(folder: Path, name: str, age_s: float) -> Path:
    path = folder / name
    path.write_text("partial")
    then = time.time() - age_s
    os.utime(path, (then, then))
    return path


def test_temporary_files_name_their_process(tmp_path):
    staged = stage(tmp_path / "out.json", "{}")
    try:
        assert Path(staged.tmp).name.startswith(f".out.json.{os.getpid()}-")
    finally:
        os.unlink(staged.tmp)


def test_stale_temporary_files_of_dead_processes_are_removed_from_any_folder_written_to(tmp_path):
    dead, old = _dead_pid(), ORPHAN_AGE_S + 600
    stale = [
        _temporary(tmp_path, f".two.html.{dead}-0123abcd.k2j4_x9q.tmp", old),
        _temporary(tmp_path, f".summary.json.{dead}-89abcdef.bak", old),
    ]
    kept = [
        _temporary(tmp_path, f".live.json.{os.getpid()}-0123abcd.abcdefgh.tmp", old),  # a running process's
        _temporary(tmp_path, f".young.json.{dead}-0123abcd.abcdefgh.tmp", 0),  # it may still be renamed
        _temporary(tmp_path, ".notes.tmp", old),  # not logscan's
        _temporary(tmp_path, f"visible.{dead}-0123abcd.abcdefgh.tmp", old),  # not hidden: not logscan's
    ]
    write_atomic(tmp_path / "other.json", "{}")  # a file of another name, in the same folder
    assert [p for p in stale if p.exists()] == []
    assert all(p.exists() for p in kept)
    assert (tmp_path / "other.json").read_text() == "{}"
    assert remove_dead_temporaries(tmp_path) == 0


def test_a_command_writing_into_a_folder_cleans_it(cli, tmp_path):
    stale = _temporary(tmp_path, f".report.html.{_dead_pid()}-0123abcd.abcdefgh.tmp", ORPHAN_AGE_S + 600)
    result = cli("detectors", "--json", tmp_path / "detectors.json")
    assert result.exit_code == 0, result.stderr
    assert not stale.exists()


# --- Ctrl-C ---------------------------------------------------------------------------------------


def _interrupt_at_progress(args: list, marker: str, seen: int) -> tuple[int | None, str]:
    """Run `python -m logscan ARGS` with stderr on a terminal (so it shows its progress), send
    SIGINT once ``marker`` has appeared more than ``seen`` times; (exit code, stderr)."""
    main_fd, terminal = pty.openpty()
    # a person at a terminal: progress shows there, except under CI=true (which this suite runs in)
    person = {key: value for key, value in os.environ.items() if key != "CI"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "logscan", *map(str, args)], stdout=subprocess.DEVNULL, stderr=terminal, env=person
    )
    os.close(terminal)
    text, sent = "", False
    deadline = time.monotonic() + POLL_LIMIT_S
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([main_fd], [], [], 1.0)
            if not ready:
                continue
            try:
                data = os.read(main_fd, 4096)
            except OSError:  # the process closed the terminal: it ended
                break
            if not data:
                break
            text += data.decode(errors="replace")
            if not sent and text.count(marker) > seen:
                proc.send_signal(signal.SIGINT)
                sent = True
        proc.wait(timeout=POLL_LIMIT_S)
    finally:
        os.close(main_fd)
        if proc.poll() is None:
            proc.kill()
    assert sent, f"{marker!r} not shown {seen + 1} times: {text}"
    return proc.returncode, text


@pytest.mark.parametrize("line_number", [0, 1, 2], ids=["reading the first log", "reading the second", "fitting"])
def test_ctrl_c_in_train_is_exit_130_at_every_step(sample, tmp_path, line_number):
    logs = [sample("jackal_train_1.mcap"), sample("jackal_train_2.mcap")]
    code, text = _interrupt_at_progress(["train", *logs, "-o", tmp_path / "t.json"], "logscan: ", line_number)
    assert code == 130, text
    assert text.strip().splitlines()[-1] == "logscan: interrupted" and "Traceback" not in text
    assert not (tmp_path / "t.json").exists() or line_number == 2  # interrupted before writing


def test_ctrl_c_in_evaluate_is_exit_130(sample, tmp_path):
    logs = [sample("sbw_healthy.mcap"), sample("sbw_yaw_rate_bitflip.mcap")]
    code, text = _interrupt_at_progress(["evaluate", *logs, "--json", tmp_path / "e.json"], "evaluating", 0)
    assert code == 130, text
    assert text.strip().splitlines()[-1] == "logscan: interrupted" and "Traceback" not in text


# --- outputs that would be replaced or misnamed ---------------------------------------------------


def test_simulate_refuses_to_replace_an_existing_log_without_force(cli, tmp_path):
    out = tmp_path / "run.mcap"
    out.write_bytes(b"an earlier log")
    result = cli("simulate", "dc_motor", "--duration", "2", "-q", "-o", out)
    assert result.exit_code == 2
    assert result.stderr.strip().splitlines() == [
        f"logscan: error: {out}: already exists (pass --force to replace it, or give another -o)"
    ]
    assert out.read_bytes() == b"an earlier log"
    result = cli("simulate", "dc_motor", "--duration", "2", "-q", "-o", out, "--force")
    assert result.exit_code == 0, result.stderr
    assert out.read_bytes().startswith(b"\x89MCAP")


def test_simulate_refuses_to_replace_a_csv_logs_sidecar(cli, tmp_path):
    (tmp_path / "run.truth.json").write_text("{}")
    result = cli("simulate", "dc_motor", "--duration", "2", "-q", "-o", tmp_path / "run.csv")
    assert result.exit_code == 2 and "would replace" in result.stderr and "run.truth.json" in result.stderr
    assert not (tmp_path / "run.csv").exists() and (tmp_path / "run.truth.json").read_text() == "{}"


def test_several_logs_with_an_output_that_is_no_directory_is_exit_2(cli, sample, tmp_path):
    logs = [sample("sbw_healthy.mcap"), sample("quad_healthy.mcap")]
    result = cli("analyze", *logs, "-o", tmp_path / "two.html")
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "does not exist, and 2 logs need a directory" in lines[0], result.stderr
    assert not (tmp_path / "two.html").exists()
