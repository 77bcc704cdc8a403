"""docs/detectors.md, the newcomer's overview of the detectors, names every built-in detector and
every vehicle model, so that a detector or model added to the code is added to the page too."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from logscan.detectors.registry import BUILTIN, Registry
from logscan.models import MODEL_NAMES

PAGE = (Path(__file__).resolve().parents[1] / "docs" / "detectors.md").read_text(encoding="utf-8")


def described_detectors(text: str) -> set[str]:
    """The detectors a bullet of the page's list starts with (`- `a` and `b`: ...`)."""
    heads = re.findall(r"^ ?- (`[a-z0-9_]+`(?: and `[a-z0-9_]+`)*):", text, re.M)
    return {name for head in heads for name in re.findall(r"`([a-z0-9_]+)`", head)}


def test_every_builtin_detector_has_its_bullet():
    builtins = {entry.name for entry in Registry(plugins=[]).entries() if entry.origin == BUILTIN}
    assert "nis" in builtins
    missing = builtins - described_detectors(PAGE)
    assert not missing, f"docs/detectors.md has no bullet ' - `name`: ...' for {sorted(missing)}"


def test_every_model_is_named_in_the_shared_ekf_section():
    section = PAGE.split("## Models and the shared EKF", 1)[1].split("\n## ", 1)[0]
    assert [m for m in MODEL_NAMES if f"`{m}`" not in section] == []


def test_the_bullet_parser_reads_single_and_paired_heads():
    text = " - `nis`: the test\n - `atfm` and `atfm_residual`: tables\n - not `a_bullet`: here\n"
    assert described_detectors(text) == {"nis", "atfm", "atfm_residual"}


def _documented_profiles() -> dict[str, list[str]]:
    """The "Which detectors run" table: built-in profile -> the detectors it runs (its cell's first
    sentence, before any parenthesis)."""
    rows = re.findall(r"^\| `([a-z0-9_]+)` \(`[^`]+`\) \| [^|]+ \| ([^|]+) \|$", PAGE, re.M)
    return {name: re.findall(r"`([a-z0-9_]+)`", cell.split("(")[0]) for name, cell in rows}


def test_the_page_says_which_detectors_run_by_default_as_the_registry_does():
    """It said `cusum` and `frozen` were "Enabled by default", while the px4 profile every PX4 log
    gets runs nis, px4_estimator and health: the defaults apply only to a profile enabling none."""
    assert "Enabled by default" not in PAGE
    section = PAGE.split("## Which detectors run", 1)[1].split("\n## ", 1)[0]
    rule = next(line for line in section.splitlines() if line.startswith("3. "))
    rule += section.split(rule, 1)[1].split("\n\n", 1)[0]
    assert re.findall(r"`([a-z0-9_]+)`", rule.split(":", 1)[1]) == Registry(plugins=[]).default_names()


def test_the_page_lists_the_detectors_each_builtin_profile_writes():
    root = Path(__file__).resolve().parents[1] / "logscan" / "profiles"
    documented = _documented_profiles()
    assert set(documented) == {"px4", "ros", "ros_wheeled"}
    for name, module in (("px4", "builtin.py"), ("ros", "ros.py"), ("ros_wheeled", "ros_wheeled.py")):
        written = re.findall(r"\[detectors\.([a-z0-9_]+)\]", (root / module).read_text(encoding="utf-8"))
        assert documented[name] == written, (name, written)


@pytest.mark.testdata("px4-ulog")
def test_the_px4_profile_of_a_real_log_runs_the_documented_detectors():
    from conftest import need_testdata

    from logscan.pipeline import builtin_profile_for
    from logscan.profiles import parse_profile

    built = builtin_profile_for(need_testdata("px4-ulog/sample_px4_events.ulg"))
    assert parse_profile(built.text).enabled_detectors() == _documented_profiles()["px4"]
