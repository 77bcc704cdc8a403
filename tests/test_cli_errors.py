"""Bad input on the command line: exit 2 with one line on stderr, never a traceback.

End to end: most tests run `python -m logscan` in a subprocess, so the exit code, stderr and stdout are a real
process's (no traceback, warning or stray print can hide in the test process). Checks of one reader's message
run in-process through the `cli` fixture.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from conftest import need_testdata

from logscan import __version__

ULOG = Path(__file__).resolve().parents[2] / "shared" / "testdata" / "px4-ulog" / "sample_log_small.ulg"


def assert_one_line_error(result, *fragments: str) -> None:
    assert result.exit_code == 2, (result.exit_code, result.stderr)
    assert "Traceback" not in result.stderr and result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("logscan: error: ")
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


def test_version(cli_process):
    """--version names logscan's version and those of the libraries results depend on."""
    result = cli_process("--version")
    assert result.exit_code == 0 and __version__ in result.stdout and result.stderr == ""
    for package in ("numpy", "numba", "mcap", "plotly"):
        assert re.search(rf"\b{package} \d+\.\d+", result.stdout), (package, result.stdout)
    assert "compiled-kernel cache: " in result.stdout


def test_missing_file(tmp_path, cli_process):
    missing = tmp_path / "nope.mcap"
    assert_one_line_error(cli_process("inspect", str(missing)), str(missing), "no such file")


def test_random_bytes_file(tmp_path, cli_process):
    junk = tmp_path / "junk.bin"
    junk.write_bytes(np.random.default_rng(0).integers(0, 256, 10_000, dtype=np.uint8).tobytes())
    assert_one_line_error(cli_process("inspect", str(junk)), str(junk), "not an MCAP, ULog or CSV")


def test_directory_without_csvs(tmp_path, cli_process):
    (tmp_path / "readme.txt").write_text("hello")
    assert_one_line_error(cli_process("inspect", str(tmp_path)), "directory holds no .csv files")


@pytest.mark.parametrize(
    "content, fragment",
    [
        ("", "empty"),
        ("time,x\n", "no data rows"),
        ("a,b\n1,2\n", "no time column"),
        ("time,x\n1,2,3,4\n5,6,7,8\n", "more fields than the header"),
    ],
)
def test_bad_csv_files(tmp_path, content, fragment, cli):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    assert_one_line_error(cli("inspect", path), str(path), fragment)


def test_mcap_with_bad_magic(tmp_path, cli_process):
    path = tmp_path / "bad.mcap"
    path.write_bytes(b"\x89MCAX0\r\n" + bytes(200))
    assert_one_line_error(cli_process("inspect", str(path)), str(path))


def test_ulog_cut_before_any_data(tmp_path, cli_process):
    need_testdata(ULOG)
    path = tmp_path / "cut.ulg"
    path.write_bytes(ULOG.read_bytes()[:3000])
    assert_one_line_error(cli_process("inspect", str(path)), str(path), "truncated")


@pytest.mark.parametrize("length", [100, 3000, 20000])
def test_analyze_says_a_ulog_cut_before_its_data_is_damaged(tmp_path, cli, length):
    """A real flight cut while copying: analyze names the damage, as inspect does, not a missing
    profile or IMU topic (what the built-in profile found of what little was read)."""
    need_testdata(ULOG)
    path = tmp_path / "cut.ulg"
    path.write_bytes(ULOG.read_bytes()[:length])
    result = cli("analyze", path, "--no-report", "-q")
    assert_one_line_error(result, str(path), "damaged log", "truncated")
    assert "no profile" not in result.stderr and "IMU" not in result.stderr


def test_a_ulog_cut_only_in_its_last_message_keeps_the_error_of_what_it_lacks(tmp_path, cli):
    """Power lost while logging cuts the last message: the rest is read, so a PX4 log without an IMU
    topic is still told so, not sent to copy the file again."""
    import numpy as np
    from ulog_writer import write_ulog

    t = (np.arange(2000) * 10_000 + 1_000_000).astype(np.int64)
    full = tmp_path / "full.ulg"
    write_ulog(
        str(full), {"vehicle_attitude": (t, {"q": np.tile([1.0, 0, 0, 0], (t.size, 1))})}, info={"sys_name": "PX4"}
    )
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(full.read_bytes()[:-5])
    result = cli("analyze", cut, "--no-report", "-q")
    assert_one_line_error(result, str(cut), "without an IMU topic")
    assert "damaged" not in result.stderr


def test_an_internal_errors_exit_code_stands_when_stderr_is_closed(monkeypatch):
    """A bug's line cannot be written to a closed stderr (`2>&1 | head`): the exit code is still 3,
    not a broken pipe's 2."""
    import sys

    from logscan.cli import main as cli_main

    class Closed:
        def write(self, text):
            raise BrokenPipeError(32, "Broken pipe")

        def flush(self):
            raise BrokenPipeError(32, "Broken pipe")

        def isatty(self):
            return False

    monkeypatch.setattr(sys, "stderr", Closed())
    monkeypatch.setattr(cli_main.cli, "main", lambda **kwargs: (_ for _ in ()).throw(RuntimeError("a bug")))
    with pytest.raises(SystemExit) as exit_info:
        cli_main.main(["analyze", "x.mcap"])
    assert exit_info.value.code == 3


def test_truncated_ulog_is_read_as_partial_and_says_so(tmp_path, cli):
    need_testdata(ULOG)
    path = tmp_path / "half.ulg"
    data = ULOG.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    result = cli("inspect", path)
    assert result.exit_code == 0 and "Traceback" not in result.stderr
    assert "PARTIAL:   only part of the file was read: truncated" in result.stdout


def test_a_closed_output_pipe_exits_2_not_1():
    """`logscan analyze ... 2>&1 | head`: the reader of stderr leaves after the first line. The lines
    still to come cannot be written, an output not written: exit 2 (click's own answer was 1, which
    says "alarms"), with no traceback. Each of the 154 conformance files of one folder gives a line
    (no profile), a few at a time, long after the reader left."""
    import subprocess
    import sys

    folder = need_testdata("mcap-conformance/TenMessages")
    command = [sys.executable, "-m", "logscan", "analyze", str(folder), "--no-report", "-q"]
    with subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE) as proc:
        assert proc.stderr is not None
        proc.stderr.read(10)
        proc.stderr.close()  # the reader leaves
        assert proc.wait(timeout=300) == 2


def test_unknown_option_is_a_usage_error(cli_process):
    result = cli_process("inspect", "--no-such-option", "x")
    assert result.exit_code == 2 and "Traceback" not in result.stderr
    assert "no such option" in result.stderr.lower()


def test_json_to_a_missing_directory_is_an_input_error(tmp_path, cli_process):
    need_testdata(ULOG)
    target = tmp_path / "missing" / "facts.json"
    assert_one_line_error(cli_process("inspect", str(ULOG), "--json", str(target)), "output directory does not exist")
