"""docs/detectors.md, the newcomer's overview of the detectors, names every built-in detector and
every vehicle model, so that a detector or model added to the code is added to the page too."""

from __future__ import annotations

import re
from pathlib import Path

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
