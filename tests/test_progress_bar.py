"""The progress bar of one long log (logscan.cli.progress_bar): a bar, a percentage and ETAs redrawn
in place on a terminal, none under CI or --quiet, the old one line per step off a terminal, and
a reader's progress callback called per block of the file, not per message."""

from __future__ import annotations

import io
import os
import pty
import subprocess
import sys
from pathlib import Path

import pytest

from logscan.cli.progress_bar import SHARES, BarLine, EtaModel, phase_of

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_logs" / "quad_healthy.mcap"


class FakeTty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_terminal_gets_a_bar_with_a_percentage_and_etas_redrawn_in_place():
    out = FakeTty()
    line = BarLine(interval=60.0, stream=out)  # no tick within the test: each draw is called here
    line.step("logscan: f.mcap: reading", name="reading")
    line.fraction(40, 100)
    line.draw()
    line.step("logscan: f.mcap: aligning", name="aligning")  # the rate of this log is known from now on
    line.close()
    text = out.getvalue()
    drawn = [part for part in text.split("\r\x1b[K") if part and not part.endswith("\n")]
    assert any(d.startswith("logscan: f.mcap: reading [########") and " 40% ETA " in d for d in drawn), drawn
    assert any(d.startswith("logscan: f.mcap: aligning [") and "% ETA " in d and ", log " in d for d in drawn)
    ended = [part for part in text.split("\r\x1b[K") if part.endswith("\n")]
    assert [part.split(" (")[0] for part in ended] == ["logscan: f.mcap: reading", "logscan: f.mcap: aligning"]


def test_off_a_terminal_each_step_is_one_plain_line_with_its_time():
    out = io.StringIO()
    line = BarLine(interval=0.01, stream=out)
    line.step("logscan: f.mcap: reading", name="reading")
    line.fraction(1, 2)
    line.draw()
    line.step("logscan: f.mcap: filtering", name="filtering")
    line.close()
    lines = out.getvalue().splitlines(keepends=True)
    assert [text.split(" (")[0] for text in lines] == ["logscan: f.mcap: reading", "logscan: f.mcap: filtering"]
    assert all(text.endswith(" s)\n") for text in lines)
    assert "\r" not in out.getvalue() and "ETA" not in out.getvalue()


def test_the_eta_model_extrapolates_this_logs_rate_to_the_steps_left():
    model = EtaModel()
    assert model.estimate("reading", 1.0, None) is None  # nothing says yet how fast this log goes
    fraction, left, whole = model.estimate("reading", 1.0, 0.25)  # a quarter read in 1 s
    assert (fraction, left) == (0.25, pytest.approx(3.0))
    assert whole == pytest.approx(3.0 + 4.0 / SHARES["reading"] * (1.0 - SHARES["reading"]))
    model.end("reading", 1.3)  # read in 1.3 s: 10 s per share
    rate = 1.3 / SHARES["reading"]
    fraction, left, whole = model.estimate("filtering", 0.5 * rate * SHARES["filtering"], None)
    assert fraction == pytest.approx(0.5) and left == pytest.approx(0.5 * rate * SHARES["filtering"])
    assert whole == pytest.approx(left + rate * (SHARES["detecting"] + SHARES["report"]))
    assert model.estimate("filtering", 10 * rate, None)[:2] == (0.99, 0.0)  # late: never 100 % nor negative
    unreported = EtaModel(skipped=frozenset({"report"}))  # --no-report: no report step to come
    unreported.end("reading", 1.3)
    assert unreported.estimate("detecting", 0.0, None)[1:] == pytest.approx((rate * SHARES["detecting"],) * 2)


def test_step_names_map_to_the_models_phases():
    names = ["reading", "aligning loop roll", "filtering", "detector nis", "recovery", "writing report", "other"]
    assert [phase_of(n) for n in names] == [
        "reading",
        "aligning",
        "filtering",
        "detecting",
        "detecting",
        "report",
        None,
    ]


def test_the_mcap_reader_reports_its_bytes_per_chunk_not_per_message():
    from logscan.readers import read_log
    from logscan.readers.mcap.scan import scan_file

    calls: list[tuple[int, int]] = []
    read_log(SAMPLE, progress=lambda done, total: calls.append((done, total)))
    scan = scan_file(str(SAMPLE))
    size = SAMPLE.stat().st_size
    assert 1 <= len(calls) <= scan.chunks_read + 1 < scan.messages_read // 1000
    assert all(total == size for _, total in calls)
    assert [done for done, _ in calls] == sorted(done for done, _ in calls) and calls[-1][0] > 0.9 * size


def test_a_csv_directory_reports_once_per_file_read(tmp_path):
    from logscan.readers import read_log

    for topic in ("sensor_accel_0", "sensor_gyro_0"):
        rows = "".join(f"{1000 * i},{0.1 * i},{0.2 * i}\n" for i in range(50))
        (tmp_path / f"flight_{topic}.csv").write_text("timestamp,x,y\n" + rows)
    calls: list[tuple[int, int]] = []
    read_log(tmp_path, progress=lambda done, total: calls.append((done, total)))
    total = sum(f.stat().st_size for f in tmp_path.iterdir())
    assert len(calls) == 2 and calls[-1] == (total, total) and 0 < calls[0][0] < total


def _analyze_on_a_terminal(*args: str, ci: bool = False) -> str:
    """stderr of `logscan analyze` run on a pseudo-terminal (so stderr.isatty() is true)."""
    env = {k: v for k, v in os.environ.items() if k not in ("CI", "NO_COLOR", "FORCE_COLOR")}
    if ci:
        env["CI"] = "true"
    master, slave = pty.openpty()
    command = [sys.executable, "-m", "logscan", "analyze", str(SAMPLE), "--no-report", *args]
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=slave, stdin=subprocess.DEVNULL, env=env)
    os.close(slave)
    chunks = []
    while True:
        try:
            chunk = os.read(master, 65536)
        except OSError:  # the child's end closed (EIO on Linux)
            break
        if not chunk:
            break
        chunks.append(chunk)
    process.wait(timeout=300)
    os.close(master)
    return b"".join(chunks).decode(errors="replace")


@pytest.mark.slow
def test_analyze_draws_the_bar_on_a_terminal_and_none_under_ci_or_quiet():
    shown = _analyze_on_a_terminal()
    assert "\r\x1b[K" in shown and "% ETA " in shown and ": filtering (" in shown
    for quiet in (_analyze_on_a_terminal(ci=True), _analyze_on_a_terminal("-q")):
        assert "\r" not in quiet.replace("\r\n", "\n") and "ETA" not in quiet and "reading" not in quiet
