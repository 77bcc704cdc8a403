"""Untrusted inputs stay data (issue 31): every file a command line, a profile or a sidecar names is
read only as a regular file under a size limit; a profile embedded in a log names no file outside
the log's folder and no plugin; a plugin's run cannot end the analysis or write into `--json -`."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from importlib.metadata import EntryPoint
from pathlib import Path

import pytest

from logscan.detectors.registry import ENTRY_POINT_GROUP, Registry

SAMPLE = "sbw_healthy.mcap"
PLUGINS = '''
import os
import sys

from logscan.detectors.base import Detector


class Chatty(Detector):
    """Chatty: prints while it runs."""

    name = "chatty"

    def _fit(self, runs, traces, **context):
        print("chatty fits")

    def _run(self, run, trace, **context):
        print("hello from a plugin")
        sys.stdout.flush()
        os.write(1, b"raw bytes on file descriptor 1\\n")
        return self.new_result()


class Exiting(Detector):
    """Exiting: ends the process in run."""

    name = "exiting"

    def _run(self, run, trace, **context):
        os._exit(0)


class SysExiting(Detector):
    """SysExiting: raises SystemExit in run."""

    name = "sysexiting"

    def _run(self, run, trace, **context):
        sys.exit(0)


class Tripwire(Detector):
    """Tripwire: a plugin an embedded profile names; its run must never come."""

    name = "tripwire"

    def _run(self, run, trace, **context):
        raise AssertionError("a plugin named by a log's embedded profile ran")
'''
MODULE = "logscan_test_isolation_plugins"
NAMES = {"chatty": "Chatty", "exiting": "Exiting", "sysexiting": "SysExiting", "tripwire": "Tripwire"}


@pytest.fixture
def plugins(tmp_path, monkeypatch):
    """The plugins above as installed `logscan.detectors` entry points of the default registry."""
    folder = tmp_path / "plugins"
    folder.mkdir()
    (folder / f"{MODULE}.py").write_text(PLUGINS)
    monkeypatch.syspath_prepend(str(folder))
    eps = [EntryPoint(name=n, value=f"{MODULE}:{c}", group=ENTRY_POINT_GROUP) for n, c in NAMES.items()]
    monkeypatch.setattr("logscan.detectors.registry._DEFAULT", Registry(plugins=eps))
    yield folder
    sys.modules.pop(MODULE, None)


def _with_profile(sample, target: Path, edit) -> Path:
    """The sample log written again with its embedded profile's TOML changed by ``edit``."""
    from logscan.readers import read_log
    from logscan.readers.mcap import TopicData, write_mcap

    log = read_log(sample(SAMPLE))
    topics: dict[str, dict] = {}
    for name, channel in log.channels.items():
        topic, _, field = name.rpartition("/")
        topics.setdefault(topic, {"t": channel.t, "fields": {}})["fields"][field] = channel.values
    data = {topic: TopicData("x/msg/Y", e["t"], e["fields"]) for topic, e in topics.items()}
    write_mcap(target, data, encoding="json", metadata={"logscan.profile": {"toml": edit(log.profile_text)}})
    return target


def _one_line(result) -> str:
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    return lines[0]


def _tables(value: str):
    return lambda text: f"tables = {json.dumps(value)}\n" + text


# --- paths an embedded profile names ----------------------------------------------------------------


@pytest.mark.parametrize("tables", ["/dev/zero", "/etc/passwd", "../outside.json", "sub/../../outside.json"])
def test_an_embedded_profile_cannot_name_a_file_outside_the_logs_folder(cli, sample, tmp_path, tables):
    folder = tmp_path / "logs"
    (folder / "sub").mkdir(parents=True)
    (tmp_path / "outside.json").write_text("{}")
    log = _with_profile(sample, folder / "flight.mcap", _tables(tables))
    result = cli("analyze", log, "--no-report")
    assert result.exit_code == 2
    line = _one_line(result)
    assert f"tables = {tables!r}" in line and "may only name a file in the log's folder" in line
    assert line.startswith(f"logscan: error: {log} (embedded profile): ")


def test_an_embedded_profile_cannot_reach_out_through_a_symbolic_link(cli, sample, tmp_path):
    (tmp_path / "logs").mkdir()
    os.symlink("/dev/zero", tmp_path / "logs" / "tables.json")
    log = _with_profile(sample, tmp_path / "logs" / "flight.mcap", _tables("tables.json"))
    result = cli("analyze", log, "--no-report")
    assert result.exit_code == 2 and "leads out of the log's folder" in _one_line(result)


def test_a_fifo_beside_the_log_is_refused_without_waiting_for_a_writer(cli_process, sample, tmp_path):
    # a subprocess: a read that blocked on the FIFO would stop at the timeout, not hang the suite
    os.mkfifo(tmp_path / "tables.json")
    log = _with_profile(sample, tmp_path / "flight.mcap", _tables("tables.json"))
    result = cli_process("analyze", log, "--no-report", timeout=120)
    assert result.exit_code == 2
    line = _one_line(result)
    assert "the tables file is a FIFO (named pipe), not a regular file" in line and "tables.json" in line


def test_tables_beside_the_log_are_still_found(cli, sample, tmp_path):
    (tmp_path / "tables.json").write_text('{"format": "something else"}')
    log = _with_profile(sample, tmp_path / "flight.mcap", _tables("tables.json"))
    result = cli("analyze", log, "--no-report")
    assert result.exit_code == 2 and "not a logscan tables file" in _one_line(result)


# --- files the user names: regular files under a size limit, never devices or FIFOs -------------------


NAMED = [
    ("--tables", "the tables file"),
    ("--baseline", "the baseline"),
    ("--suppressions", "the suppressions file"),
    ("--truth", "ground truth"),
]


@pytest.mark.parametrize("option, what", NAMED)
@pytest.mark.parametrize("kind", ["fifo", "device"])  # a directory: click refuses it (exit 2)
def test_every_named_input_file_is_a_regular_file(cli, sample, tmp_path, option, what, kind):
    if kind == "fifo":
        path = tmp_path / "input"
        os.mkfifo(path)
        words = "is a FIFO (named pipe), not a regular file"
    elif kind == "device":
        path, words = Path("/dev/zero"), "is a character device, not a regular file"
    result = cli("analyze", sample(SAMPLE), option, path, "--no-report")
    assert result.exit_code == 2
    line = _one_line(result)
    assert f"{what} {words}" in line and str(path) in line


def test_a_named_input_file_over_its_size_limit_is_refused_before_it_is_read(cli, sample, tmp_path, monkeypatch):
    monkeypatch.setattr("logscan.verdict.suppressions.MAX_SUPPRESSIONS_BYTES", 100)
    path = tmp_path / "big.toml"
    path.write_text("#" * 101)
    result = cli("analyze", sample(SAMPLE), "--suppressions", path, "--no-report")
    assert result.exit_code == 2 and "is 101 bytes, more than the 100 it may have" in _one_line(result)


# --- plugins ------------------------------------------------------------------------------------------


def test_an_embedded_profile_cannot_run_a_plugin(cli, sample, tmp_path, plugins):
    log = _with_profile(sample, tmp_path / "flight.mcap", lambda text: text + "\n[detectors.tripwire]\n")
    result = cli("analyze", log, "--no-report")
    assert result.exit_code == 2
    line = _one_line(result)
    assert "names the plugin detector(s) 'tripwire'" in line and "never runs a plugin" in line
    assert MODULE not in sys.modules  # refused before any plugin code was imported


def test_the_user_may_run_a_plugin_on_a_log_that_embeds_its_profile(cli, sample, tmp_path, plugins):
    result = cli("analyze", sample(SAMPLE), "--detector", "chatty", "--json", "-", "--no-report")
    assert result.exit_code == 0, result.stderr
    assert json.loads(result.stdout)["logs"][0]["verdict"] == "no alarms"


def _driver(tmp_path: Path, plugins: Path) -> list[str]:
    """`python -c` running the CLI with the test plugins registered: a real process, so file
    descriptor 1 shows anything written to stdout."""
    eps = [f"EntryPoint(name={n!r}, value={f'{MODULE}:{c}'!r}, group={ENTRY_POINT_GROUP!r})" for n, c in NAMES.items()]
    code = textwrap.dedent(
        f"""
        import sys
        sys.path.insert(0, {str(plugins)!r})
        from importlib.metadata import EntryPoint
        import logscan.detectors.registry as registry
        registry._DEFAULT = registry.Registry(plugins=[{", ".join(eps)}])
        from logscan.cli.main import main
        main(sys.argv[1:])
        """
    )
    return [sys.executable, "-c", code]


def test_a_plugin_that_prints_or_ends_its_process_cannot_end_or_corrupt_the_run(sample, tmp_path, plugins):
    args = ["analyze", str(sample(SAMPLE)), "--json", "-", "--no-report"]
    args += ["-d", "nis", "-d", "chatty", "-d", "exiting", "-d", "sysexiting"]
    proc = subprocess.run([*_driver(tmp_path, plugins), *args], capture_output=True, text=True, timeout=300)
    summary = json.loads(proc.stdout)  # nothing the plugins printed is in it
    assert proc.returncode == 3, proc.stderr  # the plugins' bugs, the run itself completed
    (log,) = summary["logs"]
    assert [r["detector"] for r in log["detectors"]] == ["nis", "chatty"]
    failures = " ".join(str(f) for f in log.get("failures", [])) + proc.stderr
    assert "'exiting' (plugin) failed: ended its process (exit code 0) in run" in failures
    assert "'sysexiting' (plugin) failed: raised SystemExit: 0 in run" in failures
    assert "hello from a plugin" in proc.stderr and "raw bytes on file descriptor 1" in proc.stderr


def test_a_plugins_fit_is_isolated_and_keeps_what_it_learnt(plugins):
    from logscan.detectors.registry import default_registry

    registry = default_registry()
    detector = registry.create("chatty")
    assert type(detector).plugin_origin == "plugin"
    detector.__dict__["before"] = 1
    assert detector.fit([]) is detector and detector.before == 1


def test_a_csv_logs_sidecars_are_read_as_regular_files_only(tmp_path, cli):
    import os

    log = tmp_path / "flight.csv"
    log.write_text("t,x\n0,1\n0.1,2\n0.2,3\n")
    os.mkfifo(tmp_path / "flight.profile.toml")  # a FIFO would block a plain read forever
    result = cli("analyze", log, "--no-report")
    assert result.exit_code == 2 and "profile sidecar" in result.stderr and "FIFO" in result.stderr, result.stderr
