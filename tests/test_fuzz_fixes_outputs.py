"""Fixes of the fuzzing campaign's bugs about what logscan writes (tests/fuzz_regressions/README.md):
an output path that is a FIFO or a device is written into, never replaced, and a socket is refused
(`output-replaces-special-file`)."""

from __future__ import annotations

import errno
import json
import os
import socket
import stat
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import pytest

from logscan import artifacts

OLD = b"previous run's output\n"
LINUX_FDS = Path("/proc/self/fd").is_dir()


def temporary_files(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.rglob("*") if p.name.endswith((".tmp", ".bak")))


def one_line(stderr: str) -> str:
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1, stderr
    return lines[0]


class FifoReader:
    """A FIFO at ``path`` and a thread reading it to its end (a writer blocks until it is there)."""

    def __init__(self, path: Path):
        os.mkfifo(path)
        self.path = path
        self.data: list[bytes] = []
        self.thread = threading.Thread(target=lambda: self.data.append(path.read_bytes()), daemon=True)
        self.thread.start()

    def received(self) -> bytes:
        if self.thread.is_alive():  # nothing opened the FIFO for writing: let the reader go
            with open(os.open(self.path, os.O_WRONLY | os.O_NONBLOCK), "wb"):
                pass
        self.thread.join(10)
        assert stat.S_ISFIFO(os.lstat(self.path).st_mode), f"{self.path} was replaced"
        return self.data[0] if self.data else b""


@pytest.fixture
def devices_never_replaced(monkeypatch):
    """Nothing is created in or renamed into /dev while the test runs: a regression fails the test
    instead of replacing /dev/null (as root it could)."""
    real_replace, real_mkstemp = os.replace, tempfile.mkstemp

    def replace(src, dst, *args, **kwargs):
        assert not os.path.abspath(dst).startswith("/dev/"), f"rename onto {dst}"
        return real_replace(src, dst, *args, **kwargs)

    def mkstemp(*args, dir=None, **kwargs):
        assert dir is None or not os.path.abspath(dir).startswith("/dev"), f"temporary file in {dir}"
        return real_mkstemp(*args, dir=dir, **kwargs)

    monkeypatch.setattr(os, "replace", replace)
    monkeypatch.setattr(tempfile, "mkstemp", mkstemp)


# --- artifacts: stage and commit ------------------------------------------------------------------


def test_a_fifo_target_is_written_into_after_the_renames(tmp_path):
    report = tmp_path / "r.html"
    report.write_bytes(OLD)
    fifo = FifoReader(tmp_path / "summary.json")
    staged = [artifacts.stage(report, "new report"), artifacts.stage(fifo.path, '{"new": 1}\n')]
    assert staged[1].tmp is None and staged[1].data == b'{"new": 1}\n'
    artifacts.commit(staged)
    assert fifo.received() == b'{"new": 1}\n'
    assert report.read_text() == "new report"
    assert temporary_files(tmp_path) == []


def test_a_failed_write_into_a_fifo_puts_the_renamed_outputs_back(tmp_path, monkeypatch):
    report = tmp_path / "r.html"
    report.write_bytes(OLD)
    fresh = tmp_path / "fresh.html"  # did not exist: removed again
    fifo = tmp_path / "summary.json"
    os.mkfifo(fifo)
    staged = [artifacts.stage(report, "new"), artifacts.stage(fresh, "new"), artifacts.stage(fifo, "{}")]

    def broken(target, data):
        raise BrokenPipeError(errno.EPIPE, os.strerror(errno.EPIPE))

    monkeypatch.setattr(artifacts, "_write_into", broken)
    with pytest.raises(artifacts.OutputError) as error:
        artifacts.commit(staged)
    assert error.value.one_line().startswith(f"{fifo}: cannot write the output: the reader of the pipe closed it")
    assert report.read_bytes() == OLD and not fresh.exists()
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert temporary_files(tmp_path) == []


def test_dev_null_is_written_into_and_stays_a_device(devices_never_replaced):
    before = os.stat("/dev/null")
    staged = artifacts.stage("/dev/null", "ignored")
    assert staged.tmp is None
    artifacts.commit([staged])
    artifacts.write_json("/dev/null", {"a": 1})
    after = os.stat("/dev/null")
    assert stat.S_ISCHR(after.st_mode) and after.st_rdev == before.st_rdev and after.st_ino == before.st_ino


@pytest.mark.skipif(not LINUX_FDS, reason="needs /proc/self/fd")
def test_a_path_naming_an_open_descriptor_appends_to_its_file_and_keeps_the_link(tmp_path):
    """/dev/stdout redirected to a file (`--json /dev/stdout > out`): the link /dev/stdout is a
    regular file by stat, but it must never be renamed onto; the file gets the output appended.
    A link of our own to /proc/self/fd/N stands in for /dev/stdout."""
    out = tmp_path / "out.txt"
    with open(out, "wb") as fh:
        fh.write(OLD)
        fh.flush()
        link = tmp_path / "stdout"
        link.symlink_to(f"/proc/self/fd/{fh.fileno()}")
        assert artifacts.check_target(link) is True
        artifacts.write_json(link, {"a": 1})
    assert os.path.islink(link)
    assert out.read_bytes() == OLD + b'{\n  "a": 1\n}\n'


def test_regular_files_and_new_paths_are_still_staged(tmp_path):
    existing = tmp_path / "old.json"
    existing.write_bytes(OLD)
    assert artifacts.check_target(existing) is False
    assert artifacts.check_target(tmp_path / "new.json") is False
    link = tmp_path / "link.json"
    link.symlink_to(existing)
    assert artifacts.check_target(link) is False


def test_a_socket_or_a_directory_as_target_is_refused(tmp_path):
    sock = socket.socket(socket.AF_UNIX)
    path = tmp_path / "s.json"
    try:
        sock.bind(str(path))
        with pytest.raises(artifacts.OutputError, match="it is a socket"):
            artifacts.stage(path, "{}")
    finally:
        sock.close()
    assert stat.S_ISSOCK(os.lstat(path).st_mode)
    with pytest.raises(artifacts.OutputError, match="it is a directory"):
        artifacts.stage(tmp_path, "{}")
    assert temporary_files(tmp_path) == []


# --- the command line ------------------------------------------------------------------------------


def test_analyze_writes_report_and_json_into_fifos(cli, sample, tmp_path):
    report, summary = FifoReader(tmp_path / "r.html"), FifoReader(tmp_path / "r.json")
    result = cli("analyze", sample("quad_healthy.mcap"), "-o", report.path, "--json", summary.path, "-q")
    assert result.exit_code in (0, 1), result.stderr
    html, document = report.received(), json.loads(summary.received())
    assert b"<html" in html[:1000].lower()
    assert document["exit_code"] == result.exit_code and document["logs"][0]["report"] == str(report.path)
    assert temporary_files(tmp_path) == []


def test_analyze_report_to_dev_null(cli, sample, tmp_path, devices_never_replaced):
    result = cli("analyze", sample("quad_healthy.mcap"), "-o", "/dev/null", "--json", tmp_path / "s.json", "-q")
    assert result.exit_code in (0, 1), result.stderr
    assert json.loads((tmp_path / "s.json").read_text())["logs"][0]["report"] == "/dev/null"
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)


def test_json_dash_still_goes_to_stdout(cli, sample):
    result = cli("analyze", sample("quad_healthy.mcap"), "--no-report", "--json", "-", "-q")
    assert result.exit_code in (0, 1), result.stderr
    assert json.loads(result.stdout)["exit_code"] == result.exit_code


def test_json_to_a_socket_is_refused_before_any_log_is_read(cli, tmp_path):
    sock = socket.socket(socket.AF_UNIX)
    path = tmp_path / "s.json"
    try:
        sock.bind(str(path))
        result = cli("analyze", tmp_path / "no_such_log.mcap", "--no-report", "--json", path)
    finally:
        sock.close()
    assert result.exit_code == 2
    assert one_line(result.stderr) == (
        f"logscan: error: {path}: cannot write the output: it is a socket "
        "(give the name of a file, a FIFO or a character device such as /dev/null)"
    )


def test_json_to_a_full_device_exits_2(cli, sample, devices_never_replaced):
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full")
    result = cli("analyze", sample("quad_healthy.mcap"), "--no-report", "--json", "/dev/full", "-q")
    assert result.exit_code == 2
    assert one_line(result.stderr).startswith("logscan: error: /dev/full: cannot write the output: no space left")


@pytest.mark.skipif(not LINUX_FDS, reason="needs /proc/self/fd")
def test_json_to_stdout_by_name_follows_the_summary_in_the_redirected_file(sample, tmp_path):
    """`logscan analyze LOG --json /dev/stdout > out`, in a real process (a link of our own to
    /proc/self/fd/1 stands in for /dev/stdout, so a regression cannot replace the system's)."""
    link = tmp_path / "stdout"
    link.symlink_to("/proc/self/fd/1")
    out = tmp_path / "out.txt"
    with open(out, "wb") as fh:
        proc = subprocess.run(
            [sys.executable, "-m", "logscan", "analyze", sample("quad_healthy.mcap"), "--no-report", "--json", link],
            stdout=fh,
            stderr=subprocess.PIPE,
            text=True,
            timeout=300,
        )
    assert proc.returncode in (0, 1), proc.stderr
    text = out.read_text()
    summary, _, document = text.partition("\n{")
    assert "quad_healthy.mcap" in summary
    assert json.loads("{" + document)["exit_code"] == proc.returncode
    assert os.path.islink(link) and proc.stderr == ""
