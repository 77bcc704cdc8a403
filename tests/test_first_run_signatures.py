"""The first run compiles each kernel once: one signature per kernel after analysing a sample log,
the kernels compiled ahead (while the EKF compiles in its own process) for the types the analysis
then passes them."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from numba import njit, types

from logscan.filters.warmup import kernel_compilers
from logscan.numba_cache import OneSignature
from logscan.pipeline.preparation import load_profile_for
from logscan.pipeline.stages import create_detectors

# compiled for several signatures on purpose: the model's f with and without its Jacobian
# (want_A a literal: the f-only version drops the Jacobian's code)
SEVERAL_ON_PURPOSE = {"logscan.models.quadcopter_kernels.quad_fA_nonzeros"}

PROBE = textwrap.dedent(
    """
    import gc, sys
    from numba.core.dispatcher import Dispatcher
    from logscan.filters.warmup import _compile_ekf, kernel_compilers
    from logscan.models import get_model
    from logscan.pipeline import analyze_log
    from logscan.pipeline.preparation import load_profile_for
    from logscan.pipeline.stages import create_detectors
    from logscan.verdict.observability import compile_kernel

    log = sys.argv[1]
    loaded = load_profile_for(log, None)
    detectors = create_detectors(loaded, None)
    # what the first run compiles ahead, then the analysis itself, in one process
    model = get_model(loaded.profile.vehicle.model, loaded.profile.vehicle.params)
    _compile_ekf(model)
    compile_kernel(model, 0.01)
    for compile_kernels in kernel_compilers(detectors):
        compile_kernels()
    analyze_log(log)
    for obj in gc.get_objects():
        if isinstance(obj, Dispatcher) and obj.py_func.__module__.startswith("logscan"):
            name = obj.py_func.__module__ + "." + obj.py_func.__qualname__
            print(name, len(obj.signatures))
    """
)


@pytest.mark.parametrize("cache", ["shared", pytest.param("empty", marks=pytest.mark.slow)])
def test_analysing_a_sample_log_compiles_each_kernel_for_one_signature(sample, tmp_path, cache):
    """In a fresh process: the kernels compiled ahead and those the analysis of a log with a fault in
    its ground truth (so the observability verdict runs) then calls hold one signature each. With
    the tests' shared cache the kernels mostly load (their callees are not typed again); with an
    empty one everything compiles, the callees too (a literal argument shows there)."""
    env = dict(os.environ)
    if cache == "empty":
        env["NUMBA_CACHE_DIR"] = env["LOGSCAN_CACHE_DIR"] = str(tmp_path / "cache")
    done = subprocess.run(
        [sys.executable, "-c", PROBE, str(sample("quad_imu_bias.mcap"))],
        capture_output=True,
        text=True,
        timeout=900,
        env=env,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    counts = dict(line.rsplit(" ", 1) for line in done.stdout.splitlines())
    assert "logscan.verdict.observability_kernel.signature_evidence" in counts
    assert "logscan.detectors.cusum.cusum_kernel" in counts
    several = {name: n for name, n in counts.items() if int(n) > 1 and name not in SEVERAL_ON_PURPOSE}
    assert several == {}


def test_one_signature_runs_a_contiguous_and_a_strided_column_with_one_compile():
    @njit
    def double_into(src, dst):
        for i in range(src.size):
            dst[i] = 2.0 * src[i]

    one = OneSignature(double_into, (types.float64[::1], types.float64[:]))
    src = np.arange(3.0)
    whole, columns = np.zeros(3), np.zeros((3, 2))
    one(src, whole)
    one(src, columns[:, 1])
    assert whole.tolist() == [0.0, 2.0, 4.0]
    assert columns[:, 1].tolist() == [0.0, 2.0, 4.0]
    assert len(double_into.signatures) == 1


def test_kernel_compilers_of_the_default_detectors_cover_the_modules_they_call_kernels_from(sample):
    loaded = load_profile_for(sample("quad_imu_bias.mcap"), None)
    modules = {f.__module__ for f in kernel_compilers(create_detectors(loaded, None))}
    # encoded_ekf's band (adaptive_threshold), cusum's and frozen's own kernels
    assert {
        "logscan.detectors.adaptive_threshold",
        "logscan.detectors.cusum",
        "logscan.detectors.frozen",
    } <= modules
