"""Vehicle model registry: name -> Model (see logscan.models.base for the interface)."""

from __future__ import annotations

import importlib

from logscan.docs import doc_url
from logscan.errors import ModelError
from logscan.models.base import GroupSpec, Model

# name -> "module:Class", imported lazily
_REGISTRY = {
    "quadcopter": "logscan.models.quadcopter:Quadcopter",
    "steer_by_wire": "logscan.models.steer_by_wire:SteerByWire",
    "dc_motor": "logscan.models.dc_motor:DcMotor",
    "linear": "logscan.models.linear:LinearModel",
    "hover_uav": "logscan.models.hover_uav:HoverUav",
    "ins": "logscan.models.ins:Ins",
    "unicycle": "logscan.models.unicycle:Unicycle",
    "wheeled": "logscan.models.wheeled:Wheeled",
}
MODEL_NAMES: tuple[str, ...] = tuple(_REGISTRY)


def model_class(name: str) -> type[Model]:
    """The Model subclass registered as ``name``; ModelError listing the known names otherwise."""
    if name not in _REGISTRY:
        raise ModelError(f"unknown vehicle model {name!r}", hint="known models: " + ", ".join(MODEL_NAMES))
    module, cls = _REGISTRY[name].split(":")
    return getattr(importlib.import_module(module), cls)


def get_model(name: str, params: dict | None = None) -> Model:
    """Build the model ``name`` from ``params`` (a profile's [vehicle].params table)."""
    if params is not None and not isinstance(params, dict):
        raise ModelError(f"model {name!r}: params must be a table, got {type(params).__name__}")
    cls = model_class(name)
    try:
        return cls(params)
    except (OverflowError, ZeroDivisionError):  # Python float arithmetic on extreme values
        raise ModelError(
            "its parameters give numbers beyond float range (a value far too large or too small)",
            hint=f"check the magnitudes in [vehicle.params] (see {doc_url('profiles.md')})",
        ) from None


__all__ = ["MODEL_NAMES", "GroupSpec", "Model", "get_model", "model_class"]
