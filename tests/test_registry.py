"""The detector registry: lazy built-ins, entry-point plugins, broken plugins reported and skipped,
plugins isolated (their exits, interrupts and prints at import) and imported only when needed, and
the `logscan detectors` command."""

from __future__ import annotations

import json
import sys
import textwrap
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


# --- plugins isolated ---------------------------------------------------------------------------


@pytest.fixture
def plugin_module(tmp_path, monkeypatch):
    """An entry point to a plugin module written from ``source`` into a folder on sys.path."""
    monkeypatch.syspath_prepend(tmp_path)
    written = []

    def make(name: str, source: str, attr: str = "Plugin") -> EntryPoint:
        module = f"logscan_test_plugin_{name}"
        (tmp_path / f"{module}.py").write_text(textwrap.dedent(source))
        written.append(module)
        return ep(name, attr, module=module)

    yield make
    for module in written:
        sys.modules.pop(module, None)


class TripwireEntryPoint(EntryPoint):
    """An entry point that records every attempt to import it (then fails to load)."""

    loads: list[str] = []

    def load(self):
        TripwireEntryPoint.loads.append(self.name)
        raise RuntimeError("this plugin should not have been imported")


@pytest.fixture
def tripwire():
    TripwireEntryPoint.loads = []
    yield TripwireEntryPoint(name="tripwire", value="never:Imported", group=ENTRY_POINT_GROUP)
    TripwireEntryPoint.loads = []


def test_plugin_exiting_at_import_is_a_problem_not_an_exit(plugin_module):
    exiting = plugin_module("exiting", "import sys\nsys.exit(0)\n")
    registry = Registry(builtins=[f"{HERE}:AlphaDetector"], plugins=[exiting, ep("beta", "BetaDetector")])
    assert registry.names() == ["alpha", "beta"]
    assert registry.warnings() == ["exiting (plugin): failed to load: SystemExit: 0"]
    with pytest.raises(ProfileError, match=r"'exiting' \(plugin\) is installed but could not be loaded"):
        registry.get("exiting")


def test_plugin_raising_keyboard_interrupt_at_import_is_a_problem(plugin_module):
    interrupting = plugin_module("interrupting", "raise KeyboardInterrupt\n")
    registry = Registry(builtins=[], plugins=[interrupting, ep("beta", "BetaDetector")])
    assert registry.names() == ["beta"]
    assert registry.warnings() == ["interrupting (plugin): failed to load: KeyboardInterrupt"]


@pytest.mark.parametrize("swallowed", [False, True], ids=["raised", "swallowed by the plugin"])
def test_real_ctrl_c_while_a_plugin_imports_still_interrupts(plugin_module, swallowed):
    # a SIGINT delivered while the plugin's code runs is the user's: it stops logscan
    source = "import signal\nsignal.raise_signal(signal.SIGINT)\n"
    if swallowed:
        source = "import signal\ntry:\n    signal.raise_signal(signal.SIGINT)\nexcept KeyboardInterrupt:\n    pass\n"
    registry = Registry(builtins=[], plugins=[plugin_module("slow", source)])
    with pytest.raises(KeyboardInterrupt):
        registry.entries()


def test_plugin_printing_at_import_leaves_stdout_empty(plugin_module, capsys):
    chatty = plugin_module(
        "chatty",
        """
        from logscan.detectors.base import Detector
        print("hello from a plugin")

        class Plugin(Detector):
            \"\"\"Chatty: prints when imported.\"\"\"

            name = "chatty"
        """,
    )
    registry = Registry(builtins=[], plugins=[chatty])
    assert registry.names() == ["chatty"]
    captured = capsys.readouterr()
    assert captured.out == ""
    assert "hello from a plugin" in captured.err


def test_plugins_are_not_imported_when_only_builtins_are_asked_for(tripwire):
    registry = Registry(builtins=[f"{HERE}:AlphaDetector"], plugins=[tripwire])
    assert registry.get("alpha") is AlphaDetector
    assert isinstance(registry.create("alpha"), AlphaDetector)
    assert registry.origin("alpha") == BUILTIN and "alpha" in registry
    assert registry.default_names() == []
    assert TripwireEntryPoint.loads == []
    assert registry.names() == ["alpha"]  # listing everything imports the plugins
    assert TripwireEntryPoint.loads == ["tripwire"]


def test_plugins_are_imported_for_a_name_no_builtin_provides(tripwire):
    registry = Registry(builtins=[f"{HERE}:AlphaDetector"], plugins=[tripwire, ep("beta", "BetaDetector")])
    assert registry.get("beta") is BetaDetector
    assert TripwireEntryPoint.loads == ["tripwire"]


def test_origin_names_builtin_or_plugin():
    registry = Registry(builtins=[f"{HERE}:AlphaDetector"], plugins=[ep("beta", "BetaDetector")])
    assert [registry.origin(n) for n in ("alpha", "beta", "gamma")] == [BUILTIN, "plugin", None]


class ExitingOnCreateDetector(Detector):
    """Exits when created."""

    name = "exiting_on_create"

    def __init__(self, **params):
        print("creating")
        raise SystemExit(1)


def test_plugin_failing_when_created_is_named_in_a_profile_error(capsys):
    registry = Registry(builtins=[], plugins=[ep("exiting_on_create", "ExitingOnCreateDetector")])
    with pytest.raises(ProfileError) as info:
        registry.create("exiting_on_create", source="quad.toml")
    assert info.value.one_line().startswith(
        "quad.toml: detector 'exiting_on_create' (plugin) failed to start: SystemExit: 1"
    )
    assert capsys.readouterr().out == ""


def test_plugin_profile_errors_pass_through_create():
    registry = Registry(builtins=[], plugins=[ep("alpha", "AlphaDetector")])
    with pytest.raises(ProfileError, match="unknown parameter") as info:
        registry.create("alpha", {"levle": 2}, source="quad.toml")
    assert info.value.path == "quad.toml"


class EagerDetector(Detector):
    """Eager: a plugin that asks to run by default."""

    name = "eager"
    default_enabled = True


def test_default_names_never_include_plugins():
    registry = Registry(builtins=[], plugins=[ep("eager", "EagerDetector")])
    assert registry.names() == ["eager"]  # plugins loaded; still not a default
    assert registry.default_names() == []
    assert "default_enabled is ignored for plugins" in registry.warnings()[0]


def test_detectors_command_lists_broken_plugins_and_exits_0(monkeypatch, cli, plugin_module):
    plugins = [
        plugin_module("exiting", "import sys\nsys.exit(0)\n"),
        plugin_module("interrupting", "print('noise')\nraise KeyboardInterrupt\n"),
    ]
    monkeypatch.setattr(
        "logscan.detectors.registry._DEFAULT", Registry(builtins=[f"{HERE}:BetaDetector"], plugins=plugins)
    )
    result = cli("detectors")
    assert result.exit_code == 0
    assert "  exiting (plugin): failed to load: SystemExit: 0" in result.stdout.splitlines()
    assert "  interrupting (plugin): failed to load: KeyboardInterrupt" in result.stdout.splitlines()
    assert "noise" not in result.stdout and "noise" in result.stderr


def test_detectors_command_json_stays_pure_with_a_printing_plugin(monkeypatch, cli, plugin_module):
    chatty = plugin_module("chatty", "print('hello from a plugin')\nraise ImportError('no numpy')\n")
    monkeypatch.setattr("logscan.detectors.registry._DEFAULT", Registry(builtins=[], plugins=[chatty]))
    result = cli("detectors", "--json", "-")
    assert result.exit_code == 0
    assert json.loads(result.stdout)["warnings"] == ["chatty (plugin): failed to load: ImportError: no numpy"]


def test_analyze_is_unaffected_by_a_broken_plugin_it_does_not_use(monkeypatch, cli, sample, plugin_module, tripwire):
    log = sample("quad_healthy.mcap")
    exiting = plugin_module("exiting", "import sys\nprint('plugin noise')\nsys.exit(0)\n")
    monkeypatch.setattr("logscan.detectors.registry._DEFAULT", Registry())
    clean = cli("analyze", log, "--no-report", "--json", "-")
    monkeypatch.setattr("logscan.detectors.registry._DEFAULT", Registry(plugins=[exiting, tripwire]))
    result = cli("analyze", log, "--no-report", "--json", "-")
    assert (clean.exit_code, result.exit_code) == (0, 0)
    (with_plugin,), (without,) = json.loads(result.stdout)["logs"], json.loads(clean.stdout)["logs"]
    for key in ("verdict", "n_alarms", "detectors", "exit_code"):
        assert with_plugin[key] == without[key], key
    assert [d["detector"] for d in with_plugin["detectors"]] == ["encoded_ekf", "nis", "cusum", "frozen"]
    assert TripwireEntryPoint.loads == []


def test_analyze_naming_a_broken_plugin_blames_the_plugin(monkeypatch, cli, sample, plugin_module):
    exiting = plugin_module("exiting", "import sys\nsys.exit(0)\n")
    monkeypatch.setattr("logscan.detectors.registry._DEFAULT", Registry(plugins=[exiting]))
    result = cli("analyze", sample("quad_healthy.mcap"), "--no-report", "-d", "exiting")
    assert result.exit_code == 2
    assert "'exiting' (plugin) is installed but could not be loaded: failed to load: SystemExit: 0" in result.stderr
