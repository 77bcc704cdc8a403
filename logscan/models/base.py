"""The vehicle-model interface every model implements (filters, simulator and detectors use only this).

INTERFACE (fixed): models are registered by name in `logscan.models` (`get_model(name, params)`,
`MODEL_NAMES`). The numeric parts run inside numba kernels: each model has an integer `model_id`
and a packed float64 parameter vector, and `logscan.models.dispatch` dispatches
`f / F / h / H` on (model_id, group_id) to the functions the model registered.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from logscan.errors import ModelError, did_you_mean
from logscan.models import dispatch


@dataclass(frozen=True)
class Actuators:
    """What drives a model's inputs: u = M @ a for actuator values a (the inputs as logged), an
    actuator fault acting on its total trim + a. The simulator's actuators (`logscan simulate`) and
    the fault directions of the observability verdict (`logscan.verdict.observability`) both read it,
    so the verdict's names are the ground truth's."""

    names: tuple[str, ...]  # as the simulator's truth names fault targets: motor1, steering_motor, rotor1
    M: np.ndarray  # (n_inputs, A) float64: the mixer, inputs per unit of each actuator
    trim: np.ndarray  # (A,) float64: the operating point the inputs deviate from (zeros: none)


@dataclass(frozen=True)
class GroupSpec:
    """A measurement group of a model (e.g. quadcopter "accel" = specific force x, y, z)."""

    name: str
    group_id: int  # index used by the numba dispatch
    outputs: tuple[str, ...]  # output names, in order
    noise_std: tuple[float, ...]  # default measurement noise standard deviation per output
    range_lo: tuple[float, ...]  # physical range per output: values outside are impossible
    range_hi: tuple[float, ...]
    units: tuple[str, ...] = ()
    # Extensions used by the EKF core (all optional, one entry per output when given):
    wrap: tuple[bool, ...] = ()  # angular output: the innovation is wrapped to (-pi, pi]
    direct_states: tuple[int, ...] = ()  # state observed directly (z = gain * x[i]); -1: none
    direct_gains: tuple[float, ...] = ()  # the gain of that direct observation
    # the measured quantity holds one value over long stretches of healthy operation (a wheel
    # odometry's yaw rate while driving straight): a frozen sensor cannot be told from it
    steady: bool = False
    # an outlier gate (docs/algorithms.md 8.4): the group's error is a slow wander the model
    # estimates (a GNSS receiver's), so an outlier taken into it would leave only at the wander's
    # time constant; a sample whose NIS passes the gate is kept for the detectors, not the update
    gated: bool = False

    @property
    def size(self) -> int:
        return len(self.outputs)

    def wrap_mask(self) -> np.ndarray:
        return np.array(self.wrap or (False,) * self.size, dtype=np.bool_)

    def direct_map(self) -> tuple[np.ndarray, np.ndarray]:
        """(state index per output, -1 when not direct; gain per output)."""
        idx = np.array(self.direct_states or (-1,) * self.size, dtype=np.int64)
        gain = np.array(self.direct_gains or (1.0,) * self.size, dtype=np.float64)
        return idx, gain


def model_error(problems: list[str], hint: str | None = None) -> ModelError:
    """One ModelError for every problem found: the first in its message, all in ``.problems``."""
    more = f" ({len(problems) - 1} more)" if len(problems) > 1 else ""
    err = ModelError(problems[0] + more, hint=hint)
    err.problems = list(problems)
    return err


def raise_problems(problems: list[str], hint: str | None = None) -> None:
    """Raise `model_error` when ``problems`` is not empty."""
    if problems:
        raise model_error(problems, hint)


def covariance_problem(M, name: str, *, definite: bool) -> str | None:
    """Why ``M`` cannot be a covariance, or None: it must be square, finite, symmetric and positive
    semi-definite (positive definite when ``definite``). Tolerances are relative to its largest
    entry: asymmetry up to 1e-9 of it, eigenvalues (eigvalsh) down to -1e-9 of it for
    semi-definite, above 1e-12 of it for definite."""
    M = np.asarray(M, dtype=np.float64)
    if M.ndim != 2 or M.shape[0] != M.shape[1] or M.size == 0:
        return f"{name} must be a square matrix, got shape {M.shape}"
    if not np.all(np.isfinite(M)):
        return f"{name} has non-finite entries"
    scale = float(np.abs(M).max())
    if float(np.abs(M - M.T).max()) > 1e-9 * scale:
        return f"{name} is not symmetric"
    smallest = float(np.linalg.eigvalsh(0.5 * (M + M.T)).min())
    if definite and not smallest > 1e-12 * scale:
        return f"{name} is not positive definite (smallest eigenvalue {smallest:.3g})"
    if not definite and smallest < -1e-9 * scale:
        return f"{name} is not positive semi-definite (smallest eigenvalue {smallest:.3g})"
    return None


class Model:
    """Discrete-time model x_k = f(x_{k-1}, u_k) + w, z = h_g(x_k, u_k) + v per group g.

    Subclasses set the class attributes; the numpy views f, F, h, H call the numba functions their
    kernels module (`<model>_kernels.py` beside the class module) registers under `model_id`, which
    must be one of `dispatch.MODEL_IDS`.
    """

    name: str = ""
    model_id: int = -1
    state_names: tuple[str, ...] = ()
    input_names: tuple[str, ...] = ()
    inputs_are_sensors: bool = False  # True when the inputs are sensor readings (ins: the IMU), not commands
    # the inputs (indices into input_names) `at_rest` reads: the frozen check trusts them to say when
    # the vehicle moves, so it checks them for a freeze too (a stuck wheel speed makes rest "motion")
    rest_inputs: tuple[int, ...] = ()
    # sensors that can deny that rest (detectors/frozen_rest.py): inputs whose samples shake while the
    # vehicle moves (a gyro), and the group that measures its position (a GNSS); none: rest trusted
    motion_inputs: tuple[int, ...] = ()
    motion_group: str | None = None
    # (rate group, output, level group, output, sign): a measured rate and the measured level it
    # integrates to, the level's innovation times sign (a barometer's altitude is minus down): an
    # input the prediction integrates moves both innovations one way (logscan/verdict/input_fault.py)
    kinematic_pairs: tuple[tuple[str, int, str, int, float], ...] = ()
    kinematic_inputs: tuple[int, ...] = ()  # the inputs such a pair's agreement blames
    # the level groups measured by a sensor of their own, not by the rate's (a barometer against a
    # GNSS receiver's velocity): only their agreement rules out that sensor wrong in both coherently
    kinematic_witnesses: frozenset[str] = frozenset()
    kinematic_input_words: str = "model input"
    # True when the filter's gain never reads a measurement (a linear model with fixed Q and R: the
    # Riccati recursion alone), so a gain-based check (kgn) has nothing to see
    gain_is_data_free: bool = False
    groups: dict[str, GroupSpec] = {}
    # set on instances: the parameters merged over the defaults (each subclass's __init__,
    # `_merge_params`), and the trained tables' Q scales, {state: scale}, when calibrated (set by
    # `logscan.pipeline.preparation`, read by `logscan.filters.q_scale`)
    p: dict
    process_noise_scale: dict | None

    def __init__(self, params: dict | None = None):
        dispatch.check_model_id(self.model_id, self.name)
        self.params: dict = dict(params or {})

    def _merge_params(self, defaults: dict) -> dict:
        """defaults updated by self.params; one ModelError listing every unknown, non-numeric or
        non-finite parameter."""
        problems = []
        for k in sorted(set(self.params) - set(defaults)):
            close = did_you_mean(k, defaults).strip()
            problems.append(f"model {self.name!r}: unknown parameter {k}" + (f" ({close})" if close else ""))
        merged = dict(defaults)
        for key, value in self.params.items():
            if key not in defaults:
                continue
            if isinstance(defaults[key], (int, float)) and not isinstance(defaults[key], bool):
                try:
                    value = float(value)
                except (TypeError, ValueError):
                    problems.append(f"model {self.name!r}: parameter {key} = {value!r} is not a number")
                    continue
                if not np.isfinite(value):
                    problems.append(f"model {self.name!r}: parameter {key} = {value} is not finite")
            merged[key] = value
        raise_problems(problems, hint="known parameters: " + ", ".join(defaults))
        return merged

    def _check_signs(self, positive=(), non_negative=()) -> None:
        """ModelError listing every parameter of ``positive`` not > 0 and of ``non_negative`` < 0."""
        problems = [f"{self.name}: parameter {k} must be > 0 (got {self.p[k]})" for k in positive if not self.p[k] > 0]
        problems += [
            f"{self.name}: parameter {k} must be >= 0 (got {self.p[k]})" for k in non_negative if not self.p[k] >= 0
        ]
        raise_problems(problems)

    # --- packed data for kernels -------------------------------------------------------------
    def param_vector(self, dt: float | None = None) -> np.ndarray:
        """float64 vector of the model's parameters as the numba functions read them.

        Models discretised exactly (linear, dc_motor) need the grid period ``dt``; the others
        ignore it.
        """
        raise NotImplementedError

    @property
    def n_states(self) -> int:
        return len(self.state_names)

    @property
    def n_inputs(self) -> int:
        return len(self.input_names)

    def group(self, name: str) -> GroupSpec:
        """The group called ``name``; ModelError listing the model's groups when unknown."""
        try:
            return self.groups[name]
        except KeyError:
            raise ModelError(
                f"model {self.name!r} has no measurement group {name!r}",
                hint="known groups: " + ", ".join(self.groups),
            ) from None

    def default_x0(self) -> np.ndarray:
        """Initial state when none is given (zeros unless the model knows better)."""
        return np.zeros(self.n_states)

    def default_P0(self) -> np.ndarray:
        """Initial covariance when none is given: diag(state_scale^2)."""
        return np.diag(np.square(self.state_scale()))

    # --- defaults -------------------------------------------------------------------------------
    def default_Q(self, dt: float) -> np.ndarray:
        raise NotImplementedError

    def default_R(self, group: str) -> np.ndarray:
        spec = self.groups[group]
        return np.diag(np.square(np.asarray(spec.noise_std, dtype=np.float64)))

    def covariance_problems(self, dt: float) -> list[str]:
        """Why the model's process noise Q at grid period ``dt`` or a group's default R cannot be
        used (Q must be positive semi-definite, each R positive definite); empty when they can."""
        found = [covariance_problem(self.default_Q(dt), f"process noise Q at dt = {dt:g} s", definite=False)]
        found += [covariance_problem(self.default_R(g), f"noise R of group {g!r}", definite=True) for g in self.groups]
        return [f"model {self.name!r}: {p}" for p in found if p]

    def state_scale(self) -> np.ndarray:
        """Typical magnitude of each state (sets the encoded check's sigma floor)."""
        return np.ones(len(self.state_names))

    def actuators(self) -> Actuators:
        """The model's actuators (`Actuators`): by default one per input, named after it, driving it
        alone; none when the inputs are sensor readings (ins). A model with a mixer or an operating
        point overrides it."""
        if self.inputs_are_sensors:
            return Actuators((), np.zeros((self.n_inputs, 0)), np.zeros(0))
        return Actuators(tuple(self.input_names), np.eye(self.n_inputs), np.zeros(self.n_inputs))

    def at_rest(self, u: np.ndarray) -> np.ndarray | None:
        """(N,) bool: the grid steps where the inputs ``u`` (N, nu) say the vehicle stands still (a
        ground robot's wheels report, or are commanded, no speed), where a sensor holding its value
        is stillness, not a freeze; None when the inputs cannot tell (the default)."""
        return None

    def rest_position_var(self, duration_s: float) -> np.ndarray | float:
        """Per axis, the variance the position group's error may change by over ``duration_s`` while
        the vehicle stands (a receiver's slow wander; 0: only its white noise)."""
        return 0.0

    # --- numpy views of the model (tests, simulator, reference filter) -------------------------
    # One call each of the model's own registered numba functions, the ones the EKF kernel runs.
    def f(self, x: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
        kernels = dispatch.REGISTRY[self.model_id]
        return kernels.f_disc(self.param_vector(dt), _vec(x), _vec(u), float(dt))

    def F(self, x: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
        kernels = dispatch.REGISTRY[self.model_id]
        return kernels.predict(self.param_vector(dt), _vec(x), _vec(u), float(dt))[1]

    def h(self, group: str, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        gid = self.group(group).group_id
        return dispatch.REGISTRY[self.model_id].h_meas(self.param_vector(), gid, _vec(x), _vec(u))

    def H(self, group: str, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        gid = self.group(group).group_id
        return dispatch.REGISTRY[self.model_id].H_meas(self.param_vector(), gid, _vec(x), _vec(u))

    # --- the state's chart: additive unless the model says otherwise (ins: rotated attitude) ----
    def boxplus(self, x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        """x (+) dx: the state moved by an error-state step dx (the EKF's update applies this)."""
        return _vec(x) + _vec(dx)

    def boxminus(self, x1: np.ndarray, x0: np.ndarray) -> np.ndarray:
        """dx with x0 (+) dx = x1 (F and H are Jacobians with respect to dx)."""
        return _vec(x1) - _vec(x0)

    def describe(self) -> dict:
        """JSON-ready description: name, states, inputs, groups, the parameters it was built
        from."""
        return {
            "name": self.name,
            "states": list(self.state_names),
            "inputs": list(self.input_names),
            "groups": {
                g.name: {"outputs": list(g.outputs), "noise_std": list(g.noise_std)} for g in self.groups.values()
            },
            "params": dict(getattr(self, "p", None) or self.params),
        }


def _vec(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).reshape(-1)
