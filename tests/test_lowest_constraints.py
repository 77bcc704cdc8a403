"""The constraints .ci/run installs the lowest dependency versions with (.ci/lowest_constraints.py):
every direct dependency of pyproject.toml pinned to its one `>=` floor."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import tomllib

import pytest
from conftest import REPO

SCRIPT = REPO / ".ci" / "lowest_constraints.py"


def load_script():
    spec = importlib.util.spec_from_file_location("lowest_constraints", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_dependency_is_pinned_to_its_floor():
    dependencies = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]["dependencies"]
    printed = subprocess.run([sys.executable, str(SCRIPT)], capture_output=True, text=True, check=True).stdout
    pins = [line for line in printed.splitlines() if not line.startswith("#")]
    assert len(pins) == len(dependencies)
    for requirement, pin in zip(dependencies, pins):
        name, floor = pin.split("==")
        assert requirement.startswith(name) and f">={floor}" in requirement.replace(" ", ""), (requirement, pin)


@pytest.mark.parametrize(
    ("requirement", "pin"),
    [
        ("numpy>=1.26", "numpy==1.26"),
        ("dask[distributed] >= 2024.1", "dask==2024.1"),
        ("scipy>=1.11.1,<2", "scipy==1.11.1"),
        ("tomli>=2.0; python_version < '3.11'", "tomli==2.0"),
    ],
)
def test_a_requirement_becomes_its_floor(requirement, pin):
    assert load_script().lowest_pins([requirement]) == [pin]


@pytest.mark.parametrize("requirement", ["numpy", "numpy<2", "numpy==1.26", "numpy>=1.26,>=1.27"])
def test_a_requirement_without_one_floor_is_refused(requirement, tmp_path):
    with pytest.raises(ValueError, match="needs exactly one '>=' lower bound"):
        load_script().lowest_pins([requirement])
    pyproject = tmp_path / "pyproject.toml"
    pyproject.write_text(f'[project]\ndependencies = ["{requirement}"]\n', encoding="utf-8")
    refused = subprocess.run([sys.executable, str(SCRIPT), str(pyproject)], capture_output=True, text=True)
    assert refused.returncode == 2 and refused.stdout == ""
    assert refused.stderr.count("\n") == 1 and "needs exactly one '>=' lower bound" in refused.stderr
