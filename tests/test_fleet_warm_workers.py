"""`--jobs` workers start with numba's compiler set up and the first log's kernels loaded: the parent
does both once before forking (`logscan.numba_cache.initialise_jit`, `AnalyzeTask.warm_up`), instead
of every worker paying for them on its first log (issue 29 item 5)."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from logscan.tasks import AnalyzeTask

SET_UP = "numba.np.arraymath"  # imported by numba's target registries, which initialise_jit loads
REPO = Path(__file__).resolve().parents[1]
SAMPLE = str(REPO / "sample_logs" / "quad_healthy.mcap")


def _python(code: str) -> list[str]:
    """The words ``code`` prints, run in a fresh interpreter (nothing loaded yet) from the repository."""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, cwd=REPO)
    assert result.returncode == 0, result.stderr
    return result.stdout.split()


def _compiler_was_set_up(_log: str) -> bool:
    return SET_UP in sys.modules


def test_initialise_jit_loads_the_registries_a_first_kernel_would():
    code = (
        "import sys\n"
        "import logscan.tasks\n"
        f"assert {SET_UP!r} not in sys.modules, 'already set up: the test would prove nothing'\n"
        "from logscan.numba_cache import initialise_jit\n"
        "initialise_jit()\n"
        f"print({SET_UP!r} in sys.modules)\n"
    )
    assert _python(code) == ["True"]


def test_jobs_workers_inherit_the_set_up_compiler():
    code = (
        "import sys\n"
        "sys.path.insert(0, 'tests')\n"
        "from test_fleet_warm_workers import SET_UP, _compiler_was_set_up\n"
        "from logscan.fleet import run_many\n"
        "assert SET_UP not in sys.modules\n"
        "print(run_many(['a', 'b', 'c'], _compiler_was_set_up, jobs=2, isolate=False))\n"
    )
    assert _python(code) == ["[True,", "True,", "True]"]


def _render(analysis, report_path) -> str:
    return ""


@dataclass(frozen=True)
class _KernelsAtStart(AnalyzeTask):
    """The analysis of one log that answers, besides, whether the EKF and the detectors' kernels were
    already loaded in its process when it started (before it loaded any)."""

    def __call__(self, item):
        from logscan.detectors.cusum import cusum_kernel
        from logscan.filters.ekf import ekf_run

        loaded = (len(ekf_run.overloads) > 0, len(cusum_kernel.overloads) > 0)
        return loaded, super().__call__(item).summary


def test_jobs_workers_start_with_the_first_logs_kernels_loaded():
    """`run_many` calls the task's ``warm_up`` before it forks (`AnalyzeTask.warm_up`): each worker's
    first log finds the EKF's and the detectors' kernels loaded, and the summaries are those of a
    log analysed alone."""
    code = (
        "import sys, json\n"
        "sys.path.insert(0, 'tests')\n"
        "from test_fleet_warm_workers import SAMPLE, _KernelsAtStart, _render\n"
        "from logscan.fleet import run_many\n"
        "task = _KernelsAtStart(None, None, False, None, render=_render)\n"
        "outcomes = run_many([(SAMPLE, None)] * 3, task, jobs=2, isolate=False)\n"
        "alone = task((SAMPLE, None))  # after the workers: they inherit nothing of it\n"
        "print(json.dumps([loaded for loaded, _ in outcomes]))\n"
        "print(all(summary == alone[1] for _, summary in outcomes))\n"
    )
    assert _python(code) == ["[[true,", "true],", "[true,", "true],", "[true,", "true]]", "True"]


def test_the_warm_up_leaves_one_thread_to_fork_from():
    """What `run_many` forks after: the warm-up loaded the kernels here and left no thread running
    (a fork copies only the forking thread: a lock another thread held would stay held in every
    worker)."""
    code = (
        "import sys, threading\n"
        "sys.path.insert(0, 'tests')\n"
        "from test_fleet_warm_workers import SAMPLE, _KernelsAtStart, _render\n"
        "from logscan.detectors.cusum import cusum_kernel\n"
        "from logscan.filters.ekf import ekf_run\n"
        "_KernelsAtStart(None, None, False, None, render=_render).warm_up([(SAMPLE, None)])\n"
        "print(len(ekf_run.overloads) > 0, len(cusum_kernel.overloads) > 0, threading.active_count())\n"
    )
    assert _python(code) == ["True", "True", "1"]


def test_a_log_with_a_built_in_profile_is_not_read_by_the_warm_up(monkeypatch):
    """A ROS bag's (or a ULog's) built-in profile is made by reading the log: the parent would read
    the fleet's first log whole, alone, before any worker starts. Its kernels are left to the
    workers; an MCAP's embedded profile is a metadata read, and its kernels load in the parent."""
    from logscan.pipeline import run

    profiles: list[str] = []
    monkeypatch.setattr(run, "load_profile_for", lambda path, profile_path, embedded=None: profiles.append(path))
    monkeypatch.setattr(run, "load_kernels", lambda *args, **kwargs: None)
    run.load_kernels_for(str(REPO / "sample_logs" / "husky_drive.bag"))
    assert profiles == []
    run.load_kernels_for(SAMPLE)  # the embedded profile: read (the stand-in returns None, then stops)
    assert profiles == [SAMPLE]
