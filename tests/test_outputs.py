"""Outputs: written atomically and together, never over an input or each other, environment errors on
write as exit 2 with the previous files intact, Ctrl-C as exit 130 with nothing half-written, and
names from logs escaped on the terminal and in the report's figures."""

from __future__ import annotations

import errno
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from logscan import artifacts
from logscan.cli.render import printable
from logscan.fleet import output_paths, unique_names

OLD = b"previous run's output\n"
MARKUP = '<a href="http://x">y</a>'


def temporary_files(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.rglob("*") if p.name.endswith((".tmp", ".bak")))


def previous_outputs(directory: Path, *names: str) -> list[Path]:
    paths = [directory / name for name in names]
    for path in paths:
        path.write_bytes(OLD)
    return paths


def one_line(stderr: str) -> str:
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1, stderr
    assert "Traceback" not in stderr
    return lines[0]


# --- write-side environment errors ---------------------------------------------------------------


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes whatever the directory's permissions")
def test_a_read_only_output_directory_exits_2_and_keeps_the_previous_report(cli, sample, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (report,) = previous_outputs(out, "r.html")
    out.chmod(0o555)
    try:
        result = cli("analyze", sample("quad_healthy.mcap"), "-o", report, "-q")
    finally:
        out.chmod(0o755)
    assert result.exit_code == 2
    assert re.search(r"r\.html: cannot write the output: permission denied", one_line(result.stderr))
    assert report.read_bytes() == OLD and temporary_files(tmp_path) == []


def _failing(monkeypatch, name: str, code: int, inside: Path) -> None:
    """os.<name> raises OSError(code) for paths inside ``inside`` (the rest of the run is untouched)."""
    real = getattr(os, name)

    def fake(*args, **kwargs):
        if any(str(path).startswith(str(inside)) for path in args):
            raise OSError(code, os.strerror(code))
        return real(*args, **kwargs)

    monkeypatch.setattr(os, name, fake)


def test_a_read_only_file_system_exits_2_and_keeps_the_previous_outputs(cli, sample, tmp_path, monkeypatch):
    report, summary = previous_outputs(tmp_path, "r.html", "r.json")
    _failing(monkeypatch, "replace", errno.EROFS, tmp_path)
    result = cli("analyze", sample("quad_healthy.mcap"), "-o", report, "--json", summary, "-q")
    assert result.exit_code == 2
    line = one_line(result.stderr)
    assert "r.html" in line and "read-only" in line and "write the outputs to a writable location" in line
    assert report.read_bytes() == OLD and summary.read_bytes() == OLD
    assert temporary_files(tmp_path) == []


def test_disk_full_while_writing_exits_2_with_no_temporary_file_left(cli, sample, tmp_path, monkeypatch):
    report, summary = previous_outputs(tmp_path, "r.html", "r.json")
    monkeypatch.setattr(os, "fsync", lambda fd: (_ for _ in ()).throw(OSError(errno.ENOSPC, "No space left")))
    result = cli("analyze", sample("quad_healthy.mcap"), "-o", report, "--json", summary, "-q")
    assert result.exit_code == 2
    assert "no space left on the device (free some space" in one_line(result.stderr)
    assert report.read_bytes() == OLD and summary.read_bytes() == OLD
    assert temporary_files(tmp_path) == []


def test_a_file_size_limit_exits_2_instead_of_a_kill_by_sigxfsz(sample, tmp_path):
    """ulimit -f below the report's size (plotly.js embedded: ~5 MB; compiled kernels < 1 MB): the
    write fails with EFBIG (logscan ignores SIGXFSZ, whose default would kill it mid-write)."""
    import resource

    report, summary = previous_outputs(tmp_path, "r.html", "r.json")

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (2_000_000, 2_000_000))

    args = ["analyze", sample("quad_healthy.mcap"), "-o", report, "--json", summary, "-q"]
    proc = subprocess.run(
        [sys.executable, "-m", "logscan", *map(str, args)],
        preexec_fn=limit,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 2, proc.stderr
    assert "r.html: cannot write the output: file too large" in one_line(proc.stderr)
    assert report.read_bytes() == OLD and summary.read_bytes() == OLD
    assert temporary_files(tmp_path) == []


def test_a_failed_rename_puts_back_the_outputs_already_replaced(tmp_path, monkeypatch):
    first, second = previous_outputs(tmp_path, "a.html", "b.json")
    staged = [artifacts.stage(first, "new a"), artifacts.stage(second, "new b")]
    real = os.replace

    def fake(src, dst):
        if str(dst) == str(second):
            raise OSError(errno.EIO, "I/O error")
        return real(src, dst)

    monkeypatch.setattr(os, "replace", fake)
    with pytest.raises(artifacts.OutputError) as error:
        artifacts.commit(staged)
    assert error.value.one_line().startswith(f"{second}: cannot write the output: input/output error")
    assert first.read_bytes() == OLD and second.read_bytes() == OLD  # both or neither
    assert temporary_files(tmp_path) == []


def test_an_os_error_with_a_file_name_is_an_environment_error(cli, monkeypatch, tmp_path):
    from logscan.cli import inspect_cmd

    def no_memory(*args, **kwargs):
        raise OSError(errno.EMFILE, "Too many open files", str(tmp_path / "x"))

    monkeypatch.setattr(inspect_cmd, "read_facts", no_memory)
    result = cli("inspect", tmp_path / "x")
    assert result.exit_code == 2
    assert one_line(result.stderr).startswith(f"logscan: error: {tmp_path / 'x'}: Too many open files")

    def bug(*args, **kwargs):
        raise OSError(errno.EBADF, "Bad file descriptor")

    monkeypatch.setattr(inspect_cmd, "read_facts", bug)
    result = cli("inspect", tmp_path / "x")
    assert result.exit_code == 3 and "internal error" in result.stderr


# --- no clobbering ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "options",
    [
        ["-o", "{log}"],
        ["-o", "{link}"],
        ["--no-report", "--json", "{log}"],
        ["-o", "r.html", "--json", "{truth}"],
        ["-o", "{profile}"],
    ],
)
def test_an_output_equal_to_an_input_is_refused_before_any_work(cli, sample, tmp_path, options):
    log = tmp_path / "run.csv"
    shutil.copy(sample("quad_healthy.csv"), log)
    for suffix in (".truth.json", ".profile.toml"):
        shutil.copy(sample("quad_healthy.csv").with_suffix(suffix), log.with_suffix(suffix))
    link = tmp_path / "link.html"
    link.symlink_to(log)
    names = {"log": log, "link": link, "truth": log.with_suffix(".truth.json"), "profile": tmp_path / "p.html"}
    shutil.copy(log.with_suffix(".profile.toml"), names["profile"])
    before = {p: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    args = [str(tmp_path / a.format(**names)) if "{" in a or a.endswith(".html") else a for a in options]
    result = cli("analyze", log, "--profile", names["profile"], *args)
    assert result.exit_code == 2
    assert "would replace the input" in one_line(result.stderr)
    assert {p: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()} == before
    assert not (tmp_path / "r.html").exists()


def test_outputs_on_each_other_or_named_like_a_log_are_refused(cli, sample, tmp_path):
    log = sample("quad_healthy.mcap")
    same = cli("analyze", log, "-o", tmp_path / "r.html", "--json", tmp_path / "r.html")
    assert same.exit_code == 2 and "is the same file as --output" in one_line(same.stderr)
    other = tmp_path / "other.mcap"
    other.write_bytes(OLD)
    like_a_log = cli("analyze", log, "--no-report", "--json", other)
    assert like_a_log.exit_code == 2 and "named like a log" in one_line(like_a_log.stderr)
    assert other.read_bytes() == OLD
    inspect = cli("inspect", log, "--json", log)
    assert inspect.exit_code == 2 and "would replace the input" in one_line(inspect.stderr)
    evaluate = cli("evaluate", log, "--json", log)
    assert evaluate.exit_code == 2 and "would replace the input" in one_line(evaluate.stderr)
    simulate = cli("simulate", "dc_motor", "--duration", "5", "-q", "-o", tmp_path / "x.profile.toml")
    assert simulate.exit_code == 2 and "named like a profile" in one_line(simulate.stderr)


def test_two_logs_of_one_name_get_two_reports(cli, sample, tmp_path):
    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
        shutil.copy(sample("sbw_healthy.mcap"), tmp_path / folder / "run.mcap")
    out = tmp_path / "out"
    out.mkdir()
    result = cli("analyze", tmp_path / "a" / "run.mcap", tmp_path / "b" / "run.mcap", "-o", out, "-q", "--exit-zero")
    assert result.exit_code == 0, result.stderr
    names = ["a_run.report.html", "b_run.report.html", "index.html", "plotly.min.js"]  # plotly.js shared
    assert sorted(p.name for p in out.iterdir()) == names
    for folder in ("a", "b"):
        assert f"{folder}/run.mcap" in (out / f"{folder}_run.report.html").read_text(encoding="utf-8")


def test_report_names_stay_unique_when_folders_and_case_clash(tmp_path):
    assert unique_names(["a/x/run.mcap", "b/x/run.mcap", "c/y/run.mcap"], ".html") == [
        "x_run.html",
        "x_run-2.html",
        "y_run.html",
    ]
    assert unique_names(["d/Run.mcap", "d/run.ulg"], ".html") == ["d_Run.html", "d_run-2.html"]
    assert unique_names(["one.mcap", "two.mcap"], ".html") == ["one.html", "two.html"]
    paths = output_paths(["a/x/run.mcap", "b/x/run.mcap"], f"{tmp_path / 'o'}/")
    assert len(set(paths)) == 2


# --- Ctrl-C ---------------------------------------------------------------------------------------


def _interrupt_while_compiling(args: list, tmp_path: Path) -> subprocess.CompletedProcess:
    """Run `python -m logscan ARGS` with an empty kernel cache (the first run's compile takes
    seconds), send SIGINT once it says it is compiling, and wait for it."""
    env = dict(os.environ, LOGSCAN_CACHE_DIR=str(tmp_path / "cache"))
    proc = subprocess.Popen(
        [sys.executable, "-m", "logscan", *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    seen = []
    deadline = time.monotonic() + 60
    for line in proc.stderr:
        seen.append(line)
        if "compiling" in line or time.monotonic() > deadline:
            break
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    return subprocess.CompletedProcess(args, proc.returncode, out, "".join(seen) + err)


@pytest.mark.parametrize("jobs", [1, 2])
def test_ctrl_c_exits_130_and_leaves_the_previous_outputs(sample, tmp_path, jobs):
    out = tmp_path / "out"
    out.mkdir()
    logs = [sample("quad_healthy.mcap"), sample("sbw_healthy.mcap")][:jobs]
    names = [f"{Path(log).stem}.report.html" for log in logs]
    previous = previous_outputs(out, *names, "s.json")
    target = out if jobs > 1 else out / names[0]
    proc = _interrupt_while_compiling(
        ["analyze", *logs, "-o", target, "--json", out / "s.json", "--jobs", jobs], tmp_path
    )
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr.splitlines()[-1] == "logscan: interrupted"
    assert "Traceback" not in proc.stderr
    assert all(path.read_bytes() == OLD for path in previous)
    assert temporary_files(out) == []
    time.sleep(0.5)  # no worker or compiling child outlives the command
    assert not [pid for pid in _processes_mentioning(str(out))], "a logscan process survived"


def _processes_mentioning(text: str) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if text in (entry / "cmdline").read_bytes().decode(errors="replace"):
                    found.append(int(entry.name))
            except OSError:
                continue
    return found


# --- escaping -------------------------------------------------------------------------------------


def test_printable_escapes_control_characters_and_keeps_the_rest():
    assert printable("/imu\x1b[2J\x07") == "/imu\\x1b[2J\\x07"
    assert printable("a\u009bb\nc\td\u202ee") == "a\\x9bb\\x0ac\\x09d\\u202ee"
    assert printable("/ключ/∂x.y[2]") == "/ключ/∂x.y[2]"
    assert printable(printable("\x1b")) == "\\x1b"


def test_inspect_shows_escape_sequences_in_topic_names_escaped(cli, tmp_path):
    from logscan.readers.mcap.writer import TopicData, write_mcap

    path = tmp_path / "evil.mcap"
    t = np.arange(10, dtype=np.int64) * 10_000_000
    write_mcap(path, {"/imu\x1b[2J\x1b]0;owned\x07": TopicData("X", t, {"v\x9b1m": np.zeros(10)})}, encoding="json")
    result = cli("inspect", path, "--channels")
    assert result.exit_code == 0, result.stderr
    assert "\x1b" not in result.stdout and "\x07" not in result.stdout and "\x9b" not in result.stdout
    assert "/imu\\x1b[2J\\x1b]0;owned\\x07" in result.stdout
    assert "v\\x9b1m" in result.stdout


def markup_report():
    """A report whose detector, statistic and extra are named with a link in HTML."""
    from logscan.report import ReportInput
    from logscan.results import DetectorResult

    t = np.arange(200) * 0.1
    result = DetectorResult(f"det {MARKUP}")
    result.add_statistic(t, MARKUP, np.linspace(0, 2, 200), upper=1.5, n_persist=1)
    result.extras[f"{MARKUP}.per_dof"] = np.ones(200)
    return ReportInput(
        log_facts={"file": f"/logs/{MARKUP}.mcap", "topics": {MARKUP: {}}},
        profile_text="",
        profile_source="embedded",
        model={},
        logscan_version="0",
        t=t,
        results=[result],
    )


def test_names_from_logs_reach_plotly_as_text_never_as_links():
    from logscan.report import render_html

    page = render_html(markup_report(), plotlyjs_src="plotly.min.js")
    block = re.search(r'id="logscan-figures">(.*?)</script>', page, re.S).group(1)
    figures = [spec["figure"] for spec in json.loads(block)]
    texts = [trace["name"] for fig in figures for trace in fig["data"]]
    layouts = [fig["layout"] for fig in figures]
    texts += [layout["title"]["text"] for layout in layouts if "title" in layout]
    # a section figure's rows are titled by annotations: "<b>name</b> <span style=...>words</span>",
    # markup of logscan's own around the escaped names
    own_markup = re.compile(r"</?b>|<span style='[^'<>]*'>|</span>")
    texts += [own_markup.sub("", note["text"]) for layout in layouts for note in layout.get("annotations", [])]
    texts += [
        axis["title"]["text"]
        for layout in layouts
        for key, axis in layout.items()
        if key.startswith("yaxis") and isinstance(axis, dict) and "text" in axis.get("title", {})
    ]
    shown = [text for text in texts if "href" in text]
    assert len(shown) >= 4  # trace names, figure titles, axis titles
    assert all("<" not in text and ">" not in text for text in texts)
    assert '&lt;a href="http://x"&gt;y&lt;/a&gt;' in texts
    # the page's own HTML is autoescaped by jinja2: the name is never a live link there either
    assert MARKUP not in page and "&lt;a href=&#34;http://x&#34;&gt;y&lt;/a&gt;" in page


@pytest.mark.slow
def test_a_name_with_a_link_is_no_link_in_the_browser(tmp_path):
    """plotly draws <a href> in a legend or title as an SVG link: the name must stay text."""
    test_report_browser = pytest.importorskip("test_report_browser")
    if test_report_browser.CHROMIUM is None:
        pytest.skip("chromium not installed (Debian: apt-get install -y chromium)")
    from logscan.report import render_report

    page = tmp_path / "report.html"
    render_report(markup_report(), page, plotlyjs=tmp_path / "js")
    dom, _ = test_report_browser.dump_dom(page, tmp_path / "profile")
    assert 'data-plots-rendered="' in dom and test_report_browser.js_errors(dom) == ""
    assert "http://x" in dom  # the name is drawn...
    assert not re.search(r"<a\b[^>]*http://x", dom)  # ...never as a link
    assert '&lt;a href="http://x"&gt;y&lt;/a&gt;' in dom  # as the text it is, in legends and titles


def test_a_simulated_csv_and_its_sidecars_are_replaced_together_or_not_at_all(tmp_path, monkeypatch):
    """The CSV log, its truth and its profile: when the last cannot be written, none is replaced."""
    import errno

    from logscan import artifacts
    from logscan.simulate import output, simulate, write_simulation

    target = tmp_path / "run.csv"
    for name in ("run.csv", "run.truth.json", "run.profile.toml"):
        (tmp_path / name).write_text("previous")
    real_stage = artifacts.stage

    def failing_stage(path, data, **kwargs):
        if str(path).endswith(".profile.toml"):
            raise artifacts.output_error(OSError(errno.ENOSPC, "No space left on device"), path)
        return real_stage(path, data, **kwargs)

    monkeypatch.setattr(output, "stage", failing_stage)  # the simulator's own name for artifacts.stage
    sim = simulate("dc_motor", [], duration=2.0, seed=1)
    with pytest.raises(artifacts.OutputError):
        write_simulation(sim, target, "csv")
    assert all(
        (tmp_path / name).read_text() == "previous" for name in ("run.csv", "run.truth.json", "run.profile.toml")
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.csv", "run.profile.toml", "run.truth.json"]
    monkeypatch.setattr(output, "stage", real_stage)
    write_simulation(sim, target, "csv")
    assert all(
        (tmp_path / name).read_text() != "previous" for name in ("run.csv", "run.truth.json", "run.profile.toml")
    )


def test_a_killed_runs_temporary_files_are_removed_by_the_next_run(cli, sample, tmp_path):
    """SIGKILL leaves `.<name>.<pid>-<hex>.*.tmp` beside the outputs; the next run writing into that
    folder removes those of processes that are gone, whatever output they were for (and keeps a
    live process's, and fresh ones)."""
    log = tmp_path / "quad.mcap"
    log.write_bytes(Path(sample("quad_healthy.mcap")).read_bytes())
    dead = 2**22 + 12345  # above Linux's default pid_max: no such process
    orphan = tmp_path / f".r.html.{dead}-0badc0de.k3j2.tmp"
    young = tmp_path / f".r.json.{dead}-0badc0de.a1b2.tmp"
    alive = tmp_path / f".r.html.{os.getpid()}-12345678.zz.tmp"
    other = tmp_path / f".notes.txt.{dead}-0badc0de.q.tmp"
    for path in (orphan, young, alive, other):
        path.write_text("half a report")
    old = time.time() - 3600
    for path in (orphan, alive, other):
        os.utime(path, (old, old))
    result = cli("analyze", log, "-o", tmp_path / "r.html", "--json", tmp_path / "r.json", "-q")
    assert result.exit_code == 0, result.stderr
    assert not orphan.exists() and not other.exists()
    assert young.exists() and alive.exists()


def test_dev_null_may_take_the_report_and_the_json(cli, sample, tmp_path):
    log = tmp_path / "quad.mcap"
    log.write_bytes(Path(sample("quad_healthy.mcap")).read_bytes())
    result = cli("analyze", log, "-o", "/dev/null", "--json", "/dev/null", "-q")
    assert result.exit_code == 0, result.stderr
    assert Path("/dev/null").is_char_device()


def test_a_ctrl_c_a_finalizer_swallowed_still_exits_130_and_commits_nothing(sample, tmp_path, monkeypatch):
    """Ctrl-C raised while a finalizer runs (llvmlite's ObjectRef.__del__ during the compile) is
    swallowed by Python ("Exception ignored in ..."): the handler's flag still stops the run before
    its outputs are committed, no traceback is printed, and the exit code is 130."""
    import gc

    from logscan.cli import main as cli_main

    out = tmp_path / "r.html"
    (previous,) = previous_outputs(tmp_path, "r.html")

    class Finalized:
        def __del__(self):  # the handler raising where Python cannot propagate it
            cli_main._raise_interrupted(signal.SIGINT, None)

    real = cli_main.cli.main

    def interrupted_in_a_finalizer(*args, **kwargs):
        Finalized()
        gc.collect()
        return real(*args, **kwargs)

    monkeypatch.setattr(cli_main.cli, "main", interrupted_in_a_finalizer)
    with pytest.raises(SystemExit) as exit_info:
        cli_main.main(["analyze", sample("quad_healthy.mcap"), "-o", str(out), "-q"])
    assert exit_info.value.code == 130
    assert previous.read_bytes() == OLD and temporary_files(tmp_path) == []
    assert not cli_main._INTERRUPT_SEEN[0]  # reset once the run is reported
    assert sys.unraisablehook is not cli_main._unraisable  # Python's hook back


_HALF_CLOSED_AT_EXIT = """
import atexit, gc, os, signal, sys
from logscan.cli import main as cli_main


class HalfClosed:  # llvmlite's ObjectRef after a Ctrl-C between detach's two lines
    def __init__(self):
        self.cycle = self  # freed by the collector, whenever it next runs

    def __del__(self):
        raise AttributeError("'TypeRef' object has no attribute '_as_parameter_'")


def interrupted(*args, **kwargs):
    HalfClosed()
    os.kill(os.getpid(), signal.SIGINT)
    return real(*args, **kwargs)


real = cli_main.cli.main
cli_main.cli.main = interrupted
atexit.register(gc.collect)  # a collection while the process ends
sys.argv = ["logscan", *sys.argv[1:]]
cli_main.main()
"""


def test_a_finalizer_a_ctrl_c_left_half_done_fails_quietly_as_the_process_ends(sample, tmp_path):
    """CI once saw a Ctrl-C during the first run's compile end with exit 130 and, as the last line,
    the traceback of an llvmlite object's ``__del__`` the interruption had left half-closed: after
    a Ctrl-C the finalizers' errors are not printed, also while the process ends."""
    out = tmp_path / "r.html"
    (previous,) = previous_outputs(tmp_path, "r.html")
    args = ["analyze", sample("quad_healthy.mcap"), "-o", out, "-q"]
    proc = subprocess.run(
        [sys.executable, "-c", _HALF_CLOSED_AT_EXIT, *map(str, args)], capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr.splitlines() == ["logscan: interrupted"]
    assert previous.read_bytes() == OLD and temporary_files(tmp_path) == []


@pytest.mark.parametrize(("flags", "code"), [((), 1), (("--exit-zero",), 0)])
def test_a_commands_own_exit_code_ends_the_process_by_its_own_exit(sample, tmp_path, monkeypatch, flags, code):
    """`analyze` ends with ``sys.exit(code)`` (so that click's test runner reads the code): the
    console script still ends the process by `_exit_process` with that code, exit handlers run and
    streams flushed, not by Python's teardown of every module and object (0.2-0.35 s after a
    1-hour log, a fifth of a 10-minute log's analysis)."""
    from logscan.cli import main as cli_main

    ended = []
    monkeypatch.setattr(cli_main, "_exit_process", ended.append)  # returns: `main` then raises SystemExit
    monkeypatch.setattr(sys, "argv", ["logscan", "analyze", str(sample("quad_imu_bias.mcap")), "--no-report", "-q"])
    monkeypatch.setattr(sys, "argv", [*sys.argv, "--json", str(tmp_path / "s.json"), *flags])
    with pytest.raises(SystemExit) as exit_info:
        cli_main.main()
    assert ended == [code] and exit_info.value.code == code
    assert json.loads((tmp_path / "s.json").read_text())["logs"]


def test_commit_refuses_after_a_ctrl_c_and_removes_its_temporary_files(tmp_path):
    from logscan.errors import INTERRUPT_SEEN

    target = tmp_path / "s.json"
    target.write_text("old")
    staged = [artifacts.stage(target, "new")]
    INTERRUPT_SEEN[0] = True
    try:
        with pytest.raises(KeyboardInterrupt):
            artifacts.commit(staged)
    finally:
        INTERRUPT_SEEN[0] = False
    assert target.read_text() == "old" and temporary_files(tmp_path) == []


def test_a_sys_exit_with_words_says_them_and_exits_as_an_internal_error(monkeypatch, capsys):
    """``sys.exit("why")`` inside a command (a library giving up; plugins' calls are contained by
    their isolation): Python would print the words and exit 1, which a CI reads as alarms found;
    logscan prints them and exits 3."""
    from logscan.cli import main as cli_main

    def gives_up(**_):
        sys.exit("the model file is missing")

    monkeypatch.setattr(cli_main.cli, "main", gives_up)
    assert cli_main._run(["analyze"], debug=False) == 3
    assert capsys.readouterr().err == "logscan: error: the model file is missing\n"
