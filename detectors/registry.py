"""The detector registry: built-ins listed once by lazy "module:Class" strings, plus plugins from the
`logscan.detectors` entry-point group. A detector that fails to load is reported and skipped.

Adding a built-in detector is one line in BUILTIN_DETECTORS. A plugin package declares, in its
pyproject.toml:

    [project.entry-points."logscan.detectors"]
    range_check = "logscan_example_plugin:RangeCheckDetector"

Plugins are isolated: their code is imported only when a name no built-in provides is asked for, or
when everything is listed; whatever it raises while importing (SystemExit and KeyboardInterrupt
included) becomes a problem on its registry row, and whatever it prints goes to stderr.
"""

from __future__ import annotations

import contextlib
import importlib
import signal
import sys
import threading
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from logscan.detectors.base import Detector, describe
from logscan.detectors.params import describe_constraints
from logscan.errors import LogscanError, ProfileError, did_you_mean

ENTRY_POINT_GROUP = "logscan.detectors"

# Built-in detectors, one "module:Class" line each, imported only when the registry loads.
BUILTIN_DETECTORS: list[str] = [
    "logscan.detectors.encoded_ekf:EncodedEkfDetector",
    "logscan.detectors.nis:NisDetector",
    "logscan.detectors.cusum:CusumDetector",
    "logscan.detectors.frozen:FrozenSensorDetector",
    "logscan.detectors.atfm:AtfmDetector",
    "logscan.detectors.atfm_residual:AtfmResidualDetector",
    "logscan.detectors.ubikf_chi2:Chi2Detector",
    "logscan.detectors.kgn:KgnDetector",
    "logscan.detectors.px4_estimator:Px4EstimatorDetector",
    "logscan.detectors.health:HealthDetector",
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
    details: dict[str, Any] = field(default_factory=dict)  # read from the class while it loaded

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
            out.update(self.details)
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
    if not isinstance(obj.name, str) or not obj.name:
        raise TypeError(f"{obj.__name__} has an empty `name` class attribute")
    return obj


def _details(cls: type[Detector]) -> dict[str, Any]:
    """What `logscan detectors` shows of a class, read once while its loading is isolated."""
    return {
        "requires_fit": bool(cls.requires_fit),
        "requires_trace": bool(cls.requires_trace),
        "default_enabled": bool(cls.default_enabled),
        "defaults": dict(cls.defaults),
        "parameters": parameter_rows(cls),
    }


def _origin(ep: EntryPoint) -> str:
    dist = getattr(ep, "dist", None)
    if dist is None:
        return "plugin"
    return f"plugin {dist.metadata['Name']} {dist.version}"


def _exception_text(exc: BaseException) -> str:
    """'<Type>: <message>' (or '<Type>' when the message is empty) of an exception raised by loaded code."""
    try:
        message = str(exc)
    except BaseException:  # noqa: BLE001 - its __str__ is the failing code's too
        message = "(message unavailable)"
    return f"{type(exc).__name__}: {message}" if message else type(exc).__name__


@contextlib.contextmanager
def _user_interrupts() -> Iterator[list[bool]]:
    """Yield a flag set when a real SIGINT (the user's Ctrl-C) arrives inside the block; the previous
    handler still runs, so Ctrl-C still raises KeyboardInterrupt. Outside the main thread, or when
    SIGINT has no Python handler, nothing is installed: no SIGINT can then raise there, so every
    KeyboardInterrupt seen in the block was raised by code."""
    seen = [False]
    on_main = threading.current_thread() is threading.main_thread()
    previous = signal.getsignal(signal.SIGINT) if on_main else None
    if not callable(previous):
        yield seen
        return

    def handler(signum: int, frame: Any) -> None:
        seen[0] = True
        previous(signum, frame)

    signal.signal(signal.SIGINT, handler)
    try:
        yield seen
    finally:
        signal.signal(signal.SIGINT, previous)


def _isolated(call: Callable[[], Any], passthrough: tuple[type[BaseException], ...] = ()) -> tuple[Any, str]:
    """Run plugin code: (its value, "") or (None, "<Type>: <message>"); never raises for what the code
    does, except the ``passthrough`` exceptions (logscan's typed errors it may raise on purpose).

    Everything the code throws is caught, SystemExit and KeyboardInterrupt included, and everything
    it prints goes to stderr (stdout may hold `--json -`). The one exception told apart is the
    user's Ctrl-C: a KeyboardInterrupt counts as the user's only when a real SIGINT arrived while
    the code ran (see _user_interrupts); it is re-raised, even if the code swallowed it."""
    with _user_interrupts() as interrupted:
        try:
            with contextlib.redirect_stdout(sys.stderr):
                value = call()
        except passthrough:
            raise
        except BaseException as exc:  # noqa: BLE001 - whatever plugin code throws is reported, never raised
            if interrupted[0] and isinstance(exc, KeyboardInterrupt):
                raise
            if interrupted[0]:
                raise KeyboardInterrupt from exc
            return None, _exception_text(exc)
    if interrupted[0]:
        raise KeyboardInterrupt
    return value, ""


def _load_class(loader: Callable[[], Any]) -> tuple[type[Detector], dict[str, Any]]:
    """Import a detector class with ``loader``, check it and read what the listing shows of it."""
    cls = _check_class(loader())
    return cls, {"description": describe(cls), **_details(cls)}


def _configured(cls: type[Detector], config: dict | None, source: str | None) -> Detector:
    """An instance of ``cls`` from ``config``, its parameters checked (ProfileError naming ``source``)."""
    detector = cls.from_config(config)
    try:
        detector.check_params()
    except ProfileError as exc:
        if exc.path is None:
            exc.path = source
        raise
    return detector


class Registry:
    """Detectors by name. Loading never raises: failures become entries with problems.

    builtins: "module:Class" strings (default BUILTIN_DETECTORS), all imported on the first query.
    plugins:  entry points to load, or None to read the installed `logscan.detectors` group; loaded
              only when a name no built-in provides is asked for or everything is listed.
    """

    def __init__(self, builtins: Iterable[str] | None = None, plugins: Iterable[EntryPoint] | None = None):
        self._builtins = list(BUILTIN_DETECTORS if builtins is None else builtins)
        self._plugins = None if plugins is None else list(plugins)
        self._entries: list[DetectorEntry] = []
        self._taken: dict[str, DetectorEntry] = {}
        self._builtins_loaded = False
        self._plugins_loaded = False

    # --- loading ----------------------------------------------------------------------------------
    def _add(self, entry: DetectorEntry, loader: Callable[[], Any], fallback_name: str = "") -> None:
        loaded, problem = _isolated(lambda: _load_class(loader))
        self._entries.append(entry)
        if loaded is None:
            entry.name = entry.name or fallback_name
            entry.problems.append(f"failed to load: {problem}")
            return
        cls, details = loaded
        if entry.name and entry.name != cls.name:
            entry.problems.append(f"entry point is named {entry.name!r} but the class's name is {cls.name!r}")
        entry.name = cls.name
        entry.description = details.pop("description")
        entry.details = details
        if cls.name in self._taken:
            taken = self._taken[cls.name]
            entry.problems.append(
                f"duplicate name {cls.name!r}: already provided by {taken.origin} ({taken.spec}); skipped"
            )
            return
        if entry.origin != BUILTIN and details["default_enabled"]:
            entry.problems.append("default_enabled is ignored for plugins: it runs only when a profile enables it")
        if entry.origin != BUILTIN:  # its fit and run are isolated (`logscan.detectors.isolation`)
            cls.plugin_origin = entry.origin
        entry.cls = cls
        self._taken[cls.name] = entry

    def _load(self, plugins: bool = True) -> list[DetectorEntry]:
        """The entries loaded so far: every built-in, and the plugins too when ``plugins``."""
        if not self._builtins_loaded:
            self._builtins_loaded = True
            for spec in self._builtins:
                # a built-in that fails to load is listed under its module's name
                module_name = spec.rpartition(":")[0].rpartition(".")[2]
                self._add(
                    DetectorEntry(name="", spec=spec, origin=BUILTIN), lambda spec=spec: _import_spec(spec), module_name
                )
        if plugins and not self._plugins_loaded:
            self._plugins_loaded = True
            found = self._plugins if self._plugins is not None else list(entry_points(group=ENTRY_POINT_GROUP))
            for ep in sorted(found, key=lambda e: (_origin(e), e.name)):
                self._add(DetectorEntry(name=ep.name, spec=ep.value, origin=_origin(ep)), ep.load)
        return self._entries

    def _find(self, name: str) -> list[DetectorEntry]:
        """The entries named ``name``: the built-ins' when one of them provides it, else every loaded one
        (loading the plugins)."""
        found = [e for e in self._load(plugins=False) if e.name == name]
        if not any(e.ok for e in found):
            found = [e for e in self._load() if e.name == name]
        return found

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
        """The detector class registered as ``name``; ProfileError when unknown or broken. Plugins are
        imported only when no built-in provides ``name``."""
        found = self._find(name)
        for entry in found:
            if entry.ok:
                return entry.cls  # type: ignore[return-value]
        if found:
            raise ProfileError(
                f"detector {name!r} ({found[0].origin}) is installed but could not be loaded: "
                f"{'; '.join(found[0].problems)}",
                hint="run `logscan detectors` to see every detector and its problems",
            )
        raise ProfileError(
            f"unknown detector {name!r}",
            hint=f"{did_you_mean(name, self.names())}available: {', '.join(self.names()) or 'none'} "
            "(see `logscan detectors`)",
        )

    def origin(self, name: str) -> str | None:
        """Where detector ``name`` comes from: "built-in" or "plugin <distribution> <version>" (or
        "plugin" for an entry point without a distribution); None when no loaded detector has that name."""
        return next((e.origin for e in self._find(name) if e.ok), None)

    def create(self, name: str, config: dict | None = None, *, source: str | None = None) -> Detector:
        """An instance of detector ``name`` from its configuration, its parameters checked against
        their declared types and ranges (ProfileError naming ``source``, the profile, otherwise).
        A plugin's constructor and checks run isolated: what else they raise becomes a ProfileError
        naming the plugin."""
        cls = self.get(name)
        origin = self.origin(name)
        if origin == BUILTIN:
            return _configured(cls, config, source)
        detector, problem = _isolated(lambda: _configured(cls, config, source), passthrough=(LogscanError,))
        if problem:
            raise ProfileError(
                f"detector {name!r} ({origin}) failed to start: {problem}",
                path=source,
                hint="a bug in the plugin: report it to its authors, or remove the detector from the profile",
            )
        return detector

    def builtin_names(self) -> list[str]:
        """The built-in detectors that loaded (never imports plugin code)."""
        return [e.name for e in self._load(plugins=False) if e.ok and e.origin == BUILTIN]

    def plugin_entry_names(self) -> list[str]:
        """The names of the installed plugins' entry points, read from their metadata (never imports
        plugin code)."""
        found = self._plugins if self._plugins is not None else list(entry_points(group=ENTRY_POINT_GROUP))
        return sorted({ep.name for ep in found})

    def default_names(self) -> list[str]:
        """The detectors that run when a profile enables none: the built-ins with default_enabled.
        Plugins are never default-enabled (their default_enabled is ignored and reported): a plugin
        runs only when a profile or --detectors names it, so this never imports plugin code."""
        return [e.name for e in self._load(plugins=False) if e.ok and e.origin == BUILTIN and e.cls.default_enabled]

    def __contains__(self, name: str) -> bool:
        return any(e.ok for e in self._find(name))


_DEFAULT: Registry | None = None


def default_registry(refresh: bool = False) -> Registry:
    """The process-wide registry of built-ins and installed plugins (loaded as needed, once)."""
    global _DEFAULT
    if _DEFAULT is None or refresh:
        _DEFAULT = Registry()
    return _DEFAULT
