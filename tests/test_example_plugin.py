"""The example plugin in examples/logscan-example-plugin: declared as a `logscan.detectors` entry point,
loadable through the registry like an installed plugin, and its own tests pass."""

from __future__ import annotations

import subprocess
import sys
import tomllib

import numpy as np
from test_detector_contract import EXAMPLE_ENTRY_POINT, EXAMPLE_PLUGIN, example_plugin_entry_point, synthetic_run

from logscan.detectors.registry import ENTRY_POINT_GROUP, Registry


def test_pyproject_declares_the_entry_point_group():
    data = tomllib.loads((EXAMPLE_PLUGIN / "pyproject.toml").read_text())
    assert data["project"]["entry-points"][ENTRY_POINT_GROUP] == {"range_check": EXAMPLE_ENTRY_POINT}
    assert "logscan" in data["project"]["dependencies"]


def test_registry_loads_the_plugin_through_its_entry_point():
    registry = Registry(builtins=[], plugins=[example_plugin_entry_point()])
    assert registry.names() == ["range_check"] and registry.warnings() == []
    (entry,) = registry.entries()
    assert entry.origin.startswith("plugin")
    assert entry.description.startswith("Flags measurement samples outside their allowed range")


def test_plugin_detector_catches_a_bit_flip_burst_after_training_on_healthy_runs():
    registry = Registry(builtins=[], plugins=[example_plugin_entry_point()])
    detector = registry.create("range_check").fit([synthetic_run(1), synthetic_run(2)])
    assert detector.run(synthetic_run(4)).alarms == []
    alarms = detector.run(synthetic_run(3, burst=True)).alarms
    assert [(a.signal, round(a.start, 2), round(a.end, 2)) for a in alarms] == [("/imu/acc.x", 2.5, 2.61)]
    assert alarms[0].peak_value == 1e20


def test_plugin_uses_model_ranges_when_given_a_model():
    class Spec:
        range_lo, range_hi = (-20.0, -20.0, -20.0), (20.0, 20.0, 20.0)

    class Model:
        groups = {"accel": Spec()}

    registry = Registry(builtins=[], plugins=[example_plugin_entry_point()])
    result = registry.create("range_check").run(synthetic_run(3, burst=True), model=Model())
    assert [a.signal for a in result.alarms] == ["/imu/acc.x"]
    assert "no range for 3 channel(s)" in result.warnings[0]  # the position group has no range
    assert np.isnan(result.series["/imu/acc.x"]).sum() == 0


def test_plugin_own_tests_pass():
    # a separate pytest process: the plugin's suite runs with its own rootdir and imports, as its author runs it
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(EXAMPLE_PLUGIN / "tests")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
