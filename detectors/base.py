"""The detector contract: the `Detector` base class (declared parameters, declared needs, fit/run).

A detector (built-in or plugin) subclasses `Detector`:

    class MyDetector(Detector):
        '''One line: what it detects.'''            # shown by `logscan detectors`
        name = "my_detector"                          # unique registry name
        defaults = {"threshold": 3.0, "n_persist": 3} # every parameter with its default
        parameter_constraints = {                     # types and ranges, checked at creation
            "threshold": [Interval(float, 0, None, closed="neither")],
            "n_persist": [Interval(int, 1, None)],
        }
        requires_fit = False                          # True: `run` needs trained state
        requires_trace = False                        # True: needs the shared EKF trace
        trained_attributes = ()                       # e.g. ("threshold_",): what `fit` learns
        reads = frozenset({"x_post"})                 # the large series it reads (see `reads`)

        def needs(self, run=None) -> Needs:           # optional: more than the EKF's default trace
            ...
        def _fit(self, runs, traces, **context):      # optional: set trailing-underscore attributes
            ...
        def _run(self, run, trace, **context) -> DetectorResult:
            ...
        def end_delays(self, run, trace, result) -> dict:  # optional: a windowed statistic's
            ...                                                # alarm outlasts the anomaly by its window

Rules (STYLE.md): ``__init__`` only stores parameters (they are the detector's JSON config, read
back as attributes: ``self.threshold``); the registry checks them against `parameter_constraints`
when it creates the detector, before any log is read (`check_params`). `fit` sets trained
attributes ending in "_" and returns self. Trained state is JSON with a schema version, never
pickle. A detector that needs trained state it lacks raises NotTrainedError. A statistic that
belongs to another check for scoring says so with ``add_statistic(..., check="e_x")``.

Context keywords passed to `fit` / `run` (all optional): ``model`` (a logscan.models.base.Model),
``log_name``, ``traces`` (every filter trace the pipeline ran, by filter name), ``alarm_policy``
(the profile's alarm floors, applied by `new_result` to every statistic; its suspended steps to
every statistic but those of a detector with ``raw_topics``, which are never suspended), ``truth`` (a simulated
log's ground truth: fault events and transients; None for real logs; never used to detect, only to
report against, e.g. fusion error against the fault-free fusion), ``raw`` (the channels of the
detector's `raw_topics` present in the log, as read: channel name -> logscan.log.Channel),
``metadata`` (the log's metadata: ULog info and parameters, MCAP metadata records) and, for `fit`
only, ``refilter`` (the pipeline's filter on a run the detector made, given when its needs declare
probes: `logscan.needs`; a detector never runs a filter itself).
The trace is the shared EKF trace (``logscan.traces.EkfTrace``: data between the layers, a
foundation, so this module does not import the filter layer).
"""

from __future__ import annotations

import copy
import json
import math
import shlex
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from logscan import __version__
from logscan.align import AlignedRun
from logscan.detectors.isolation import call_isolated
from logscan.detectors.params import describe_constraints, satisfies
from logscan.errors import (
    InputError,
    InternalError,
    NotTrainedError,
    OutOfMemoryError,
    ProfileError,
    UsageError,
    did_you_mean,
)
from logscan.needs import Needs
from logscan.results import Band, DetectorResult
from logscan.traces import EkfTrace

__all__ = [
    "END_DELAY_KEY",
    "Band",
    "Detector",
    "DetectorResult",
    "Needs",
    "any_per_row",
    "describe",
    "median_period",
    "on_steps",
]

STATE_FORMAT = "logscan-detector-state"
END_DELAY_KEY = "end_delay_s"  # DetectorResult.info: statistic -> its declared end delay (`Detector.end_delays`)


def on_steps(values: np.ndarray, steps: np.ndarray, n_steps: int) -> np.ndarray:
    """``values`` at the grid ``steps`` (ascending), NaN elsewhere; themselves when every step is one."""
    if steps.size == n_steps:
        return values
    out = np.full(n_steps, np.nan, dtype=values.dtype)
    out[steps] = values
    return out


def any_per_row(mask: np.ndarray) -> np.ndarray:
    """``mask.any(axis=1)`` of an (N, G) bool array (a trace's ``updated``): a C-contiguous row of 1,
    2, 4 or 8 flags is read as one unsigned integer, non-zero when any flag is set (numpy's row
    reduction over so few columns is some 80 times slower)."""
    width = mask.shape[1] if mask.ndim == 2 else 0
    if mask.dtype == np.bool_ and mask.flags.c_contiguous and width in (1, 2, 4, 8):
        return mask.view(f"u{width}")[:, 0] != 0
    return np.asarray(mask.any(axis=1))


def median_period(t: np.ndarray, steps: np.ndarray) -> float:
    """The median time between the steps of ``t`` where ``steps`` (bool) is True; 0 with fewer than two."""
    times = np.asarray(t, dtype=np.float64)[np.asarray(steps, dtype=bool)]
    # the differences are a temporary of its own: partitioned in place, not copied first
    return float(np.median(np.diff(times), overwrite_input=True)) if times.size > 1 else 0.0


# --- trained-state encoding (lossless, strict JSON) -----------------------------------------------

_NONFINITE = {"NaN": math.nan, "Infinity": math.inf, "-Infinity": -math.inf}


def _encode_float(x: float) -> float | str:
    if math.isfinite(x):
        return x
    return "NaN" if math.isnan(x) else ("Infinity" if x > 0 else "-Infinity")


def encode_state_value(value: Any) -> Any:
    """Trained attribute -> strict JSON, lossless for arrays (dtype and shape kept) and floats."""
    if isinstance(value, np.ndarray):
        flat = value.ravel().tolist()
        if value.dtype.kind == "f":
            flat = [_encode_float(x) for x in flat]
        return {"__ndarray__": flat, "dtype": value.dtype.str, "shape": list(value.shape)}
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return {"__float__": _encode_float(float(value))} if not math.isfinite(value) else float(value)
    if isinstance(value, Mapping):
        return {str(k): encode_state_value(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [encode_state_value(v) for v in value]
    if value is None or isinstance(value, str):
        return value
    raise InternalError(f"cannot store a {type(value).__name__} in trained detector state")


def decode_state_value(value: Any) -> Any:
    """Inverse of `encode_state_value`."""
    if isinstance(value, dict):
        if "__ndarray__" in value:
            data = [_NONFINITE.get(x, x) if isinstance(x, str) else x for x in value["__ndarray__"]]
            return np.asarray(data, dtype=np.dtype(value["dtype"])).reshape(value["shape"])
        if set(value) == {"__float__"}:
            return _NONFINITE[value["__float__"]]
        return {k: decode_state_value(v) for k, v in value.items()}
    if isinstance(value, list):
        return [decode_state_value(v) for v in value]
    return value


def _short(value: Any) -> str:
    """A setting as the error line quotes it (a 400-digit integer is not worth 400 characters)."""
    text = repr(value)
    return text if len(text) <= 40 else f"{text[:20]}...{text[-8:]} ({len(text)} characters)"


class Detector:
    """Base class of every detector (see the module docstring for the contract)."""

    name: ClassVar[str] = ""
    defaults: ClassVar[Mapping[str, Any]] = {}
    parameter_constraints: ClassVar[Mapping[str, list]] = {}
    default_enabled: ClassVar[bool] = False  # runs when a profile enables no detector
    requires_fit: ClassVar[bool] = False
    requires_trace: ClassVar[bool] = False
    trained_attributes: ClassVar[tuple[str, ...]] = ()
    # Parameters that shape what `fit` learns: a trained detector keeps them from its tables; the
    # others come from the profile it runs with (`logscan.training.tables.apply_tables`).
    fit_params: ClassVar[tuple[str, ...]] = ()
    state_version: ClassVar[int] = 1
    # Which of the large per-step series (`logscan.pipeline.RELEASABLE`: the EKF's state, covariance,
    # gain and innovation series, the run's on-board estimates) `run` reads. The pipeline frees each
    # once no detector still to run reads it. None: not declared, nothing is freed before it runs.
    reads: ClassVar[frozenset[str] | None] = None
    # Source topics (ULog ``topic_instance`` names, MCAP topics) the detector reads from the log
    # itself, beyond the profile's channels (e.g. the autopilot's own estimator status). The pipeline
    # decodes those present and passes their channels, unaligned, as the context keyword ``raw``
    # (channel name -> logscan.log.Channel), with the log's metadata as ``metadata``.
    raw_topics: ClassVar[tuple[str, ...]] = ()
    # Threshold multipliers `logscan train --tune` may choose (logscan.training.tuning): parameter -> the
    # statistics whose alarms it alone decides, e.g. {"rho": ("e_x",)}.
    tunable: ClassVar[Mapping[str, tuple[str, ...]]] = {}
    # The autopilot's own verdict (PX4's estimator tests): the baseline logscan's model-based alarms
    # are reported against (`logscan.pipeline.analysis.Analysis.against_baseline`).
    is_baseline: ClassVar[bool] = False
    # What an incident headed by a group says of it when this detector's alarm is the one quoted
    # (`logscan.verdict.incidents.headline_parts`): "accelerometer inconsistent", "barometer stuck".
    group_verdict: ClassVar[str] = "inconsistent"
    # Where a plugin class comes from ("plugin <distribution> <version>"), set by the registry when it
    # loads one; None for built-ins. A plugin's fit and run are isolated (`logscan.detectors.isolation`).
    plugin_origin: ClassVar[str | None] = None

    def __init__(self, **params: Any) -> None:
        self.params = {**copy.deepcopy(dict(self.defaults)), **params}

    def __getattr__(self, key: str) -> Any:
        # parameters read as attributes (self.rho); only reached when normal lookup fails
        params = self.__dict__.get("params")
        if params is not None and key in params:
            return params[key]
        raise AttributeError(f"{type(self).__name__!s} has no attribute {key!r}")

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params.items())
        return f"{type(self).__name__}({args})"

    # --- configuration ----------------------------------------------------------------------------
    def get_params(self) -> dict[str, Any]:
        """The detector's configuration (JSON-ready copy of its parameters)."""
        return copy.deepcopy(self.params)

    @classmethod
    def from_config(cls, config: Mapping[str, Any] | None) -> Detector:
        """A detector from its configuration dict (e.g. a profile's [detectors.NAME] table)."""
        return cls(**dict(config or {}))

    def check_params(self) -> None:
        """Validate the parameters against `parameter_constraints` (the registry calls this when it
        creates a detector; fit and run call it again). Subclasses may extend it with checks that
        relate several parameters, raising ProfileError naming the parameter."""
        unknown = sorted(set(self.params) - set(self.defaults))
        if unknown:
            raise ProfileError(
                f"detector {self.name!r}: unknown parameter(s) {', '.join(unknown)}",
                hint="".join(did_you_mean(name, self.defaults) for name in unknown)
                + f"known: {', '.join(sorted(self.defaults)) or 'none'}",
            )
        for key, constraints in self.parameter_constraints.items():
            value = self.params.get(key)
            if not satisfies(value, constraints):
                raise ProfileError(
                    f"detector {self.name!r}: {key} must be {describe_constraints(constraints)}, got {_short(value)}"
                )
        try:
            json.dumps(self.params, allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise ProfileError(f"detector {self.name!r}: parameters are not plain JSON values ({exc})") from None

    def needs(self, run: AlignedRun | None = None) -> Needs:
        """What this detector asks of the pipeline. ``run`` (the aligned run, when known) lets the
        needs follow what the log holds; the default is the shared EKF trace when requires_trace."""
        return Needs.of(ekf=()) if self.requires_trace else Needs()

    # --- training ---------------------------------------------------------------------------------
    def fit(
        self, runs: Sequence[AlignedRun], traces: Sequence[EkfTrace | None] | None = None, **context: Any
    ) -> Detector:
        """Learn trained state (trailing-underscore attributes) from healthy runs; returns self."""
        if type(self).plugin_origin is not None:  # plugin code: isolated from the analysis
            return call_isolated(self, "fit", lambda: self._fit_checked(runs, traces, **context))
        return self._fit_checked(runs, traces, **context)

    def _fit_checked(
        self, runs: Sequence[AlignedRun], traces: Sequence[EkfTrace | None] | None, **context: Any
    ) -> Detector:
        self.check_params()
        runs = list(runs)
        traces = [None] * len(runs) if traces is None else list(traces)
        if len(traces) != len(runs):
            raise InternalError(f"detector {self.name!r}: {len(runs)} runs but {len(traces)} traces")
        if self.requires_trace and any(tr is None for tr in traces):
            raise UsageError(f"detector {self.name!r} needs the filter trace of every training run")
        try:
            self._fit(runs, traces, **context)
        except MemoryError:  # the logs are too big for this machine: exit 2 with what to do, not a bug
            raise OutOfMemoryError() from None
        return self

    def _fit(self, runs: list[AlignedRun], traces: list[EkfTrace | None], **context: Any) -> None:
        """Training step of subclasses that learn something; the default learns nothing."""

    @classmethod
    def signal_words(cls, signal: str) -> str | None:
        """Plain words for one of its statistics, said instead of "<group> inconsistent" in an
        incident's headline (`logscan.verdict.incidents`); None: the default wording."""
        return None

    @classmethod
    def judged_input(cls, signal: str) -> str | None:
        """The model input (its name in `Model.input_names`) one of its statistics judges, not a
        measurement group: an incident it alarms first in is headed by that input
        (`logscan.verdict.incidents`, rule 5); None (the default): a group's or the filter's."""
        return None

    @classmethod
    def signal_label(cls, signal: str) -> str | None:
        """What one of its statistics means to a flight-test engineer, in plain words ("the state
        prediction disagrees with the measurements"), shown next to the statistic's name in the
        report, the alarm table, incidents and the summary. Every statistic a detector produces
        should have one (tests/test_words.py checks the built-ins); default: `signal_words`."""
        return cls.signal_words(signal)

    def with_params(self, **params: Any) -> Detector:
        """A copy with ``params`` changed (checked), trained state kept (`logscan.training.tuning`)."""
        other = copy.deepcopy(self)
        other.params.update(params)
        other.check_params()
        return other

    def learns(self) -> bool:
        """Whether `fit` learns anything in this configuration (`logscan train` fits those that do)."""
        return bool(self.trained_attributes)

    @classmethod
    def asked_for_by(cls, profile) -> bool:
        """Whether a profile asks for this detector's tables even without enabling it (A-TFM: a
        [redundant] group); `logscan train` then trains it too."""
        return False

    @classmethod
    def state_lines(cls, state: Mapping[str, Any]) -> list[str]:
        """What `logscan train` prints of a trained state (`to_state` output): one line by default."""
        return [f"  {cls.name}: trained ({', '.join(cls.trained_attributes)})"]

    def is_trained(self) -> bool:
        return all(hasattr(self, attr) for attr in self.trained_attributes)

    def check_trained(self) -> None:
        missing = [attr for attr in self.trained_attributes if not hasattr(self, attr)]
        if missing:
            raise NotTrainedError(
                f"detector {self.name!r} is not trained (missing {', '.join(missing)})",
                hint="train it on healthy logs (`logscan train HEALTHY_LOG... -o tables.json`), then pass "
                "--tables tables.json",
            )

    # --- running ----------------------------------------------------------------------------------
    def run(self, run: AlignedRun, trace: EkfTrace | None = None, **context: Any) -> DetectorResult:
        """Run on one aligned run (and the shared filter trace); returns a DetectorResult."""
        if type(self).plugin_origin is not None:  # plugin code: isolated from the analysis
            return call_isolated(self, "run", lambda: self._run_checked(run, trace, **context))
        return self._run_checked(run, trace, **context)

    def _run_checked(self, run: AlignedRun, trace: EkfTrace | None, **context: Any) -> DetectorResult:
        self.check_params()
        if self.requires_fit:
            self.check_trained()
        if self.requires_trace and trace is None:
            raise UsageError(f"detector {self.name!r} needs the filter trace, but none was given")
        # the profile's alarm floors reach every statistic through new_result(); its suspension (the
        # ground, take-off and landing, the filter converging) only the model's: a detector that reads
        # the autopilot's own topics (raw_topics) judges what the vehicle reported, on the whole log
        policy = context.pop("alarm_policy", None)
        self._alarm_policy = policy.unsuspended() if policy is not None and self.raw_topics else policy
        try:
            result = self._run(run, trace, **context)
        except MemoryError:  # the log is too big for this machine: exit 2 with what to do, not a bug
            raise OutOfMemoryError() from None
        finally:
            self._alarm_policy = None
        self._check_result(result, run)
        delays = {name: float(s) for name, s in self.end_delays(run, trace, result).items() if name in result.series}
        if delays:
            result.info[END_DELAY_KEY] = delays
        return result

    def end_delays(self, run: AlignedRun, trace: EkfTrace | None, result: DetectorResult) -> dict[str, float]:
        """Statistic (of ``result``) -> its end delay (s): how long after an anomaly ends an alarm of
        that statistic can still last because the statistic sums or spreads a trailing window over the
        anomaly's samples. Stored in the result's info under ``END_DELAY_KEY``; recovery looks for the
        end of an anomaly from an alarm's end minus it (docs/algorithms.md section 5). Default: none,
        every statistic judges each sample alone (delay 0: its alarm ends with the anomaly)."""
        return {}

    def _run(self, run: AlignedRun, trace: EkfTrace | None, **context: Any) -> DetectorResult:
        raise NotImplementedError(f"{type(self).__name__} must implement _run")

    def new_result(self) -> DetectorResult:
        """An empty result of this detector, carrying the profile's alarm floors during `run`."""
        return DetectorResult(detector=self.name, alarm_policy=self.__dict__.get("_alarm_policy"))

    def _check_result(self, result: DetectorResult, run: AlignedRun) -> None:
        if not isinstance(result, DetectorResult):
            raise InternalError(f"detector {self.name!r} returned {type(result).__name__}, not DetectorResult")
        n = run.n_steps
        for kind, named in (("series", result.series), ("extras", result.extras)):
            for key, values in named.items():
                if np.shape(values)[:1] != (n,):
                    raise InternalError(
                        f"detector {self.name!r}: {kind} {key!r} has shape {np.shape(values)}, grid has {n} steps"
                    )
        for key, band in result.thresholds.items():
            for values in (band.upper, band.lower):
                if values is not None and np.shape(values) != (n,):
                    raise InternalError(f"detector {self.name!r}: threshold of {key!r} has shape {np.shape(values)}")

    # --- trained state ----------------------------------------------------------------------------
    def to_state(self) -> dict[str, Any]:
        """Trained state as strict JSON: format, detector name, schema version, params, state."""
        self.check_trained()

        return {
            "format": STATE_FORMAT,
            "detector": self.name,
            "schema_version": self.state_version,
            "logscan_version": __version__,
            "params": self.get_params(),
            "state": {attr: encode_state_value(getattr(self, attr)) for attr in self.trained_attributes},
        }

    @classmethod
    def from_state(cls, state: Mapping[str, Any], *, path: str | None = None) -> Detector:
        """A trained detector from `to_state` output (raises InputError on a mismatch)."""
        if not isinstance(state, Mapping) or state.get("format") != STATE_FORMAT:
            raise InputError("not a logscan detector state", path=path, hint="use a file written by `logscan train`")
        if state.get("detector") != cls.name:
            raise InputError(f"trained state is for detector {state.get('detector')!r}, not {cls.name!r}", path=path)
        version = state.get("schema_version")
        if version != cls.state_version:
            raise InputError(
                f"trained state of {cls.name!r} has schema version {version}, this logscan reads {cls.state_version}",
                path=path,
                hint=f"retrain with `logscan train HEALTHY_LOG... -o {shlex.quote(str(path or 'tables.json'))}`",
            )
        detector = cls.from_config(state.get("params") or {})
        stored = state.get("state") or {}
        missing = [attr for attr in cls.trained_attributes if attr not in stored]
        if missing:
            raise InputError(
                f"trained state of {cls.name!r} lacks {', '.join(missing)}",
                path=path,
                hint=f"retrain with `logscan train HEALTHY_LOG... -o {shlex.quote(str(path or 'tables.json'))}`",
            )
        for attr in cls.trained_attributes:
            setattr(detector, attr, decode_state_value(stored[attr]))
        return detector


def describe(cls: type[Detector]) -> str:
    """First line of a detector class's docstring ('' when it has none)."""
    doc = (cls.__doc__ or "").strip()
    return doc.splitlines()[0].strip() if doc else ""
