"""The vehicle-model interface every model implements (filters, simulator and detectors use only this).

INTERFACE (fixed): models are registered by name in `logscan.models` (`get_model(name, params)`,
`MODEL_NAMES`). The numeric parts run inside numba kernels: each model has an integer `model_id`
and a packed float64 parameter vector, and `logscan.models.kernels` dispatches
`f / F / h / H` on (model_id, group_id) so one cached EKF kernel serves every model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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

    @property
    def size(self) -> int:
        return len(self.outputs)


class Model:
    """Discrete-time model x_k = f(x_{k-1}, u_k) + w, z = h_g(x_k, u_k) + v per group g.

    Subclasses set the class attributes and implement the numpy methods as thin wrappers around
    their numba functions in `logscan.models.kernels`.
    """

    name: str = ""
    model_id: int = -1
    state_names: tuple[str, ...] = ()
    input_names: tuple[str, ...] = ()
    groups: dict[str, GroupSpec] = {}

    def __init__(self, params: dict | None = None):
        self.params: dict = dict(params or {})

    # --- packed data for kernels -------------------------------------------------------------
    def param_vector(self) -> np.ndarray:
        """float64 vector of the model's parameters as the numba functions read them."""
        raise NotImplementedError

    # --- defaults -------------------------------------------------------------------------------
    def default_Q(self, dt: float) -> np.ndarray:
        raise NotImplementedError

    def default_R(self, group: str) -> np.ndarray:
        spec = self.groups[group]
        return np.diag(np.square(np.asarray(spec.noise_std, dtype=np.float64)))

    def state_scale(self) -> np.ndarray:
        """Typical magnitude of each state (sets the encoded check's sigma floor)."""
        return np.ones(len(self.state_names))

    # --- numpy views of the model (tests, simulator, reference filter) -------------------------
    def f(self, x: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
        raise NotImplementedError

    def F(self, x: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
        raise NotImplementedError

    def h(self, group: str, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def H(self, group: str, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def describe(self) -> dict:
        """JSON-ready description: name, states, inputs, groups, the parameters it was built from."""
        return {
            "name": self.name,
            "states": list(self.state_names),
            "inputs": list(self.input_names),
            "groups": {
                g.name: {"outputs": list(g.outputs), "noise_std": list(g.noise_std)}
                for g in self.groups.values()
            },
            "params": dict(self.params),
        }
