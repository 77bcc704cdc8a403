"""`pytest --campaign=full` draws FULL_CAMPAIGN_FACTOR times the examples of each property test
(tests/conftest.py); the default CI size draws each test's own max_examples."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest
from conftest import FULL_CAMPAIGN_FACTOR, full_campaign
from hypothesis import given, settings
from hypothesis import strategies as st


def counting_test(examples: int):
    drawn = []

    @settings(max_examples=examples, database=None, derandomize=True)
    @given(st.integers())
    def prop(x):
        drawn.append(x)

    return prop, drawn


def test_full_campaign_multiplies_the_examples_once_per_test_function():
    prop, drawn = counting_test(7)
    items = [SimpleNamespace(obj=prop, nodeid="prop[a]"), SimpleNamespace(obj=prop, nodeid="prop[b]")]
    full_campaign(items, 3)  # two items of one parametrised test: scaled once, not twice
    prop()
    assert prop._hypothesis_internal_use_settings.max_examples == 21
    assert 7 < len(drawn) <= 21


def test_plain_tests_are_left_alone():
    def plain():
        pass

    full_campaign([SimpleNamespace(obj=plain, nodeid="plain")], 3)
    assert not hasattr(plain, "_hypothesis_internal_use_settings")


def test_the_option_defaults_to_the_ci_size(pytestconfig):
    assert pytestconfig.getoption("campaign") in ("ci", "full")
    assert FULL_CAMPAIGN_FACTOR > 1
    if pytestconfig.getoption("campaign") == "ci":
        prop, _ = counting_test(5)
        assert prop._hypothesis_internal_use_settings.max_examples == 5


@settings(max_examples=4, database=None)
@given(st.integers())
def test_a_property_test_draws_its_campaign_size(x):
    """Run by the test below: appends a line per example to $CAMPAIGN_EXAMPLES_FILE."""
    if os.environ.get("CAMPAIGN_EXAMPLES_FILE"):
        with open(os.environ["CAMPAIGN_EXAMPLES_FILE"], "a", encoding="utf-8") as out:
            out.write(f"{x}\n")
    assert isinstance(x, int)


@pytest.mark.parametrize("size, drawn", [("ci", range(1, 5)), ("full", range(5, 4 * FULL_CAMPAIGN_FACTOR + 1))])
def test_the_option_sizes_the_property_tests(tmp_path, size, drawn):
    examples = tmp_path / "examples"
    env = dict(os.environ, CAMPAIGN_EXAMPLES_FILE=str(examples))
    env.pop("LOGSCAN_CAMPAIGN", None)
    test = f"{Path(__file__).name}::test_a_property_test_draws_its_campaign_size"
    command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", f"--campaign={size}", test]
    done = subprocess.run(command, cwd=Path(__file__).parent, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert len(examples.read_text(encoding="utf-8").splitlines()) in drawn
