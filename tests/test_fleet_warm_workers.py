"""`--jobs` workers start with numba's compiler set up: the parent does it once before forking
(`logscan.numba_cache.initialise_jit`), instead of every worker paying 0.4-1 s for it on its first
kernel (issue 29 item 5)."""

from __future__ import annotations

import subprocess
import sys

SET_UP = "numba.np.arraymath"  # imported by numba's target registries, which initialise_jit loads


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
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "True"


def test_jobs_workers_inherit_the_set_up_compiler():
    code = (
        "import sys\n"
        "sys.path.insert(0, 'tests')\n"
        "from test_fleet_warm_workers import SET_UP, _compiler_was_set_up\n"
        "from logscan.fleet import run_many\n"
        "assert SET_UP not in sys.modules\n"
        "print(run_many(['a', 'b', 'c'], _compiler_was_set_up, jobs=2, isolate=False))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[True, True, True]"
