"""The first run's compile: one EKF specialisation per model, compiled beside the reading."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from logscan.align import AlignedGroup, AlignedRun
from logscan.filters import run_ekf
from logscan.filters.ekf import ekf_run
from logscan.filters.warmup import COMPILING_NOTE
from logscan.models import get_model


def _tiny_run(model, steps=50):
    name, spec = next(iter(model.groups.items()))
    z = np.zeros((steps, spec.size))
    return AlignedRun(
        t=np.arange(steps) * 0.01,
        dt=0.01,
        start_ns=0,
        u=np.zeros((steps, model.n_inputs)),
        u_fresh=np.ones(steps, dtype=bool),
        input_channels=list(model.input_names),
        groups={name: AlignedGroup(name, list(spec.outputs), z, np.ones(steps, dtype=bool))},
    )


def test_each_model_gets_its_own_kernel_specialisation():
    for name in ("dc_motor", "steer_by_wire"):
        model = get_model(name)
        trace = run_ekf(model, _tiny_run(model))
        assert np.isfinite(trace.nis).any()
    literal_ids = {sig[0].literal_value for sig in ekf_run.signatures}
    assert {get_model("dc_motor").model_id, get_model("steer_by_wire").model_id} <= literal_ids


def test_repeated_runs_do_not_retype_the_kernel():
    model = get_model("dc_motor")
    run = _tiny_run(model)
    run_ekf(model, run)
    count = len(ekf_run.overloads)
    for _ in range(3):
        run_ekf(model, run)
    assert len(ekf_run.overloads) == count


@pytest.mark.slow
def test_cold_cache_compiles_only_the_logs_model_in_the_background(tmp_path, sample):
    """In a fresh cache: the note on stderr, the analysis right, and the cache then holds the
    quadcopter's kernel and not the dc_motor's."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), LOGSCAN_CACHE_DIR=str(tmp_path / "cache"))
    log = sample("quad_imu_bias.mcap")
    first = subprocess.run(
        [sys.executable, "-m", "logscan", "analyze", str(log), "--no-report"],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert first.returncode == 1, first.stderr
    assert COMPILING_NOTE in first.stderr
    assert "1 incident" in first.stdout
    probe = textwrap.dedent(
        """
        from logscan.filters.warmup import ekf_cached
        from logscan.models import get_model
        print(ekf_cached(get_model("quadcopter")), ekf_cached(get_model("dc_motor")))
        """
    )
    cached = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, timeout=120)
    assert cached.stdout.split() == ["True", "False"], cached.stderr
    second = subprocess.run(
        [sys.executable, "-m", "logscan", "analyze", str(log), "--no-report"],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert COMPILING_NOTE not in second.stderr
    assert second.stdout == first.stdout


@pytest.mark.slow
def test_the_filter_helpers_compiled_ahead_are_the_ones_the_kernel_calls(tmp_path):
    """In a fresh cache, the EKF kernel's compile alone gives each of FILTER_HELPERS exactly the
    signature the first run compiles ahead for it: else that head start compiles a version the
    kernel never calls, and the kernel's compile still pays for its own."""
    probe = textwrap.dedent(
        """
        import numpy as np
        from logscan.align import AlignedGroup, AlignedRun
        from logscan.filters import run_ekf, warmup
        from logscan.models import get_model

        model = get_model("dc_motor")
        name, spec = next(iter(model.groups.items()))
        run = AlignedRun(
            t=np.arange(3) * 0.01, dt=0.01, start_ns=0, u=np.zeros((3, model.n_inputs)),
            u_fresh=np.ones(3, dtype=bool), input_channels=list(model.input_names),
            groups={name: AlignedGroup(name, list(spec.outputs), np.zeros((3, spec.size)), np.ones(3, dtype=bool))},
        )
        run_ekf(model, run)
        for dispatcher, codes in warmup.FILTER_HELPERS:
            print(dispatcher.__name__, dispatcher.signatures == [warmup.helper_signature(codes)])
        """
    )
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), LOGSCAN_CACHE_DIR=str(tmp_path / "cache"))
    done = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    verdicts = dict(line.split() for line in done.stdout.splitlines())
    assert len(verdicts) == 18
    assert all(verdict == "True" for verdict in verdicts.values()), verdicts


@pytest.mark.slow
def test_the_kernels_compiled_after_the_ekf_compile_in_its_process(tmp_path):
    """On a cold cache, ``start_compile(model, after=...)`` runs ``after`` in the forked process,
    once the EKF kernel is compiled (the detectors' kernels, off the main process's critical path)."""
    probe = textwrap.dedent(
        f"""
        import os, sys
        from logscan.filters.warmup import ekf_cached, start_compile
        from logscan.models import get_model

        model = get_model("dc_motor")
        def after():
            with open({str(tmp_path / "after")!r}, "w") as fh:
                fh.write(f"{{os.getpid()}} {{ekf_cached(model)}}")
        compiling = start_compile(model, after=[after])
        assert compiling.in_background
        compiling.wait()
        print(os.getpid())
        """
    )
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), LOGSCAN_CACHE_DIR=str(tmp_path / "cache"))
    done = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    child_pid, cached = (tmp_path / "after").read_text().split()
    assert child_pid != done.stdout.strip()
    assert cached == "True"


def test_each_kernel_compiled_after_the_ekf_is_taken_by_one_process_only():
    """The first run's two processes split the kernels compiled after the EKF's: an item already
    claimed (by the other process) is skipped, the others are claimed and compiled here."""
    import multiprocessing

    from logscan.filters.warmup import _compile_unclaimed

    done: list[int] = []
    claims = multiprocessing.get_context("fork").Array("b", 3)
    claims[1] = 1  # the other process took the second
    _compile_unclaimed([lambda: done.append(0), lambda: done.append(1), lambda: done.append(2)], claims)
    assert done == [0, 2]
    assert list(claims) == [1, 1, 1]
    _compile_unclaimed([lambda: done.append(9)] * 3, claims)  # nothing left to take
    assert done == [0, 2]
