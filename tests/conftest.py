"""Shared test fixtures: one in-process CLI runner, and the paths of the repository's sample logs.

`cli("analyze", LOG, "--json", "-")` runs `logscan` through its real entry point (`logscan.cli.main.main`,
so errors become exit codes and one-line messages exactly as in a shell) inside the test process:
no interpreter start-up and numba kernels compiled once per session. A few end-to-end tests still
run `python -m logscan` in a subprocess through `cli_process` (tests/test_cli_errors.py) or install
the package (tests/test_readme.py; `installed_wheel`, the built wheel in a fresh venv outside the
checkout, tests/test_wheel_install.py).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from hypothesis import settings

import logscan  # noqa: F401 - sets NUMBA_CACHE_DIR (numba_cache_dir)

# CI must not fail at random: property tests draw the same examples on every run (a seed per test).
# HYPOTHESIS_PROFILE=explore draws fresh ones, to search for new failures locally.
settings.register_profile("ci", derandomize=True, print_blob=True)
settings.register_profile("explore", derandomize=False, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

REPO = Path(__file__).resolve().parents[1]
SAMPLES = REPO / "sample_logs"
TESTDATA = REPO.parent / "shared" / "testdata"
# Set (to anything but "" or "0") by .ci/run: missing shared test data fails the tests that need
# it instead of skipping them, so CI cannot pass without having run them.
REQUIRE_TESTDATA = "LOGSCAN_REQUIRE_TESTDATA"


def one_state_profile(thrust: str, accel: str, name: str = "one state") -> str:
    """A linear one-state profile TOML: one input channel and one accelerometer channel (the
    smallest profile a ULog or hand-made log can be analysed with)."""
    return f"""\
name = "{name}"
[vehicle]
model = "linear"
rate_hz = 100
[vehicle.params]
A = [[0.0]]
B = [[0.0]]
C = {{ accel = [[1.0]] }}
R = {{ accel = [1.0] }}
inputs = ["thrust"]
states = ["az"]
[inputs]
thrust = "{thrust}"
stale_s = 0.5
[measurements.accel]
channels = ["{accel}"]
rate_hz = 100
"""


def need_testdata(path: str | os.PathLike = "") -> Path:
    """Path of shared test data: ``../shared/testdata/PATH`` (or ``PATH`` itself when absolute).

    When it is missing (or an empty directory) the test is skipped, or fails with a clear message
    when ``LOGSCAN_REQUIRE_TESTDATA`` is set. Module-level lists of files can use the marker
    ``@pytest.mark.testdata("px4-ulog")`` instead (checked before the test runs).
    """
    found = Path(path) if Path(path).is_absolute() else TESTDATA / path
    missing = not found.exists() or (found.is_dir() and not any(found.iterdir()))
    if missing:
        message = f"shared test data missing: {found}"
        if os.environ.get(REQUIRE_TESTDATA, "") not in ("", "0"):
            pytest.fail(f"{message} ({REQUIRE_TESTDATA} is set: provide ../shared/testdata)", pytrace=False)
        pytest.skip(message)
    return found


def pytest_configure(config):
    config.addinivalue_line("markers", "testdata(path): needs ../shared/testdata/PATH (skips, or fails in CI)")


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item):
    # before pytest's own skip marks: a test parametrised over an empty list of shared files
    # must fail in CI, not skip as "got empty parameter set"
    for marker in item.iter_markers("testdata"):
        need_testdata(*marker.args)


# --- the whole suite on every core -----------------------------------------------------------------
# The README's test command (pytest without arguments: the testpaths) runs on every core with
# pytest-xdist, one test module per worker at a time, so that a module's fixtures are built once; a
# run of chosen files or tests (-k) stays in one process unless -n is given. The modules that take
# longest start first, so that the last ones are short and both workers end together. The fuzz
# seeds' warm-up comes second, beside the README's run, which like the wheel's after it compiles
# into a cache of its own: in a fresh clone it fills the shared kernel cache alone (the docs
# examples then start from it), not while another worker compiles the same kernels. A session
# fixture is built once per worker: one too costly to build twice (installed_wheel, fuzz) is used by
# the tests of one module only. The tests of a module whose fixtures cost little but whose tests
# take minutes each go to any worker.
SLOWEST_MODULES_FIRST = (
    "test_readme.py",
    "test_fuzz.py",
    "test_wheel_install.py",
    "test_docs_examples.py",
    "test_first_run_signatures.py",  # an analysis compiled from an empty kernel cache
    "test_extending.py",  # the pendulum's, from an empty cache too
    "test_warmup.py",  # and the first run's
)
TESTS_TO_ANY_WORKER = ("test_docs_examples.py",)


@pytest.hookimpl(tryfirst=True)
def pytest_cmdline_main(config):
    if hasattr(config, "workerinput") or not config.pluginmanager.hasplugin("xdist"):
        return
    chosen = config.args_source is not pytest.Config.ArgsSource.TESTPATHS or config.option.keyword
    if config.option.numprocesses is not None or chosen:  # -n given, or chosen files or tests (-k)
        return
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if cores > 1 and not config.getoption("usepdb", False):
        config.option.numprocesses = cores
        config.option.dist = "loadfile"
        config.option.loadscopereorder = False  # in the order of pytest_collection_modifyitems


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """xdist's loadfile, but each test of TESTS_TO_ANY_WORKER a unit of its own."""
    if config.option.dist != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class ModulesOrTests(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::", 1)[0]
            return nodeid if Path(module).name in TESTS_TO_ANY_WORKER else module

    return ModulesOrTests(config, log)


def pytest_collection_modifyitems(config, items):
    if config.getoption("campaign") == "full":
        full_campaign(items, FULL_CAMPAIGN_FACTOR)
    if hasattr(config, "workerinput"):  # an xdist worker: the controller hands modules out in this order
        rank = {name: i for i, name in enumerate(SLOWEST_MODULES_FIRST)}
        items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: the rest keep their order


# --- campaign size -----------------------------------------------------------------------------------
# The property tests (hypothesis) and the fuzz tests (tests/test_fuzz.py) draw their own max_examples:
# the CI size. `pytest --campaign=full` (or LOGSCAN_CAMPAIGN=full) draws FULL_CAMPAIGN_FACTOR times as
# many, to search longer before a release; bench/fuzz_campaign.py is the fuzzer's long campaign.
FULL_CAMPAIGN_FACTOR = 10


def pytest_addoption(parser):
    parser.addoption(
        "--campaign",
        choices=("ci", "full"),
        default=os.environ.get("LOGSCAN_CAMPAIGN") or "ci",
        help=f"property and fuzz tests: ci (their own max_examples) or full ({FULL_CAMPAIGN_FACTOR} times as many)",
    )


def full_campaign(items, factor: int) -> None:
    """Multiply the max_examples of every hypothesis test among ``items`` by ``factor`` (once per
    test function: the items of a parametrised test share it)."""
    scaled = set()
    for item in items:
        test = getattr(getattr(item, "obj", None), "__func__", getattr(item, "obj", None))
        if getattr(test, "is_hypothesis_test", False) and test not in scaled:
            own = getattr(test, "_hypothesis_internal_use_settings", None)  # hypothesis's own attribute
            if own is None:
                raise pytest.UsageError(f"--campaign=full cannot find the settings of {item.nodeid}")
            test._hypothesis_internal_use_settings = settings(own, max_examples=own.max_examples * factor)
            scaled.add(test)


@dataclass
class CliResult:
    """Exit code and captured streams of one in-process `logscan` run."""

    exit_code: int
    stdout: str
    stderr: str

    @property
    def output(self) -> str:
        return self.stdout


@pytest.fixture
def cli(capsys):
    """Run `logscan ARGS...` in-process; returns a CliResult."""
    from logscan.cli.main import main

    def invoke(*args) -> CliResult:
        capsys.readouterr()  # drop anything printed before the command
        try:
            main([str(a) for a in args])
            code = 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        captured = capsys.readouterr()
        return CliResult(int(code), captured.out, captured.err)

    return invoke


@pytest.fixture
def cli_process():
    """Run `python -m logscan ARGS...` in a subprocess (a real process's exit code and streams:
    nothing can hide in the test process); returns a CliResult."""
    import subprocess
    import sys

    def invoke(*args, timeout: float = 300) -> CliResult:
        proc = subprocess.run(
            [sys.executable, "-m", "logscan", *(str(a) for a in args)], capture_output=True, text=True, timeout=timeout
        )
        return CliResult(proc.returncode, proc.stdout, proc.stderr)

    return invoke


@pytest.fixture
def sample():
    """Path of a shipped sample log by name; skips when it is missing."""

    def path(name: str) -> Path:
        found = SAMPLES / name
        if not found.exists():
            pytest.skip(f"{found} missing (run sample_logs/make_samples.py)")
        return found

    return path


@pytest.fixture(autouse=True)
def _ctrl_c_is_the_users():
    """Each test starts with Python's own Ctrl-C handler. A test that leaves SIGINT ignored (seen
    once in the full suite, not reproduced alone) would make every later subprocess inherit the
    ignore, and the Ctrl-C tests (tests/test_outputs.py, tests/test_registry.py) fail for a reason
    that is not theirs."""
    import signal

    if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    yield


@dataclass(frozen=True)
class InstalledWheel:
    """logscan as a user gets it: the wheel `pip wheel` builds from the tracked files, installed
    with its dependencies into a fresh venv outside the checkout (tests/test_wheel_install.py)."""

    wheel: Path
    venv: Path
    workdir: Path  # outside the checkout: run from here, nothing of the checkout is importable
    env: dict[str, str]  # no checkout or dev venv on any path; this session's kernel cache

    def run(self, *args: str | os.PathLike, timeout: float = 900) -> subprocess.CompletedProcess:
        """`logscan ARGS...` from the venv's bin/, in workdir."""
        command = [str(self.venv / "bin" / "logscan"), *(str(a) for a in args)]
        return subprocess.run(command, cwd=self.workdir, env=self.env, capture_output=True, text=True, timeout=timeout)

    def python(self, code: str) -> subprocess.CompletedProcess:
        command = [str(self.venv / "bin" / "python"), "-c", code]
        return subprocess.run(command, cwd=self.workdir, env=self.env, capture_output=True, text=True, timeout=300)


def clean_env(cache_dir: Path) -> dict[str, str]:
    """This process's environment without the dev venv, PYTHONPATH or an explicit numba cache, and
    with logscan's cache (compiled kernels) in cache_dir."""
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHONPATH", "NUMBA_CACHE_DIR")}
    env["PATH"] = os.pathsep.join(
        p for p in env.get("PATH", "").split(os.pathsep) if ".venv" not in p and "/venv/" not in p
    )
    env["LOGSCAN_CACHE_DIR"] = str(cache_dir)
    return env


def numba_cache_dir() -> Path:
    """The folder this session's logscan compiles its kernels into (set by `import logscan`)."""
    return Path(os.environ["NUMBA_CACHE_DIR"])


def copy_tracked_files(dest: Path) -> None:
    """The files git tracks (as they are in the working tree) copied to dest: what a clean clone has."""
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True).stdout
    for rel in filter(None, listed.decode().split("\0")):
        src = REPO / rel
        if src.is_file():
            (dest / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / rel)


@pytest.fixture(scope="session")
def installed_wheel(tmp_path_factory) -> InstalledWheel:
    """Build the wheel once from a copy of the tracked files, install it with its dependencies into
    a fresh venv in a temporary directory outside the checkout (session-scoped: tests share it)."""
    if shutil.which("git") is None or not (REPO / ".git").exists():
        pytest.skip("needs a git checkout to build the wheel from the tracked files")
    root = tmp_path_factory.mktemp("wheel")
    assert REPO not in root.resolve().parents, f"{root} is inside the checkout"
    source, wheels, venv, workdir = root / "source", root / "dist", root / "venv", root / "work"
    workdir.mkdir()
    copy_tracked_files(source)
    env = clean_env(root / "cache")
    # the kernels this session compiled already: numba's cache files a kernel by its sources, not
    # by where they are installed (logscan.numba_cache.relocate), so the wheel's identical sources
    # load them instead of compiling every model again (6-7 minutes of a CI run)
    env.pop("LOGSCAN_CACHE_DIR")
    env["NUMBA_CACHE_DIR"] = str(numba_cache_dir())

    def step(*command: str | os.PathLike) -> None:
        done = subprocess.run([str(c) for c in command], cwd=workdir, env=env, capture_output=True, text=True)
        assert done.returncode == 0, (command, done.stdout[-2000:], done.stderr[-3000:])

    step(sys.executable, "-m", "pip", "wheel", source, "-w", wheels, "--no-deps", "-q")
    (wheel,) = wheels.glob("logscan-*.whl")
    step(sys.executable, "-m", "venv", venv)
    # --no-compile: byte-compiling numpy, scipy and pandas at install time is most of an install's
    # CPU; the modules logscan imports are compiled on first import instead
    step(venv / "bin" / "python", "-m", "pip", "install", "-q", "--no-compile", wheel)
    return InstalledWheel(wheel=wheel, venv=venv, workdir=workdir, env=env)
