"""Fixes of the fuzzing campaign's bugs about what logscan writes (tests/fuzz_regressions/README.md):
an output path that is a FIFO or a device is written into, never replaced, and a socket is refused
(`output-replaces-special-file`); stderr holds logscan's own lines only, no numpy or scipy
RuntimeWarning with its source line: overflows are handled where they arise (NIS window sums and
their float32 copy, peak ratios, a signalling NaN, the discretisation of a huge A, which is a
profile error), and any warning left is one logscan line (`runtime-warning-leak`)."""

from __future__ import annotations

import errno
import json
import math
import os
import re
import socket
import stat
import subprocess
import sys
import tempfile
import threading
import warnings
from pathlib import Path

import numpy as np
import pytest

from logscan import artifacts
from logscan.alarms import alarm_intervals
from logscan.cli import main as cli_main
from logscan.detectors.nis import as_float32, window_sums
from logscan.log import Channel
from logscan.models import get_model

OLD = b"previous run's output\n"
LINUX_FDS = Path("/proc/self/fd").is_dir()
REPO = Path(__file__).resolve().parents[1]
PY_WARNING = re.compile(r"^\S+\.py:\d+: \w*Warning: ", re.M)  # Python's own format (the fuzzer's oracle)


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
        self.thread.join(5)  # at once when something wrote and closed the FIFO
        if self.thread.is_alive():  # nothing opened the FIFO for writing: let the reader go
            try:
                os.close(os.open(self.path, os.O_WRONLY | os.O_NONBLOCK))
            except OSError:  # ENXIO: the reader is not in open() yet
                pass
            self.thread.join(5)
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


@pytest.mark.parametrize("failure", [BrokenPipeError(errno.EPIPE, os.strerror(errno.EPIPE)), KeyboardInterrupt()])
def test_a_failed_or_interrupted_write_into_a_fifo_puts_the_renamed_outputs_back(tmp_path, monkeypatch, failure):
    report = tmp_path / "r.html"
    report.write_bytes(OLD)
    fresh = tmp_path / "fresh.html"  # did not exist: removed again
    fifo = tmp_path / "summary.json"
    os.mkfifo(fifo)
    staged = [artifacts.stage(report, "new"), artifacts.stage(fresh, "new"), artifacts.stage(fifo, "{}")]

    def broken(target, data):  # e.g. the reader went away, or Ctrl-C while waiting for one
        raise failure

    monkeypatch.setattr(artifacts, "_write_into", broken)
    with pytest.raises(artifacts.OutputError if isinstance(failure, OSError) else KeyboardInterrupt) as error:
        artifacts.commit(staged)
    if isinstance(failure, OSError):
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


# --- runtime-warning-leak ------------------------------------------------------------------------


@pytest.fixture
def warnings_are_errors():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


def test_the_reproducer_leaves_stderr_to_logscan(cli_process):
    """runtime_warning.mcap: a `tau_eq` of 3.4e38 made the NIS per dof overflow float32."""
    log = REPO / "tests" / "fuzz_regressions" / "runtime_warning.mcap"
    result = cli_process("analyze", log, "--no-report", "--json", "-")
    assert result.exit_code == 1, result.stderr
    assert not PY_WARNING.search(result.stderr) and "Warning" not in result.stderr, result.stderr
    document = json.loads(result.stdout)
    alarms = document["logs"][0]["detectors"]
    assert any(a["signal"].startswith("nis.") for d in alarms for a in d["alarms"])


def test_window_sums_of_huge_nis_neither_overflow_nor_lose_the_later_windows(warnings_are_errors):
    values = np.array([1.0, 1e308, 1e308, 2.0, 1e20, 3.0, 1.0, 1.0, 1.0, 5e9, 2.0, np.nan, 1.0, 1.0])
    counts = np.arange(values.size) % 2 + 1
    for window in (1, 2, 3, 20):
        sums, dof, full = window_sums(values, counts, window)
        for i in range(values.size):
            part = values[max(0, i + 1 - window) : i + 1]
            if not np.all(np.isfinite(part)):
                assert sums[i] == math.inf  # a non-finite NIS is an exceedance
            else:
                exact = sum(float(v) for v in part)  # Python floats: 1e308 + 1e308 = inf, no warning
                assert sums[i] == pytest.approx(exact, rel=1e-12), (window, i)
            assert dof[i] == counts[max(0, i + 1 - window) : i + 1].sum()
    # the windows after 1e20 keep their digits (the running sum used to give 0 or 16384 there)
    sums, _, _ = window_sums(np.array([1e20, 1.5, 2.25, 3.0]), np.ones(4, dtype=np.int64), 2)
    assert sums.tolist() == [1e20, 1e20 + 1.5, 3.75, 5.25]


def test_as_float32_makes_values_beyond_its_range_infinite(warnings_are_errors):
    out = as_float32(np.array([1e300, -1e300, 3.4e38, np.nan, 1.5, -np.inf]))
    assert out.dtype == np.float32
    assert out[0] == np.inf and out[1] == -np.inf and np.isnan(out[3]) and out[-1] == -np.inf
    assert out[2] == np.float32(3.4e38) and out[4] == 1.5


def test_a_peak_ratio_beyond_float_range_is_infinite_without_a_warning(warnings_are_errors):
    t = np.arange(10) * 0.1
    statistic = np.where(np.arange(10) == 5, 1e308, 0.0)
    (alarm,) = alarm_intervals(t, statistic, upper=np.full(10, 0.1), signal="s", detector="d")
    assert alarm.peak_value == 1e308 and alarm.peak_ratio == math.inf


def test_a_signalling_nan_becomes_a_quiet_nan_without_a_warning(warnings_are_errors):
    values = np.array([1.0, 2.0], dtype=np.float32)
    values.view(np.uint32)[1] = 0x7F800001  # a flipped exponent bit: a signalling NaN
    channel = Channel("x", np.array([1, 2]), values)
    assert channel.values.dtype == np.float64 and channel.values[0] == 1.0 and np.isnan(channel.values[1])


LINEAR = """
[vehicle]
model = "linear"
rate_hz = 100.0

[vehicle.params]
A = [[A00, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
B = [[0.0], [0.0], [0.0]]
C = { accel = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] }
R = { accel = [0.1, 0.1, 0.1] }

[inputs]
u0 = "/cmd/thrust"

[measurements.accel]
channels = ["/imu/accel.x", "/imu/accel.y", "/imu/accel.z"]
rate_hz = 100.0
"""


@pytest.mark.parametrize("a00", [1e308, 1e5])
def test_a_model_whose_discretisation_overflows_is_a_profile_error(a00, warnings_are_errors):
    model = get_model("linear", {"A": [[a00, 0.0], [0.0, 0.0]], "B": [[0.0], [0.0]], "C": [[1.0, 0.0]]})
    (problem,) = model.covariance_problems(0.01)
    assert problem.startswith("model 'linear': the dynamics (A, B) discretised at dt = 0.01 s are not finite")
    assert get_model("linear", {"A": [[-1.0]], "B": [[0.0]], "C": [[1.0]]}).covariance_problems(0.01) == []


def test_analyze_with_a_huge_a_exits_2_with_one_line(cli_process, sample, tmp_path):
    profile = tmp_path / "huge_a.toml"
    profile.write_text(LINEAR.replace("A00", "1e308"))
    result = cli_process("analyze", sample("quad_healthy.csv"), "--profile", profile, "--no-report", "-q")
    assert result.exit_code == 2
    assert re.fullmatch(
        rf"logscan: error: {re.escape(str(profile))}: invalid profile: \[vehicle\] params: model 'linear': the "
        r"dynamics \(A, B\) discretised at dt = 0.01 s are not finite: exp\(A dt\) overflows.*",
        one_line(result.stderr),
    )


def test_a_warning_left_is_one_logscan_line(cli, sample, monkeypatch):
    """The backstop: a RuntimeWarning nobody handled (here from a patched step) is one line of
    logscan's own on stderr, naming where; the run goes on."""
    import logscan.cli.analyze_cmd as analyze_cmd

    real = analyze_cmd.render_summary

    def render(*args, **kwargs):
        with np.errstate(over="warn"):
            np.float32(np.float64(1e300))
        return real(*args, **kwargs)

    monkeypatch.setattr(analyze_cmd, "render_summary", render)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        result = cli("analyze", sample("quad_healthy.mcap"), "--no-report", "-q")
    assert result.exit_code in (0, 1)
    line = one_line(result.stderr)
    assert re.fullmatch(
        r"logscan: warning: numeric problem in logscan/tasks\.py line \d+ "
        r"\(tests/test_fuzz_fixes_outputs\.py\): overflow encountered in cast \(a result there may be inf or NaN\)",
        line,
    ), line
    assert not PY_WARNING.search(result.stderr)


def test_a_warning_from_a_library_names_the_line_of_logscan_that_called_it(capsys):
    import logscan

    namespace = {"warnings": warnings}
    caller = Path(logscan.__file__).parent / "filters" / "caller.py"  # a frame of logscan's (no such file)
    source = "def f():\n    warnings.warn_explicit(MESSAGE, RuntimeWarning, LIBRARY, 83)\n"
    exec(compile(source, str(caller), "exec"), namespace)
    namespace.update(MESSAGE="overflow encountered in reduce", LIBRARY="/v/site-packages/numpy/_core/fromnumeric.py")
    with cli_main._warnings_as_lines(debug=False):
        namespace["f"]()
    assert capsys.readouterr().err == (
        "logscan: warning: numeric problem in logscan/filters/caller.py line 2 (numpy/_core/fromnumeric.py): "
        "overflow encountered in reduce (a result there may be inf or NaN)\n"
    )


def test_other_warnings_are_one_line_too_and_debug_keeps_pythons_format(capsys):
    with cli_main._warnings_as_lines(debug=False):
        warnings.warn_explicit("something odd", UserWarning, "/x/site-packages/pkg/mod.py", 7)
    assert capsys.readouterr().err == "logscan: warning: UserWarning in pkg/mod.py line 7: something odd\n"
    with pytest.warns(UserWarning, match="something odd"):  # --debug: Python's own machinery and format
        with cli_main._warnings_as_lines(debug=True):
            warnings.warn_explicit("something odd", UserWarning, "/x/site-packages/pkg/mod.py", 8)
    assert capsys.readouterr().err == ""


def test_a_directory_that_takes_no_new_files_is_named_so(tmp_path):
    """ENOENT on a file in an existing directory (/proc refuses new files so) is not a missing
    directory: the message must not send the user to create one that exists."""
    missing = artifacts.output_error(OSError(errno.ENOENT, "No such file"), tmp_path / "r.html")
    assert "the directory does not take new files" in missing.one_line()
    gone = artifacts.output_error(OSError(errno.ENOENT, "No such file"), tmp_path / "no" / "r.html")
    assert "the directory does not exist" in gone.one_line()


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs /proc")
def test_report_into_proc_exits_2_with_the_real_reason(cli, sample):
    result = cli("analyze", sample("quad_healthy.mcap"), "-o", "/proc/logscan_report.html", "-q")
    assert result.exit_code == 2
    assert "/proc/logscan_report.html: cannot write the output: the directory does not take new files" in one_line(
        result.stderr
    )
