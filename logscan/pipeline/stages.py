"""What the pipeline of one log is made of, below its orchestration (`logscan.pipeline`) and the
further control loops (`logscan.pipeline.loops`), which both use them: the filters (`FILTERS`), a loaded
profile (`LoadedProfile`), a prepared log (`Prepared`), the detectors a profile runs
(`create_detectors`) and the union of their needs (`needs_of`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

from logscan.detectors.registry import default_registry
from logscan.docs import doc_url
from logscan.errors import InternalError, ProfileError, did_you_mean
from logscan.filters.ubikf import run_ubikf
from logscan.needs import Needs, Part, union
from logscan.pipeline.refilter import run_ekf_parts

if TYPE_CHECKING:  # the types of the layers a prepared log carries (imported where they are used)
    from logscan.align import AlignedRun
    from logscan.filters.ubikf import UbikfTrace
    from logscan.log import Log
    from logscan.models.base import Model
    from logscan.pipeline.lead_in import FilterStart
    from logscan.profiles.schema import Profile
    from logscan.report.run_context import RunContext
    from logscan.report.sensor_views import GroupRows
    from logscan.timebase.clock import Clock
    from logscan.traces import EkfTrace


def _run_ekf(model, run, parts: frozenset[Part], x0=None, P0=None, steps_done=None, seed=None):
    # R from each group's profile noise_std, else the model's default; Q the model's, scaled when
    # trained tables calibrated it (`LoadedProfile.process_noise_scale`): pack_run. x0, P0: a
    # checkpoint to start from (a probe re-filtering a slice, a window's lead-in), else the model's
    # prior; seed: whether it seeds the directly observed states first (`pack_run`). K and S, when
    # asked, are filtered again block by block as they are read (`logscan.pipeline.refilter`)
    return run_ekf_parts(model, run, parts, x0=x0, P0=P0, steps_done=steps_done, seed=seed)


def _run_ubikf(model, run, parts: frozenset[Part]):
    interval_model = getattr(model, "interval_model", None)
    if interval_model is None:
        raise ProfileError(
            f"the UBIKF needs a model with interval parameters; {model.name!r} has none",
            hint=f'use [vehicle] model = "hover_uav" ({doc_url("models.md")}), or drop the chi2 detector',
        )
    return run_ubikf(interval_model(run.dt), run)


# Filter name -> function(model, aligned run, trace parts to keep) -> trace. A new filter is one line.
FILTERS: dict[str, Callable[..., Any]] = {"ekf": _run_ekf, "ubikf": _run_ubikf}
# The filters that count their steps into a ``steps_done`` array as they run (`logscan.pipeline.step_counter`);
# the others' progress is estimated from the time the step takes on other logs.
COUNTS_STEPS = frozenset({"ekf"})


@dataclass
class LoadedProfile:
    """A parsed profile with its TOML text and where it came from ("embedded" or a file path)."""

    profile: Profile
    text: str
    source: str  # a file path, "embedded", or "built-in <name>"
    notes: list[str] = field(default_factory=list)  # what a built-in profile left out, one line each
    # a built-in profile's log, read once to build it with every topic an analysis of it may read
    # (`builtin_profile_for`): `prepare` takes it instead of reading the file again, then drops it
    log: Log | None = field(default=None, repr=False, compare=False)
    log_extra_topics: frozenset = field(default=frozenset(), repr=False, compare=False)
    # the tables' calibrated process noise, {state: scale of its Q} (`logscan.training.calibration`; set by
    # `analyze_log` from --tables): `prepare` gives it to the model, the EKF scales Q by it
    process_noise_scale: dict | None = field(default=None, compare=False)
    # the groups those tables' calibration could not bring to NIS 1 (kept the profile's noise)
    uncalibrated: frozenset = field(default=frozenset(), compare=False)
    # why the model's filter cannot run on this log ("": it can; a built-in profile says,
    # `BuiltProfile.model_not_run`): only detectors that need no filter run (`filter_free`)
    model_not_run: str = ""


@dataclass
class Prepared:
    """One log made ready for detectors: the log, its profile, model, aligned run and filter traces."""

    path: str
    log: Log
    loaded: LoadedProfile
    model: Model
    run: AlignedRun
    traces: dict[str, EkfTrace | UbikfTrace] = field(default_factory=dict)  # filter name -> trace
    warnings: list[str] = field(default_factory=list)
    _filter_summary: dict | None = None
    context: RunContext | None = None  # the path and mode the report draws (small)
    innovations: GroupRows | None = None  # the report's measured-vs-predicted figures (blocks: kept rows)
    raw: dict = field(default_factory=dict)  # the detectors' raw_topics' channels, as read (not aligned)
    loops: dict = field(default_factory=dict)  # a hierarchical profile's further loops: name -> Prepared
    clock: Clock | None = None  # the log's own clock, dated before the samples go
    # a window's EKF started from its lead-in (`logscan.pipeline.lead_in`); None: from the model's prior
    lead_in: FilterStart | None = None
    # (steps, step in s) of the grid when ``run.t`` holds a block-mode analysis' envelope times instead
    # (`logscan.pipeline.block_reduce`); None: ``run.t`` is the grid
    grid: tuple[int, float] | None = None

    @property
    def filter_from(self) -> float | None:
        """Where the filters started converging, when before the run: the EKF's lead-in, when it is
        the only filter (the UBIKF has none)."""
        return self.lead_in.start_s if self.lead_in is not None and set(self.traces) <= {"ekf"} else None

    def filter_summary(self) -> dict | None:
        """The EKF trace's JSON counts (kept when the series are released)."""
        if self._filter_summary is None and self.trace is not None:
            self._filter_summary = self.trace.summary()
            if self.lead_in is not None:  # filtered from this long before the run, not judged there
                self._filter_summary["lead_in_s"] = round(float(self.run.t[0]) - self.lead_in.start_s, 6)
        return self._filter_summary

    def release_series(self) -> None:
        """Free what only the filters and detectors read, once they have run: the filter traces and
        the aligned signals (~290 MB for a 1-hour 100 Hz log). The report draws the grid's times and
        the detectors' results; the filter's counts stay (``filter_summary``)."""
        import numpy as np

        self.filter_summary()
        self.traces.clear()
        empty = np.empty((self.run.n_steps, 0))
        self.run = replace(
            self.run,
            u=empty,
            u_fresh=np.empty(0, dtype=bool),
            groups={},
            redundant={},
            mode=None,
            onboard_state=None,
            onboard_variance=None,
        )

    @property
    def profile(self) -> Profile:
        return self.loaded.profile

    @property
    def trace(self) -> EkfTrace | None:
        """The shared EKF trace (None when no detector needed the EKF)."""
        return self.traces.get("ekf")  # type: ignore[return-value]  # FILTERS["ekf"] makes an EkfTrace


def create_detectors(loaded: LoadedProfile, names: Sequence[str] | None = None) -> list:
    """The detectors to run: ``names``, else those the profile enables, else the registry's defaults;
    configured from the profile's [detectors.NAME] tables and checked before any log is read."""
    registry = default_registry()
    profile = loaded.profile
    # the profile's file, or "<log> (embedded profile)": its errors name the log too ("embedded" does not)
    source = profile.source
    chosen = list(names or profile.enabled_detectors() or registry.default_names())
    if loaded.source == "embedded" and not names:
        refuse_embedded_plugins(chosen, registry.builtin_names(), registry.plugin_entry_names(), source)
    detectors = []
    for name in chosen:
        spec = profile.detectors.get(name)
        try:
            detectors.append(registry.create(name, dict(spec.settings) if spec else {}, source=source))
        except ProfileError as exc:
            if exc.path is None and not names:  # an unknown name the profile chose, not --detector
                exc.path = source
            raise
    return detectors


def refuse_embedded_plugins(
    chosen: Sequence[str], builtins: Sequence[str], plugins: Sequence[str], source: str
) -> None:
    """A profile embedded in a log (MCAP metadata, CSV sidecar) runs built-in detectors only: a
    plugin is code, and it runs only when the user's own --profile or --detector names it (the log
    is data; its author must not choose which installed code runs). ProfileError otherwise,
    before any plugin is imported: an installed plugin's name is refused as such, any other name
    is unknown."""
    installed = [name for name in chosen if name not in builtins and name in plugins]
    if installed:
        raise ProfileError(
            f"the profile embedded in the log names the plugin detector(s) {', '.join(map(repr, installed))}: "
            "a profile that comes with a log never runs a plugin",
            path=source,
            hint="to run a plugin, name it yourself: --detector NAME, or a profile file of yours (--profile)",
        )
    unknown = next((name for name in chosen if name not in builtins), None)
    if unknown is not None:
        raise ProfileError(
            f"unknown detector {unknown!r}",
            path=source,
            hint=f"{did_you_mean(unknown, builtins)}available: {', '.join(builtins)} "
            "(a profile embedded in a log runs built-in detectors only; "
            "see `logscan detectors`)",
        )


def needs_of(detectors: Sequence) -> Callable[[AlignedRun], Needs]:
    """The union of the detectors' needs, as a function of the aligned run they depend on."""
    return lambda run: union(detector.needs(run) for detector in detectors)


def fit_context(detector, model: Model, run: AlignedRun) -> dict[str, Any]:
    """The context keywords of a detector's `fit` on training runs like ``run``: the ``model``, and
    ``refilter`` when its needs declare probes (`logscan.needs`): ``refilter(name, run)`` runs the
    filter ``name``, one of its probes, on a run the detector made, with this model and the trace
    parts the detector asks of that filter, as the pipeline runs it on a log; ``start`` (the EKF:
    ``x0=..., P0=...``) starts it from a checkpoint instead of the model's prior."""
    if not detector.needs(run).probes:
        return {"model": model}

    def refilter(name: str, probe_run: AlignedRun, **start: Any) -> Any:
        needs = detector.needs(probe_run)
        if name not in needs.probes:
            raise InternalError(f"detector {detector.name!r} re-filters with {name!r}, not one of its probes")
        return FILTERS[name](model, probe_run, needs.parts(name), **start)

    return {"model": model, "refilter": refilter}
