"""The detector registry: lazy built-ins, entry-point plugins, broken plugins reported and skipped,
and the `logscan detectors` command."""

from __future__ import annotations

import json
from importlib.metadata import EntryPoint

import pytest

from logscan.cli.render import render_detectors
from logscan.detectors.base import Detector
from logscan.detectors.registry import BUILTIN, ENTRY_POINT_GROUP, Registry, default_registry
from logscan.errors import ProfileError

HERE = __name__


class AlphaDetector(Detector):
    """Alpha: a detector used by the registry tests.

    More text that is not part of the description.
    """

    name = "alpha"
    defaults = {"level": 1.0}


class BetaDetector(Detector):
    """Beta: another test detector."""

    name = "beta"


class AlphaAgainDetector(Detector):
    """Claims alpha's name."""

    name = "alpha"


class NamelessDetector(Detector):
    """Forgets its name."""


class NotADetector:
    """Looks like one, is not one."""

    name = "impostor"


def ep(name: str, attr: str, module: str = HERE) -> EntryPoint:
    return EntryPoint(name=name, value=f"{module}:{attr}", group=ENTRY_POINT_GROUP)


def test_builtins_load_lazily_by_spec_with_description():
    registry = Registry(builtins=[f"{HERE}:AlphaDetector"], plugins=[])
    (entry,) = registry.entries()
    assert (entry.name, entry.origin, entry.ok) == ("alpha", BUILTIN, True)
    assert entry.description == "Alpha: a detector used by the registry tests."
    assert registry.get("alpha") is AlphaDetector
    detector = registry.create("alpha", {"level": 2.5})
    assert isinstance(detector, AlphaDetector) and detector.level == 2.5


def test_broken_builtin_is_reported_under_its_module_name_and_skipped():
    registry = Registry(builtins=["logscan.detectors.not_written_yet:Thing", f"{HERE}:BetaDetector"], plugins=[])
    assert registry.names() == ["beta"]
    (warning,) = registry.warnings()
    assert warning.startswith("not_written_yet (built-in): failed to load: ModuleNotFoundError")
    with pytest.raises(ProfileError, match="could not be loaded"):
        registry.get("not_written_yet")


def test_plugins_load_after_builtins():
    registry = Registry(builtins=[f"{HERE}:AlphaDetector"], plugins=[ep("beta", "BetaDetector")])
    assert registry.names() == ["alpha", "beta"]
    assert registry.entries()[1].origin == "plugin"  # a hand-made entry point has no distribution


@pytest.mark.parametrize(
    "bad, problem",
    [
        (ep("gone", "Missing", module="no_such_plugin_module"), "ModuleNotFoundError"),
        (ep("gone", "NoSuchClass"), "AttributeError"),
        (ep("impostor", "NotADetector"), "not a subclass of logscan.detectors.base.Detector"),
        (ep("nameless", "NamelessDetector"), "empty `name`"),
        (EntryPoint(name="bad", value="not a spec", group=ENTRY_POINT_GROUP), "failed to load"),
    ],
)
def test_broken_plugin_is_reported_and_never_breaks_the_others(bad, problem):
    registry = Registry(builtins=[f"{HERE}:AlphaDetector"], plugins=[bad, ep("beta", "BetaDetector")])
    assert registry.names() == ["alpha", "beta"]
    (warning,) = registry.warnings()
    assert problem in warning
    broken = [e for e in registry.entries() if not e.ok]
    assert len(broken) == 1 and broken[0].name == bad.name


def test_duplicate_name_keeps_the_builtin_and_reports_the_plugin():
    registry = Registry(builtins=[f"{HERE}:AlphaDetector"], plugins=[ep("alpha", "AlphaAgainDetector")])
    assert registry.get("alpha") is AlphaDetector
    (warning,) = registry.warnings()
    assert "duplicate name 'alpha'" in warning and "skipped" in warning


def test_entry_point_name_differing_from_class_name_is_noted_but_loads():
    registry = Registry(builtins=[], plugins=[ep("b", "BetaDetector")])
    assert registry.names() == ["beta"]
    assert "named 'b' but the class's name is 'beta'" in registry.warnings()[0]


def test_unknown_detector_names_the_available_ones():
    registry = Registry(builtins=[f"{HERE}:AlphaDetector"], plugins=[])
    with pytest.raises(ProfileError, match="unknown detector 'gamma'") as info:
        registry.get("gamma")
    assert "alpha" in info.value.one_line()
    assert "alpha" in registry and "gamma" not in registry


def test_default_registry_has_no_broken_builtins():
    registry = default_registry(refresh=True)
    assert [w for w in registry.warnings() if "(built-in)" in w] == []


def test_render_lists_name_origin_description_and_problems():
    registry = Registry(builtins=[f"{HERE}:AlphaDetector"], plugins=[ep("impostor", "NotADetector")])
    text = render_detectors([e.to_dict() for e in registry.entries()])
    lines = text.splitlines()
    assert lines[0].split() == ["name", "origin", "description"]
    assert lines[1].split()[:2] == ["alpha", "built-in"]
    assert "impostor" in lines[2] and "BROKEN" in lines[2]
    assert "problems:" in lines and any("not a subclass" in line for line in lines)


def test_detectors_command_json(monkeypatch, cli):
    registry = Registry(builtins=[f"{HERE}:AlphaDetector"], plugins=[ep("gone", "Nope")])
    monkeypatch.setattr("logscan.detectors.registry._DEFAULT", registry)
    result = cli("detectors", "--json", "-")
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert [d["name"] for d in data["detectors"]] == ["alpha", "gone"]
    assert data["detectors"][0]["defaults"] == {"level": 1.0}
    assert data["detectors"][1]["ok"] is False and len(data["warnings"]) == 1


def test_detectors_command_text(monkeypatch, cli):
    registry = Registry(builtins=[f"{HERE}:BetaDetector"], plugins=[])
    monkeypatch.setattr("logscan.detectors.registry._DEFAULT", registry)
    result = cli("detectors")
    assert result.exit_code == 0
    assert "beta" in result.output and "Beta: another test detector." in result.output
