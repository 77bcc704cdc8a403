"""The detector registry: built-ins listed once by lazy "module:Class" strings, plus plugins from the
`logscan.detectors` entry-point group. A detector that fails to load is reported and skipped.

Adding a built-in detector is one line in BUILTIN_DETECTORS. A plugin package declares, in its
pyproject.toml:

    [project.entry-points."logscan.detectors"]
    range_check = "logscan_example_plugin:RangeCheckDetector"
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from logscan.detectors.base import Detector, describe
from logscan.detectors.params import describe_constraints
from logscan.errors import ProfileError

ENTRY_POINT_GROUP = "logscan.detectors"

# Built-in detectors, one "module:Class" line each, imported only when the registry loads.
BUILTIN_DETECTORS: list[str] = [
    "logscan.detectors.encoded_ekf:EncodedEkfDetector",
    "logscan.detectors.nis:NisDetector",
]

BUILTIN = "built-in"


@dataclass
class DetectorEntry:
    """One registry row: a loaded detector class, or a detector that failed to load (cls None)."""

    name: str
    spec: str  # "module:Class"
    origin: str  # "built-in" or "plugin <distribution> <version>"
    cls: type[Detector] | None = None
    description: str = ""
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.cls is not None

    def to_dict(self) -> dict[str, Any]:
        out = {
            "name": self.name,
            "origin": self.origin,
            "spec": self.spec,
            "ok": self.ok,
            "description": self.description,
            "problems": list(self.problems),
        }
        if self.cls is not None:
            out.update(
                requires_fit=self.cls.requires_fit,
                requires_trace=self.cls.requires_trace,
                default_enabled=self.cls.default_enabled,
                defaults=dict(self.cls.defaults),
                parameters=parameter_rows(self.cls),
            )
        return out


def parameter_rows(cls: type[Detector]) -> list[dict[str, Any]]:
    """One row per parameter: name, default and its declared constraints as text."""
    return [
        {
            "name": key,
            "default": default,
            "constraints": describe_constraints(cls.parameter_constraints[key])
            if key in cls.parameter_constraints
            else "any JSON value",
        }
        for key, default in cls.defaults.items()
    ]


def _import_spec(spec: str) -> Any:
    module_name, _, attr = spec.partition(":")
    if not module_name or not attr:
        raise ValueError(f"{spec!r} is not of the form 'module:Class'")
    obj = importlib.import_module(module_name)
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj


def _check_class(obj: Any) -> type[Detector]:
    if not (isinstance(obj, type) and issubclass(obj, Detector)):
        raise TypeError(f"{obj!r} is not a subclass of logscan.detectors.base.Detector")
    if not obj.name:
        raise TypeError(f"{obj.__name__} has an empty `name` class attribute")
    return obj


def _origin(ep: EntryPoint) -> str:
    dist = getattr(ep, "dist", None)
    if dist is None:
        return "plugin"
    return f"plugin {dist.metadata['Name']} {dist.version}"


class Registry:
    """Detectors by name. Loading never raises: failures become entries with problems.

    builtins: "module:Class" strings (default BUILTIN_DETECTORS).
    plugins:  entry points to load, or None to read the installed `logscan.detectors` group.
    """

    def __init__(self, builtins: Iterable[str] | None = None, plugins: Iterable[EntryPoint] | None = None):
        self._builtins = list(BUILTIN_DETECTORS if builtins is None else builtins)
        self._plugins = None if plugins is None else list(plugins)
        self._entries: list[DetectorEntry] | None = None

    # --- loading ----------------------------------------------------------------------------------
    def _load(self) -> list[DetectorEntry]:
        if self._entries is not None:
            return self._entries
        entries: list[DetectorEntry] = []
        taken: dict[str, DetectorEntry] = {}

        def add(entry: DetectorEntry, loader: Callable[[], Any], fallback_name: str = "") -> None:
            try:
                cls = _check_class(loader())
            except Exception as exc:  # noqa: BLE001 - any plugin failure is reported, never raised
                entry.name = entry.name or fallback_name
                entry.problems.append(f"failed to load: {type(exc).__name__}: {exc}")
                entries.append(entry)
                return
            if entry.name and entry.name != cls.name:
                entry.problems.append(f"entry point is named {entry.name!r} but the class's name is {cls.name!r}")
            entry.name = cls.name
            entry.description = describe(cls)
            if cls.name in taken:
                entry.problems.append(
                    f"duplicate name {cls.name!r}: already provided by {taken[cls.name].origin} "
                    f"({taken[cls.name].spec}); skipped"
                )
                entries.append(entry)
                return
            entry.cls = cls
            taken[cls.name] = entry
            entries.append(entry)

        for spec in self._builtins:
            # a built-in that fails to load is listed under its module's name
            module_name = spec.rpartition(":")[0].rpartition(".")[2]
            add(DetectorEntry(name="", spec=spec, origin=BUILTIN), lambda spec=spec: _import_spec(spec), module_name)
        plugins = self._plugins
        if plugins is None:
            plugins = list(entry_points(group=ENTRY_POINT_GROUP))
        for ep in sorted(plugins, key=lambda e: (_origin(e), e.name)):
            add(DetectorEntry(name=ep.name, spec=ep.value, origin=_origin(ep)), ep.load)
        self._entries = entries
        return entries

    # --- queries ----------------------------------------------------------------------------------
    def entries(self) -> list[DetectorEntry]:
        """Every built-in and plugin, loaded or not, built-ins first."""
        return list(self._load())

    def names(self) -> list[str]:
        """Names of the detectors that loaded, in registry order."""
        return [e.name for e in self._load() if e.ok]

    def warnings(self) -> list[str]:
        """One line per problem: '<name> (<origin>): <problem>'."""
        return [f"{e.name} ({e.origin}): {p}" for e in self._load() for p in e.problems]

    def get(self, name: str) -> type[Detector]:
        """The detector class registered as ``name``; ProfileError when unknown or broken."""
        for entry in self._load():
            if entry.name == name and entry.ok:
                return entry.cls  # type: ignore[return-value]
        broken = [e for e in self._load() if e.name == name]
        if broken:
            raise ProfileError(
                f"detector {name!r} is installed but could not be loaded: {'; '.join(broken[0].problems)}",
                hint="run `logscan detectors` to see every detector and its problems",
            )
        raise ProfileError(
            f"unknown detector {name!r}",
            hint=f"available: {', '.join(self.names()) or 'none'} (see `logscan detectors`)",
        )

    def create(self, name: str, config: dict | None = None, *, source: str | None = None) -> Detector:
        """An instance of detector ``name`` from its configuration, its parameters checked against
        their declared types and ranges (ProfileError naming ``source``, the profile, otherwise)."""
        detector = self.get(name).from_config(config)
        try:
            detector.check_params()
        except ProfileError as exc:
            if exc.path is None:
                exc.path = source
            raise
        return detector

    def default_names(self) -> list[str]:
        """The detectors that run when a profile enables none (those with default_enabled)."""
        return [e.name for e in self._load() if e.ok and e.cls.default_enabled]

    def __contains__(self, name: str) -> bool:
        return name in self.names()


_DEFAULT: Registry | None = None


def default_registry(refresh: bool = False) -> Registry:
    """The process-wide registry of built-ins and installed plugins (loaded once)."""
    global _DEFAULT
    if _DEFAULT is None or refresh:
        _DEFAULT = Registry()
    return _DEFAULT
